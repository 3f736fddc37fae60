"""Certified witnesses (studies/witness.py), the verdict rules (studies/verdict.py), the witness study's
--quick run and README answer (studies/witness_study.py), and the exact / seed-clustered intervals."""
import csv
import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("scipy")
gym = pytest.importorskip("gymnasium")

import penny_env  # noqa: E402,F401
from studies import witness as wt  # noqa: E402
from studies import witness_study as ws  # noqa: E402
from lab.stats import clopper_pearson, seed_clustered_ci  # noqa: E402
from studies.verdict import ANCHORS, cell_verdict  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


def _replay(env_id, overrides, seed, actions):
    """The witness's actions replayed open loop in a fresh env of the id: (is_success, steps)."""
    env = gym.make(env_id, **overrides)
    env.reset(seed=seed)
    for i, a in enumerate(actions, 1):
        _, _, term, trunc, info = env.step(a)
        if term or trunc:
            env.close()
            return bool(info["is_success"]), i
    env.close()
    return False, len(actions)


@pytest.mark.parametrize("env_id, overrides", [
    ("PennyProbeDrive-Ellipse-Elastic-v0", {}),
    ("PennyProbeSteer-Ellipse-Elastic-v0", {"scene": "circle", "law": "plastic"}),
])
def test_witness_episode_is_a_success_of_the_real_env(env_id, overrides):
    w = wt.Witness(env_id, overrides)
    try:
        r = w.pair(0)
    finally:
        w.close()
    assert r.witnessed, r.reason
    assert r.impacts >= 1  # single input: only an impact can change the conserved speed (T2, T3)
    ok, steps = _replay(env_id, overrides, 0, r.actions)
    assert ok and steps == r.steps == len(r.actions)


def test_real_episode_gets_the_searched_actions_bitwise():
    """The search runs float64 actions on the vector env; the real episode must get the same (a float32 cast
    changed the torques' last bits, and on the elastic ellipse this pair's episode missed the target)."""
    w = wt.Witness("PennyProbeSteer-Ellipse-Elastic-v0")
    try:
        r = w.pair(27)
    finally:
        w.close()
    assert r.witnessed, r.reason
    assert all(a.dtype == np.float64 for a in r.actions)


def test_witness_on_the_plane_fails_with_the_theorem_as_reason():
    w = wt.Witness("PennyProbeDrive-Plane-v0")
    try:
        r = w.pair(0)
    finally:
        w.close()
    assert not r.witnessed and "theorem T3" in r.reason


def test_witness_command_on_a_cell_a_theorem_excludes(capsys):
    """The issue's cell: steering only on a circle of radius 0.5 m with e = 0.5 walls. Theorem T2.5 (with the first
    impact's time) excludes the whole cell and each pair; each failure line says which condition failed (the
    penny passes within 0.002 m of the target but never slowly: speed) and cites the theorem with its numbers."""
    wt.main(["PennyProbeSteer-Stadium-Elastic-v0", "--pairs", "2", "table={kind: circle, r: 0.5}", "law=0.5"])
    out = capsys.readouterr().out
    assert "witnessed 0/2 pairs; 2/2 impossible (theorem T2.5)" in out
    assert "the whole cell: impossible (theorem T2.5) on speed and time" in out and "0.202 m of the wall" in out
    lines = [x for x in out.splitlines() if x.startswith("  seed ")]
    assert len(lines) == 2
    for line in lines:
        assert "impossible (theorem T2.5) on speed and time" in line
        assert "position met" in line and "but speed never" in line


def test_witness_on_a_cell_a_theorem_excludes_in_part():
    """A circle of radius 0.35 m: T2.5 excludes the pair of seed 2 (its target is too far from the wall for the time
    left after the first impact) but not that of seed 0; both lines say which success condition was never met."""
    w = wt.Witness("PennyProbeSteer-Stadium-Elastic-v0", {"table": {"kind": "circle", "radius": 0.35}, "law": 0.5})
    try:
        r0, r2 = w.pair(0), w.pair(2)
    finally:
        w.close()
    assert r0.theorem == "" and r2.theorem == "T2.5"
    assert not r2.witnessed and r2.reason.startswith("impossible (theorem T2.5) on speed and time")
    for r in (r0, r2):
        assert r.witnessed or any(k in r.reason for k in ("position never met", "but speed never", "but spin never"))


