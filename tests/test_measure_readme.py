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


def test_report_only_renders_the_stored_parts(reports_untouched, capsys):
    with pytest.raises(SystemExit):
        measure_readme.main(["--report-only", "--out", "costs.md"])
    assert "no part measured yet" in capsys.readouterr().err
    store = reports_untouched / "runs" / "readme_costs"
    assert store.is_dir()  # (made by the first call)
    part = {"part": "main", "quick": False, "machine": ["- machine: M"], "load_at_start": [3.0, 2.0, 1.0],
            "steps": [{"step": "pip install x", "seconds": 30.0, "rc": 0, "load": {"mean": 2.5, "max": 4.0},
                       "venv_bytes": 2**30},
                      {"step": "python -m training.train", "seconds": 600.0, "rc": 1, "load": {"mean": 1, "max": 2}}]}
    (store / "main.json").write_text(__import__("json").dumps(part))
    measure_readme.main(["--report-only", "--out", "costs.md"])
    text = (reports_untouched / "costs.md").read_text()
    assert "| `pip install x` | 30 s | 0 | 2.5 / 4.0 | 1.00 GiB |" in text
    assert "| `python -m training.train` | 600 s (10.0 min) | 1 |" in text and "a step FAILED" in text
    assert "load average at the start (1, 5, 15 min): 3.0, 2.0, 1.0" in text and "Install and run the tests" not in text
