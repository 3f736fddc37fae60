"""Docs that run: every fenced ```python block of README.md and docs/*.md runs, as written, in a fresh process (from
the repository root), unless an HTML comment just before it says why not (``<!-- not run: REASON -->``, the reason
shown as the skip's); docs/extending.md's table and task examples are the text of the tests' own example modules
(tests/physics/example_table.py, tests/step/example_task.py), and the example table carries a penny."""
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
BLOCK = re.compile(r"^```python\n(.*?)^```", re.S | re.M)
NOT_RUN = re.compile(r"<!--\s*not run:\s*(.+?)\s*-->\s*$")


def blocks(path: Path) -> list[tuple[int, str, str | None]]:
    """(line, code, reason not to run it or None) of every Python block of a Markdown file."""
    text = path.read_text()
    out = []
    for m in BLOCK.finditer(text):
        before = text[:m.start()].rstrip("\n").rsplit("\n", 1)[-1]
        reason = NOT_RUN.search(before)
        out.append((text[:m.start()].count("\n") + 1, m.group(1), reason.group(1) if reason else None))
    return out


CASES = [pytest.param(path, line, code, reason, id=f"{path.relative_to(ROOT)}:{line}")
         for path in DOCS for line, code, reason in blocks(path)]


def run(code: str, timeout: int = 900) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=timeout,
                          env=dict(os.environ, PYTHONPATH=str(ROOT), MPLBACKEND="Agg"))


def test_the_blocks_are_found_and_the_marker_is_read(tmp_path):
    assert len(CASES) >= 8 and any("class Disc(Table)" in c.values[2] for c in CASES)
    probe = tmp_path / "probe.md"
    probe.write_text("<!-- not run: needs a GPU -->\n```python\nx = 1\n```\n```python\ny = 2\n```\n")
    assert blocks(probe) == [(2, "x = 1\n", "needs a GPU"), (5, "y = 2\n", None)]


@pytest.mark.slow
@pytest.mark.parametrize("path, line, code, reason", CASES)
def test_every_python_block_of_the_docs_runs(path, line, code, reason):
    if reason is not None:
        pytest.skip(f"{path.name}:{line} is marked not to run: {reason}")
    r = run(code)
    assert r.returncode == 0, f"{path.relative_to(ROOT)}:{line} failed:\n{r.stderr[-3000:]}"


def _block_with(path: Path, needle: str) -> str:
    [code] = [code for _, code, _ in blocks(path) if needle in code]
    return code


def test_extending_shows_the_tests_example_table_and_task_as_they_are():
    doc = ROOT / "docs" / "extending.md"
    assert _block_with(doc, "class Disc(Table)") == (ROOT / "tests" / "physics" / "example_table.py").read_text()
    assert _block_with(doc, "class HurryTask") == (ROOT / "tests" / "step" / "example_task.py").read_text()


@pytest.mark.slow
def test_a_penny_rolls_on_the_example_table_as_on_the_circle():
    """The example table is the circle written out: the same impacts to round-off, in the compiled loop."""
    r = run("import numpy as np, penny_env as pe\n"
            "from tests.physics.example_table import Disc\n"
            "s = [0.0, 0.0, 0.0, 0.3, 10.0, 0.7]\n"
            "a = pe.simulate(s, table=Disc(0.15), law='elastic', n_impacts=3)\n"
            "b = pe.simulate(s, table=pe.Circle(0.15), law='elastic', n_impacts=3)\n"
            "assert a.n_impacts == b.n_impacts == 3, (a.n_impacts, b.n_impacts)\n"
            "assert np.allclose(a.impact_times, b.impact_times, rtol=0, atol=1e-10), (a.impact_times, b.impact_times)\n"
            "assert np.allclose(a.final_state, b.final_state, rtol=0, atol=1e-9)\n"
            "assert pe.physics.make_table({'kind': 'disc', 'r': 0.15}) == Disc(0.15)\n")
    assert r.returncode == 0, r.stderr[-3000:]