def test_witness_failure_lines_name_the_failed_condition():
    """why(): position (closest approach >= tolerance), speed (within it, never slower than speed_tolerance), spin
    (within it and slow, never under spin_tolerance); the time limit searched; a theorem where one covers the pair."""
    from penny_env.analysis.controllability_theorems import theorem_for

    w = wt.Witness("PennyProbeSteer-Ellipse-Elastic-v0")
    try:
        base = {"any_hit": True, "max_w_after_hit": 1.0, "steps": 400}
        far = w.why({**base, "best_d": 0.05, "slowest_within": np.inf, "calmest": np.inf})
        assert "position never met: closest approach 0.050 m >= tolerance 0.02 m" in far and "20 s" in far
        fast = w.why({**base, "best_d": 0.001, "slowest_within": 0.03, "calmest": np.inf})
        assert "position met (closest approach 0.0010 m < tolerance 0.02 m) but speed never" in fast
        assert "0.0300 m/s >= speed_tolerance 0.01 m/s" in fast
        spin = w.why({**base, "best_d": 0.001, "slowest_within": 0.001, "calmest": 0.9})
        assert "spin never" in spin and "0.9 rad/s >= spin_tolerance 0.5 rad/s" in spin
        thm = theorem_for("PennyProbeSteer-Plane-v0")
        cited = w.why({**base, "best_d": 0.001, "slowest_within": 0.03, "calmest": np.inf}, thm)
        assert cited.startswith("impossible (theorem T2.3) on speed: ") and "but speed never" in cited
    finally:
        w.close()


def test_a_witness_on_an_excluded_pair_stops_the_run(monkeypatch):
    """A witnessed pair that a theorem excludes is a contradiction: Witness.pair raises instead of counting it."""
    from penny_env.analysis.controllability_theorems import theorem_for

    fake = theorem_for("PennyProbeSteer-Plane-v0")
    monkeypatch.setattr(wt.Witness, "theorem", lambda self, state, target: fake)
    w = wt.Witness("PennyProbeDrive-Ellipse-Elastic-v0")
    try:
        with pytest.raises(wt.TheoremContradiction, match="T2.3"):
            w.pair(0)
    finally:
        w.close()


def test_witness_command_prints_the_count(capsys):
    wt.main(["PennyProbeDrive-Ellipse-Elastic-v0", "--pairs", "1", "table=circle", "law=0.5"])
    out = capsys.readouterr().out
    assert "scene=circle law=0.5: witnessed 1/1 pairs" in out


@pytest.mark.parametrize("argv, names", [
    (["PennyReach-Ellipse-v0"], "PennyReach-Ellipse-v0"),
    (["PennyProbeNothing-Plane-v0"], "PennyProbeNothing-Plane-v0"),
    (["PennyProbeSteer-Plane-v0", "--pairs", "0"], "--pairs"),
    (["PennyProbeSteer-Plane-v0", "--pairs", "-3"], "--pairs"),
    (["PennyProbeSteer-Plane-v0", "--pairs", "two"], "--pairs"),
    (["PennyProbeSteer-Plane-v0", "--seed", "-1"], "--seed"),
    (["PennyProbeSteer-Plane-v0", "--workers", "0"], "--workers"),
    (["PennyProbeSteer-Plane-v0", "law=sticky"], "law"),
    (["PennyProbeSteer-Plane-v0", "law=1.5"], "law"),
    (["PennyProbeSteer-Plane-v0", "table=hexagon"], "hexagon"),
    (["PennyProbeSteer-Plane-v0", "table={kind: hexagon}"], "table"),
    (["PennyProbeSteer-Plane-v0", "colour=red"], "colour"),
    (["PennyProbeSteer-Plane-v0", "law"], "field=value"),
])
def test_witness_command_bad_input_names_it(argv, names, capsys):
    with pytest.raises(SystemExit) as exc:
        wt.main(argv)
    assert exc.value.code == 2
    assert names in capsys.readouterr().err


