"""studies.measure_readme (issue 21.8): runs the README's main job step by step and reports each step's cost."""
import json
import re
import shutil
from pathlib import Path

import pytest

from studies import measure_readme

ROOT = Path(__file__).resolve().parents[2]


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
    assert [r["step"].split()[2] for r in ran] == ["studies.paper_figures", "training.train"]
    assert all(r["rc"] == 0 and r["seconds"] > 0 for r in ran), [r.get("output_tail") for r in ran]
    assert any("skipped" in r for r in rows)  # no installs in --quick
    out = capsys.readouterr().out
    assert "| `python -m studies.paper_figures` |" in out and "load average" in out
    assert list(reports_untouched.iterdir()) == []  # the report went to a temporary folder


def test_report_only_renders_the_stored_parts(reports_untouched, capsys):
    with pytest.raises(SystemExit):
        measure_readme.main(["--report-only", "--out", "costs.md"])
    assert "no part measured yet" in capsys.readouterr().err
    store = reports_untouched / "costs.json"  # the measurements live beside the report
    part = {"part": "main", "quick": False, "machine": ["- machine: M"], "load_at_start": [3.0, 2.0, 1.0],
            "steps": [{"step": "pip install x", "seconds": 30.0, "rc": 0, "load": {"mean": 2.5, "max": 4.0},
                       "venv_bytes": 2**30, "pip_retries": 7},
                      {"step": "python -m training.train", "seconds": 600.0, "rc": 1, "load": {"mean": 1, "max": 2}}]}
    store.write_text(json.dumps({"main": part}))
    measure_readme.main(["--report-only", "--out", "costs.md"])
    text = (reports_untouched / "costs.md").read_text()
    assert "| `pip install x` | 30 s (7 pip retries) | 0 | 2.5 / 4.0 | 1.00 GiB |" in text
    assert "| `python -m training.train` | 600 s (10.0 min) | 1 |" in text and "a step FAILED" in text
    assert "load average at the start (1, 5, 15 min): 3.0, 2.0, 1.0" in text and "Install and run the tests" not in text


def _fake_part(part, readme, seconds=10.0, pytest_counts=None):
    """A measurement of `part` of this README whose every step took `seconds` (for the sentence tests)."""
    steps = []
    for step in measure_readme.steps_of(measure_readme.readme_block(readme, part)):
        row = {"step": step, "seconds": seconds, "rc": 0, "load": {"mean": 1.5, "max": 3.0}}
        if step.startswith("pip install torch"):
            row.update(venv_bytes=2**30, pip_retries=12)
        elif step.startswith("pip install -e"):
            row["venv_bytes"] = 1.5 * 2**30
        elif step.startswith("python -m pytest"):
            row["pytest"] = pytest_counts
        steps.append(row)
    return {"part": part, "quick": False, "machine": ["- machine: Linux, CPU: AMD EPYC (2 logical cores)"],
            "steps": steps, "load_at_start": [1.0, 1.0, 1.0], "date": "2026-11-26"}


def test_measuring_one_part_keeps_the_other(reports_untouched, monkeypatch):
    """The source of the README's main-job sentence was dropped when only the tests were remeasured: the
    measurements now live in a JSON file beside the report, and each run adds its parts to it."""
    readme = (ROOT / "README.md").read_text()
    (reports_untouched / "costs.json").write_text(json.dumps({"main": _fake_part("main", readme)}))
    monkeypatch.setattr(measure_readme, "copy_checkout", lambda dest: dest)
    monkeypatch.setattr(measure_readme, "run_part", lambda part, *a, **k: _fake_part(
        part, readme, 20.0, {"passed": 1199, "skipped": 9}))
    measure_readme.main(["--parts", "tests", "--out", "costs.md"])
    text = (reports_untouched / "costs.md").read_text()
    assert "## Install and run the main job" in text and "## Install and run the tests" in text
    assert "Tests: 1199 passed, 9 skipped." in text
    stored = json.loads((reports_untouched / "costs.json").read_text())
    assert set(stored) == {"main", "tests"}


