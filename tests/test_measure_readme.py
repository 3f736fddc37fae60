"""training.measure_readme (issue 21.8): runs the README's main job step by step and reports each step's cost."""
import importlib.util
import shutil
from pathlib import Path

import pytest

from training import measure_readme

ROOT = Path(__file__).resolve().parent.parent


def test_readme_blocks_split_into_steps():
    readme = (ROOT / "README.md").read_text()
    main = measure_readme.steps_of(measure_readme.readme_block(readme, "main"))
    tests = measure_readme.steps_of(measure_readme.readme_block(readme, "tests"))
    assert main[0].startswith("python3 -m venv") and main[-1].startswith("python -m training.train")
    assert tests[-1] == "python -m pytest -n 2 -q"
    with pytest.raises(ValueError, match="no bash block"):
        measure_readme.readme_block("nothing here", "main")


def test_ci_runs_the_readme_test_command_exactly():
    """.ci/run installs and tests exactly as the README's test command says."""
    readme = (ROOT / "README.md").read_text()
    steps = measure_readme.steps_of(measure_readme.readme_block(readme, "tests"))
    ci = [ln.strip() for ln in (ROOT / ".ci" / "run").read_text().splitlines()]
    for step in steps:
        if step.startswith(("pip ", "python -m pytest")):
            assert step in ci, step


@pytest.mark.slow
def test_quick_measures_the_main_job(reports_untouched, capsys):
    for module in ("stable_baselines3", "matplotlib"):
        pytest.importorskip(module, reason=f"{module}: an extra of the main job")
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("needs git and a git checkout")
    results = measure_readme.main(["--quick"])
    rows = results["main"]["steps"]
    ran = [r for r in rows if "seconds" in r and r.get("note") != "activation"]
    assert [r["step"].split()[2] for r in ran] == ["penny_env.analysis.paper_figures", "training.train"]
    assert all(r["rc"] == 0 and r["seconds"] > 0 for r in ran), [r.get("output_tail") for r in ran]
    assert any("skipped" in r for r in rows)  # no installs in --quick
    out = capsys.readouterr().out
    assert "| `python -m penny_env.analysis.paper_figures` |" in out and "load average" in out
    assert list(reports_untouched.iterdir()) == []  # the report went to a temporary folder