def test_probe_of_and_overrides():
    assert wt.probe_of("PennyProbeBoth-Stadium-E05-v0") == "Both"
    with pytest.raises(ValueError, match="PennyImpacts-Stadium-v0"):
        wt.probe_of("PennyImpacts-Stadium-v0")
    with pytest.raises(TypeError, match="ENV_ID"):
        wt.probe_of(3)
    assert wt.parse_overrides(["table=circle", "law=0.5", "init={theta_dot: [3, 4]}"]) == \
        {"scene": "circle", "law": 0.5, "init": {"theta_dot": [3, 4]}}


# -- verdict rules ------------------------------------------------------------------------------------
def test_verdict_rules():
    assert cell_verdict("Steer", "plane", 0, 5) == "impossible (theorem T2.3)"
    assert cell_verdict("Drive", "plane", 0, 30) == "impossible (theorem T3.2)"
    assert cell_verdict("Steer", "circle", 0, 30) == "open"
    assert cell_verdict("Steer", "circle", 7, 30) == "possible (witnessed 7/30)"
    assert cell_verdict("Both", "plane", 30, 30) == "possible (witnessed 30/30)"  # no theorem forbids it
    assert cell_verdict("Both", "plane", 0, 30) == "open"
    # a witness in a theorem's cell is a contradiction, not a vote: the theorem's cell never says "possible"
    with pytest.raises(ValueError, match="contradict theorem T2"):
        cell_verdict("Steer", "plane", 1, 5)
    with pytest.raises(ValueError, match="pairs"):
        cell_verdict("Steer", "circle", 0, 0)
    with pytest.raises(ValueError, match="witnessed"):
        cell_verdict("Steer", "circle", 31, 30)
    with pytest.raises(TypeError, match="witnessed"):
        cell_verdict("Steer", "circle", 1.5, 30)
    # pairs a theorem excludes in a cell it does not decide as a whole
    assert cell_verdict("Steer", "circle_r0.35", 3, 40, "0.5", 21, "T2.5") == \
        "possible (witnessed 3/40; 21/40 impossible, theorem T2.5)"
    assert cell_verdict("Steer", "circle_r0.35", 0, 40, "0.5", 21, "T2.5") == "open (21/40 impossible, theorem T2.5)"
    assert cell_verdict("Steer", "circle_r0.5", 0, 5, "0.5", 5, "T2.5") == "impossible (theorem T2.5)"
    assert cell_verdict("Steer", "stadium", 200, 200, "plastic", 0, "", 78, "T8.1") == \
        "possible (theorem T8.1 for 78/200 pairs, given enough time; witnessed 200/200)"
    assert cell_verdict("Steer", "stadium", 0, 200, "elastic", 0, "", 80, "T8.2").startswith("possible (theorem T8.2")
    with pytest.raises(ValueError, match="possible"):
        cell_verdict("Steer", "stadium", 0, 200, "elastic", 0, "", 201, "T8.2")
    with pytest.raises(ValueError, match="excluded"):
        cell_verdict("Steer", "circle", 30, 30, "elastic", 1, "T2.5")


def test_theory_anchors_name_the_theory_pages_headings():
    doc = ROOT / "docs" / "controllability_theory.md"
    if not doc.is_file():
        pytest.skip("docs/controllability_theory.md (the theory, another branch of issue 20) is not here yet")
    import re
    anchors = set()
    for line in doc.read_text().splitlines():
        if line.startswith("## "):
            anchors.add(re.sub(r"[^a-z0-9 -]", "", line[3:].strip().lower()).replace(" ", "-"))
    for tid, anchor in ANCHORS.items():
        assert anchor in anchors, (tid, anchor, sorted(anchors))


