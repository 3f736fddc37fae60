"""The repository passes ruff (issue 29.8): `ruff check .` at the root, with the rules of pyproject.toml's
[tool.ruff] (pycodestyle errors and warnings, pyflakes; lines up to 130 characters)."""
import importlib.util
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _ruff():
    """The command that runs ruff: the module of this interpreter's ruff package, else a ruff on PATH."""
    if importlib.util.find_spec("ruff") is not None:
        return [sys.executable, "-m", "ruff"]
    found = shutil.which("ruff")
    return [found] if found else None


def test_ruff_check_is_clean():
    pyproject = ROOT / "pyproject.toml"
    if not pyproject.is_file() or "[tool.ruff]" not in pyproject.read_text():
        pytest.skip("not a source checkout (no pyproject.toml with [tool.ruff])")
    ruff = _ruff()
    if ruff is None:
        pytest.skip("ruff is not installed (the penny-env[test] extra): pip install ruff")
    # --no-cache: nothing written into the checkout
    run = subprocess.run([*ruff, "check", "--no-cache", "."], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, f"ruff check . found problems (rc {run.returncode}):\n{run.stdout}\n{run.stderr}"
