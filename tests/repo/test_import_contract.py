"""The import contract (pyproject.toml's [tool.importlinter], docs/architecture.md): the package's layers import one
way (physics, the step, the backends, the envs, then what a user calls on top), the repository's folders too
(the package, training, studies, devtools), and no circle of imports is left between siblings at any depth.
lint-imports (import-linter, the test extra) checks it; without it the test skips."""
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.fast
def test_the_import_contract_holds():
    pytest.importorskip("importlinter", reason="import-linter (the test extra) checks the import contract")
    r = subprocess.run([sys.executable, "-c", "import sys; from importlinter.cli import lint_imports_command; "
                        "sys.exit(lint_imports_command())"], cwd=ROOT, capture_output=True, text=True, timeout=300,
                       env={**__import__("os").environ, "PYTHONPATH": str(ROOT)})
    assert r.returncode == 0, r.stdout[-4000:] + r.stderr[-2000:]
    assert "0 broken" in r.stdout, r.stdout[-4000:]


@pytest.mark.fast
def test_the_contract_names_every_layer_of_the_package():
    """Every subpackage and top-level module of penny_env is in one layer of the contract (a new folder cannot sit
    outside it unnoticed)."""
    import tomllib
    contracts = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]["contracts"]
    package = next(c for c in contracts if c.get("containers") == ["penny_env"])
    named = {m.strip() for layer in package["layers"] for m in layer.replace("|", ":").split(":")}
    present = {p.stem if p.is_file() else p.name for p in (ROOT / "penny_env").iterdir()
               if (p.suffix == ".py" and p.stem != "__init__") or (p.is_dir() and (p / "__init__.py").exists())}
    assert present <= named | {"presets"}, sorted(present - named)