# -- intervals ----------------------------------------------------------------------------------------
def test_clopper_pearson_exact_at_zero_and_at_n():
    lo, hi = clopper_pearson(0, 500)
    assert lo == 0.0 and hi == pytest.approx(1 - 0.025 ** (1 / 500), rel=1e-9) and 0.0073 < hi < 0.0074
    lo, hi = clopper_pearson(500, 500)
    assert hi == 1.0 and lo == pytest.approx(0.025 ** (1 / 500), rel=1e-9)
    lo, hi = clopper_pearson(3, 10)
    assert (lo, hi) == pytest.approx((0.0667, 0.6525), abs=1e-4)  # the textbook values
    from scipy.stats import binomtest
    ci = binomtest(3, 10).proportion_ci(method="exact")
    assert (lo, hi) == pytest.approx((ci.low, ci.high))
    for bad, err in (((1, 0), ValueError), ((5, 4), ValueError), ((-1, 4), ValueError), ((0.5, 4), TypeError)):
        with pytest.raises(err):
            clopper_pearson(*bad)


def test_seed_clustered_interval():
    zeros = np.zeros((5, 100))
    assert seed_clustered_ci(zeros) == pytest.approx(clopper_pearson(0, 500))  # honest at 0: [0, 0.0074]
    assert seed_clustered_ci(np.ones((5, 100))) == pytest.approx(clopper_pearson(500, 500))
    # seeds that disagree: the t interval over the seed means, far wider than the pooled binomial one
    split = np.r_[np.ones((2, 100)), np.zeros((3, 100))]
    lo, hi = seed_clustered_ci(split)
    means = split.mean(axis=1)
    half = 2.7764451051977987 * means.std(ddof=1) / math.sqrt(5)
    assert (lo, hi) == pytest.approx((max(0.0, 0.4 - half), min(1.0, 0.4 + half)))
    assert hi - lo > 0.9
    # unlike a percentile bootstrap over seeds, it can leave the hull of the seed means
    M = np.zeros((3, 10))
    M[0, :4], M[1, :5], M[2, :6] = 1, 1, 1
    lo, hi = seed_clustered_ci(M)
    assert lo < 0.4 and hi > 0.6
    with pytest.raises(ValueError, match="0/1"):
        seed_clustered_ci(np.full((2, 3), 0.5))