def test_pytest_counts_from_the_summary_line():
    out = "....\n=== warnings ===\n1199 passed, 9 skipped, 3 warnings in 287.31s (0:04:47)\n"
    assert measure_readme.pytest_counts(out) == {"passed": 1199, "skipped": 9, "warnings": 3} or \
        measure_readme.pytest_counts(out) == {"passed": 1199, "skipped": 9}
    assert measure_readme.pytest_counts("-q\n2 failed, 10 passed in 3.0s") == {"failed": 2, "passed": 10}
    assert measure_readme.pytest_counts("no summary") is None


def test_readme_sentences_come_from_the_measurement(tmp_path):
    readme = (ROOT / "README.md").read_text()
    main = measure_readme.readme_sentence("main", _fake_part("main", readme), readme)
    assert main.startswith("Cost: ") and "AMD EPYC (2 logical cores), 2026-11-26" in main
    assert "could not reach download.pytorch.org" in main and "after 12 connection retries" in main
    assert "for `studies.paper_figures`" in main and "for `training.train`" in main
    tests = measure_readme.readme_sentence("tests", _fake_part("tests", readme, 300.0, {"passed": 5, "skipped": 1}),
                                           readme)
    assert "the suite 5.0 minutes (5 passed, 1 skipped)" in tests and "2.50 GiB" not in tests and "1.50 GiB" in tests
    # a measurement of another command, a failed step or none: the sentence says it is not measured
    other = _fake_part("main", readme)
    other["steps"][2]["step"] = "pip install torch==2.13.0"
    failed = _fake_part("main", readme)
    failed["steps"][-1]["rc"] = 1
    for result in (None, other, failed, dict(_fake_part("main", readme), quick=True)):
        assert measure_readme.readme_sentence("main", result, readme).startswith("Not yet measured")
    # --readme rewrites between the markers, and only there
    copy = tmp_path / "README.md"
    copy.write_text(readme)
    measure_readme.update_readme(copy, {"main": _fake_part("main", readme)})
    new = copy.read_text()
    assert measure_readme.readme_marked(new, "main") == " ".join(main.split())
    assert measure_readme.readme_marked(new, "tests").startswith("Not yet measured")
    def strip(t):
        return re.sub(r"<!-- readme-costs:(\w+) -->.*?<!-- /readme-costs:\1 -->", "", t, flags=re.S)
    assert strip(new) == strip(readme)
    with pytest.raises(SystemExit):
        measure_readme.main(["--quick", "--readme", str(copy)])


def test_the_readme_quotes_the_committed_measurement():
    """The README's cost sentences are what `measure_readme --readme` writes from docs/readme_costs.json
    for the README's current commands (a sentence about an older command, or typed by hand, fails)."""
    readme = (ROOT / "README.md").read_text()
    store = ROOT / "docs" / "readme_costs.json"
    results = json.loads(store.read_text()) if store.is_file() else {}
    for part in measure_readme.PARTS:
        expected = " ".join(measure_readme.readme_sentence(part, results.get(part), readme).split())
        assert measure_readme.readme_marked(readme, part) == expected, part


def test_the_copy_is_a_clean_git_checkout_of_the_files(tmp_path):
    # the README's test command in the copy runs the tests that need a git checkout (as CI's clean checkout does)
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("needs git and a git checkout")
    import subprocess
    dest = measure_readme.copy_checkout(tmp_path)
    status = subprocess.run(["git", "status", "--porcelain"], cwd=dest, capture_output=True, text=True, check=True)
    assert status.stdout == ""
    tracked = subprocess.run(["git", "ls-files"], cwd=dest, capture_output=True, text=True, check=True).stdout.split()
    assert "README.md" in tracked and "penny_env/__init__.py" in tracked and "pyproject.toml" in tracked
