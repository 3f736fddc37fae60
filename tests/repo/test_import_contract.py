"""The import contract (pyproject.toml's [tool.importlinter], docs/architecture.md): the package's layers import one
way (physics, the step, the backends, the envs, then what a user calls on top), the repository's folders too
(the package, lab, training, studies, devtools), and no circle of imports is left between siblings at any depth.
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


@pytest.mark.fast
def test_the_layout_in_architecture_md_is_the_contract_s():
    """docs/architecture.md's layout block (the one layout of the repository; the README links it) names the
    repository's folders and the package's layers in the contract's order."""
    import re
    import tomllib
    contracts = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]["contracts"]
    repo = next(c for c in contracts if c.get("type") == "layers" and "containers" not in c)
    package = next(c for c in contracts if c.get("containers") == ["penny_env"])
    text = (ROOT / "docs" / "architecture.md").read_text()
    block = re.search(r"## Layers\n.*?```\n(.*?)```", text, re.S).group(1)
    tops = [m.group(1) for m in re.finditer(r"^(\w+)/ ", block, re.M)]
    assert tops == repo["layers"], (tops, repo["layers"])
    inner = [re.split(r"\s{2,}", line.strip())[0] for line in block.splitlines() if re.match(r"^  \S", line)]
    named = [sorted(x.strip().removesuffix("/").removesuffix(".py") for x in entry.rstrip(",").split(", "))
             for entry in inner]
    layers = [sorted(m.strip() for m in layer.replace("|", ":").split(":")) for layer in package["layers"]]
    assert named == layers, (named, layers)
    readme = (ROOT / "README.md").read_text()
    assert "[docs/architecture.md](docs/architecture.md)" in readme.split("## Layout", 1)[1]
    assert "| folder |" not in readme  # no second copy of the layout


def private_names_imported(path: Path) -> list:
    """(line, what) of every private name (a module or a name starting with "_", dunders aside) that the module at
    ``path`` imports from penny_env, or reads as an attribute of a penny_env module it imported."""
    import ast

    def private(name):
        return any(part.startswith("_") and not part.startswith("__") for part in name.split("."))
    tree = ast.parse(path.read_text())
    found, modules = [], set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "penny_env":
            for alias in node.names:
                if private(f"{node.module}.{alias.name}"):
                    found.append((node.lineno, f"{node.module}.{alias.name}"))
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == "penny_env":
                    modules.add(alias.asname or alias.name.split(".")[0])
                    if private(alias.name):
                        found.append((node.lineno, alias.name))
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and private(node.attr):
            chain, base = [node.attr], node.value
            while isinstance(base, ast.Attribute):
                chain.append(base.attr)
                base = base.value
            if isinstance(base, ast.Name) and base.id in modules:
                found.append((node.lineno, ".".join([base.id] + chain[::-1])))
    return found


def lab_packages() -> list:
    """The lab: every root package of the import contract but penny_env (adding one there makes it lab)."""
    import tomllib
    roots = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]["root_packages"]
    return [r for r in roots if r != "penny_env"]


@pytest.mark.fast
def test_the_lab_imports_no_private_name_of_the_package(tmp_path):
    """The lab uses penny_env's public modules and names only: a private one it needs gets a public home (the import
    contract checks private modules; names are this test's)."""
    assert {"training", "studies", "devtools"} <= set(lab_packages())
    found = [f"{p.relative_to(ROOT)}:{line}: {what}" for package in lab_packages()
             for p in sorted((ROOT / package).rglob("*.py")) for line, what in private_names_imported(p)]
    assert found == []
    probe = tmp_path / "probe.py"
    probe.write_text("import penny_env.envs.scene as sc\nfrom penny_env.envs.scene import (resolve,\n    _merge)\n"
                     "import penny_env\nx = penny_env.envs._private\n")
    assert [w for _, w in private_names_imported(probe)] == ["penny_env.envs.scene._merge", "penny_env.envs._private"]