# -- the study --------------------------------------------------------------------------------------
def test_witness_study_quick_writes_only_its_folder(tmp_path):
    docs_before = {p: p.stat().st_mtime_ns for p in (ROOT / "docs").glob("witnesses*")}
    readme_before = (ROOT / "README.md").read_text()
    cells = ws.main(["--quick", "--workers", "1", "--out-dir", str(tmp_path)])
    assert {(c["probe"], c["table"], c["law"]) for c in cells} == set(ws.QUICK_CELLS)
    by = {(c["probe"], c["table"]): c for c in cells}
    assert by[("Drive", "plane")]["verdict"] == "impossible (theorem T3.2)"
    assert by[("Drive", "ellipse")]["verdict"].startswith("possible (witnessed")
    assert by[("Steer", "circle_r0.5")]["verdict"] == "impossible (theorem T2.5)"  # an override cell
    text = (tmp_path / "witnesses.md").read_text()
    assert "## The verdict" in text and "theorem T3" in text and "witnessed" in text
    assert "Circle r = 0.5 m" in text and "2/2 (T2.5)" in text
    with open(tmp_path / "witnesses_pairs.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 8 and {r["theorem"] for r in rows if r["table"] == "circle_r0.5"} == {"T2.5"}
    assert {p: p.stat().st_mtime_ns for p in (ROOT / "docs").glob("witnesses*")} == docs_before
    assert (ROOT / "README.md").read_text() == readme_before
    # --report-only rewrites the same verdicts from the CSVs
    again = ws.main(["--report-only", "--out-dir", str(tmp_path)])
    assert [c["verdict"] for c in again] == [c["verdict"] for c in cells]
    with pytest.raises(SystemExit):
        ws.main(["--quick", "--out-dir", str(ROOT / "docs")])


def test_readme_answer_is_the_verdict_tables():
    """The README's answer is computed from the committed verdict table (docs/witnesses.csv), not typed."""
    text = (ROOT / "README.md").read_text()
    assert ws.README_BEGIN in text and ws.README_END in text
    assert "<!-- study-answer" not in text  # the old RL-comparison verdict is gone
    cells_csv = ROOT / "docs" / "witnesses.csv"
    assert cells_csv.is_file(), "docs/witnesses.csv (the committed witness study) is missing"
    cells = ws.read_csv(cells_csv)
    pairs = ws.read_csv(ROOT / "docs" / "witnesses_pairs.csv")
    for c in cells:
        mine = [r for r in pairs if ws._key(r) == ws._key(c)]
        ex, by = ws.excluded_of(mine)
        assert (ex, by) == (int(c["excluded"]), c["excluded_by"])
        pos, pos_by = ws.possible_of(mine)  # (recomputed by the theory's code from the pairs' seeds)
        assert (pos, pos_by) == (int(c["possible"]), c["possible_by"])
        c["verdict"] = cell_verdict(c["probe"], c["table"], int(c["witnessed"]), int(c["pairs"]), c["law"], ex, by,
                                    pos, pos_by)
        assert c["verdict"].startswith("possible (theorem T8") == (c["probe"] == "Steer" and c["table"] in (
            "stadium", "rounded_rectangle"))
    block = text.split(ws.README_BEGIN, 1)[1].split(ws.README_END, 1)[0].strip()
    assert block == ws.readme_answer(cells)
    assert "RL study" not in block and "docs/ladder.md" in block  # (the agents: the agent study's one answer)
    # every probe x table x law cell was run
    keys = {(c["probe"], c["table"], c["law"]) for c in cells}
    assert keys == set(ws.all_cells())


@pytest.mark.parametrize("argv, names", [(["--pairs", "0"], "--pairs"), (["--workers", "-1"], "--workers"),
                                          (["--theorem-pairs", "0"], "--theorem-pairs")])
def test_witness_study_bad_input_names_it(argv, names, capsys):
    with pytest.raises(SystemExit) as exc:
        ws.main(argv)
    assert exc.value.code == 2 and names in capsys.readouterr().err


def test_witness_study_report_only_needs_its_csvs(tmp_path, capsys):
    with pytest.raises(SystemExit):
        ws.main(["--report-only", "--out-dir", str(tmp_path)])
    assert "witnesses.csv" in capsys.readouterr().err


def test_witness_accepts_a_time_limit_override():
    """Issue 39 item 2: max_episode_steps is a gymnasium.make keyword and T2.5 depends on the time limit, so a cell
    with a shorter limit must be witnessable. It reached gym.make_vec twice (TypeError: multiple values). The vector
    search and the real episode must both run under the override's limit."""
    w = wt.Witness("PennyProbeSteer-Stadium-Elastic-v0", {"max_episode_steps": 40})
    try:
        assert w.max_steps == 40 == w.env.spec.max_episode_steps
        r = w.pair(0)
    finally:
        w.close()
    # T2.5 reads the episode's limit (2 s), not the preset's 20 s: under 20 s it excludes no pair of this cell
    # (docs/controllability_theory.md), under 2 s it excludes this one, and the search never contradicts it
    assert not r.witnessed and r.theorem == "T2.5" and r.reason.startswith("impossible (theorem T2.5)")
    w20 = wt.Witness("PennyProbeSteer-Stadium-Elastic-v0")
    try:
        assert w20.theorem(*_pair_of(w20, 0)) is None
    finally:
        w20.close()


def _pair_of(w, seed):
    """The start state and target of the pair of this seed in the witness's real env."""
    w.env.reset(seed=seed)
    return w.env.unwrapped.state.copy(), w.env.unwrapped.target.copy()
