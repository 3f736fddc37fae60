"""Imitation of the witnesses on the single-input probes (studies/fair_rl.py, issue 20 item 4): the --quick
run's report and CSVs, the goal arithmetic, the expert's state-read memory, and the command's errors."""
import csv
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("scipy")
pytest.importorskip("torch")
gym = pytest.importorskip("gymnasium")

import penny_env  # noqa: E402,F401
from studies import fair_rl as fr  # noqa: E402
from studies.stats import clopper_pearson  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("fair") / "fair_rl.md"
    rows = fr.main(["--quick", "--out", str(out)])
    return out, rows


def test_quick_run_writes_report_and_csvs(quick_run):
    out, rows = quick_run
    text = out.read_text()
    for heading in ("## The agents", "## Results", "## Verdict per cell", "## Curves: validation success per round"):
        assert heading in text, heading
    assert re.search(r"^- command: `python -m studies\.fair_rl --quick --out .*fair_rl\.md` \(\d+ s wall", text, re.M)
    assert re.search(r"^- machine: ", text, re.M) and re.search(r"^- date: ", text, re.M)
    assert "- sources: sha256" not in text  # only the committed report carries the provenance line
    with open(out.with_name("fair_rl.csv")) as f:
        got = list(csv.DictReader(f))
    assert list(got[0]) == fr.FIELDS
    cells = {(r["probe"], r["table"], r["law"]) for r in got}
    assert cells == set(fr.QUICK_CELLS)
    for cell in cells:  # one row per agent and cell, each with its own results table line
        agents = [r["agent"] for r in got if (r["probe"], r["table"], r["law"]) == cell]
        assert agents == ["witness", "bc", "dagger", "options"]
    assert len([line for line in text.splitlines() if line.startswith("| steer only") or
                line.startswith("| drive only")]) == len(got) + 2 * len(cells)  # results + curves (2 learners)
    with open(out.with_name("fair_rl_curves.csv")) as f:
        curves = list(csv.DictReader(f))
    assert {(c["learner"], c["round"]) for c in curves} == {(lr, str(i)) for lr in ("flat", "options")
                                                            for i in range(fr.QUICK["rounds"] + 1)}
    meta = json.loads(out.with_name("fair_rl_run.json").read_text())
    assert meta["config"] == fr.QUICK and meta["sources"] is None


def test_quick_rows_are_consistent(quick_run):
    _, rows = quick_run
    for r in rows:
        assert r["episodes"] == fr.QUICK["eval_episodes"]
        assert 0 <= r["success"] <= r["episodes"]
        assert (r["ci_low"], r["ci_high"]) == pytest.approx(clopper_pearson(r["success"], r["episodes"]))
        assert r["ci_low"] <= r["rate"] <= r["ci_high"]
        wit = [w for w in rows if w["agent"] == "witness" and (w["probe"], w["table"]) == (r["probe"], r["table"])][0]
        assert r["witnessed"] == wit["success"]
        if r["witnessed"]:
            assert r["ratio"] == pytest.approx(r["success"] / r["witnessed"])
        if r["agent"] != "witness":
            assert r["goal_met"] == ("yes" if r["witnessed"] and r["success"] >= r["witnessed"] / 2 else "no")


def test_goal_arithmetic():
    class E:
        env_id, overrides = "PennyProbeSteer-Ellipse-Elastic-v0", {}
    cell = ("Steer", "ellipse", "elastic")
    wit = [True] * 9 + [False]
    assert fr._row(cell, E, "bc", [True] * 5 + [False] * 5, wit, 1, 0)["goal_met"] == "yes"  # 5/9 >= 0.5
    assert fr._row(cell, E, "bc", [True] * 4 + [False] * 6, wit, 1, 0)["goal_met"] == "no"  # 4/9 < 0.5
    r = fr._row(cell, E, "bc", [True] * 2 + [False] * 8, [False] * 10, 1, 0)  # nothing witnessed: no ratio
    assert r["goal_met"] == "no" and math.isnan(r["ratio"])


def test_expert_memory_is_read_from_the_state():
    """The witness's modes are functions of the state (speeds change only at impacts): the expert re-planned
    from a slow-rolling steer state tracks the target (mode 2), from a spinning drive state it tracks (mode 1)."""
    ex = fr.Expert("Steer", "stadium", "elastic")
    try:
        S = np.array([[0.0, 0.0, 0.0, 0.0, 0.5, 0.0], [0.0, 0.0, 0.0, 0.0, 4.0, 0.0]])  # R theta_dot 0.005, 0.04 m/s
        assert fr.Expert.controller(ex, ex.cands[:2], S).mode.tolist() == [2, 0]
    finally:
        ex.close()
    ex = fr.Expert("Drive", "ellipse", "elastic")
    try:
        p = ex.cands[[0, 0]]  # w_min 0
        S = np.array([[0.0, 0.0, 0.0, 0.0, 0.0, 0.3], [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]])
        assert ex.controller(p, S).mode.tolist() == [1, 0]
    finally:
        ex.close()


def test_expert_ranking_prefers_the_most_successful_candidate():
    class E:
        order = None
    succ = np.array([[0, 1, 1], [0, 1, 0], [1, 1, 0]], bool)
    fr.Expert.rank(E, succ)
    assert E.order.tolist() == [1, 0, 2]
    assert fr.Expert.choose(E, np.array([True, False, True])) == 0  # rank 1 failed here: the next that succeeds
    assert fr.Expert.choose(E, np.array([False, False, False])) is None


@pytest.mark.parametrize("argv, names", [
    (["--cells", "Both:ellipse:elastic"], "'Both'"),
    (["--cells", "Steer:moon:elastic"], "'moon'"),
    (["--cells", "Steer:plane:elastic"], "'plane'"),
    (["--cells", "Drive:ellipse:rubber"], "'rubber'"),
    (["--cells", "Drive-ellipse"], "PROBE:TABLE:LAW"),
    (["--eval-episodes", "0"], "--eval-episodes"),
    (["--demos", "0"], "--demos"),
    (["--grad-steps", "x"], "--grad-steps"),
    (["--workers", "2"], "--workers"),
])
def test_invalid_arguments_name_what_is_wrong(argv, names, capsys, tmp_path):
    with pytest.raises(SystemExit) as exc:
        fr.main(["--quick", "--out", str(tmp_path / "r.md"), *argv])
    assert exc.value.code == 2
    assert names in capsys.readouterr().err
    assert not (tmp_path / "r.md").exists()


def test_quick_never_writes_into_docs(capsys):
    with pytest.raises(SystemExit):
        fr.main(["--quick", "--out", str(ROOT / "docs" / "fair_rl.md")])
    assert "never writes into docs/" in capsys.readouterr().err
