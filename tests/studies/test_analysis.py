"""Benchmarks and reports (penny_env.analysis): quick modes run end to end, baselines are sane."""
from __future__ import annotations

import importlib.util
import subprocess
import sys

import numpy as np
import pytest

from studies import reference

# scipy (solve_ivp, the other integrators) and matplotlib (the plots) are optional extras ([bench], [plot])
needs_scipy = pytest.mark.skipif(importlib.util.find_spec("scipy") is None,
                                 reason="scipy (the penny-env[bench] extra) is not installed")
needs_matplotlib = pytest.mark.skipif(importlib.util.find_spec("matplotlib") is None,
                                      reason="matplotlib (the penny-env[plot] extra) is not installed")


PAPER = ("circle_elastic", "circle_plastic", "ellipse_elastic", "ellipse_plastic")


def test_import_penny_env_does_not_import_heavy_modules():
    code = ("import sys, penny_env, penny_env.physics; "
            "bad = [m for m in ('scipy', 'matplotlib', 'tqdm') if m in sys.modules]; "
            "assert not bad, bad")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_matching_counts_missed_and_spurious():
    from studies.matching import match_impacts
    t_ref = np.array([1.0, 2.0, 3.0, 4.0])
    e_ref = np.array([1, -1, 1, -1])
    # found: first two exact, third missing, a spurious one, fourth slightly off
    m = match_impacts(t_ref, e_ref, [1.0, 2.0 + 1e-9, 3.5, 4.0 + 1e-3], [1, -1, 1, -1])
    assert (m.matched, m.missed, m.spurious) == (3, 1, 1)
    assert m.max_abs_err == pytest.approx(1e-3)
    assert m.first_divergence == 2
    # wrong end never matches
    m = match_impacts(t_ref[:1], e_ref[:1], [1.0], [-1])
    assert (m.matched, m.missed, m.spurious) == (0, 1, 1)


def test_reference_loads_as_float64():
    scenes = reference.paper_scenes()
    assert [s.name for s in scenes] == list(PAPER)
    for s in scenes + reference.extra_scenes():
        assert s.impact_times.dtype == np.float64 and s.impact_states.shape == (s.n_impacts, 6)
        assert s.initial_state.shape == (6,) and s.state_at_t_final.shape == (6,)
        assert np.all(np.diff(s.impact_times) > 0) and set(np.unique(s.impact_ends)) <= {-1, 1}
    ctrl = [s for s in reference.extra_scenes() if s.controls is not None]
    assert ctrl and ctrl[0].controls.shape[1] == 2 and ctrl[0].control_dt > 0


@needs_scipy
def test_integrators_find_first_impacts_of_paper_elastic_circle():
    from studies.integrators import rk4_hybrid, run_simulate, run_step_path, solve_ivp_hybrid
    sc = reference.paper_scenes()[0]
    assert sc.name == "circle_elastic"
    kw = dict(params=sc.params, table=sc.table, law=sc.law, n_impacts=4, t_stop=20.0)
    cases = [(solve_ivp_hybrid(sc.initial_state, method="DOP853", rtol=1e-10, **kw), 1e-6),
             (solve_ivp_hybrid(sc.initial_state, method="RK45", rtol=1e-9, **kw), 1e-4),
             (rk4_hybrid(sc.initial_state, dt=1e-4, **kw), 1e-4),
             (run_simulate(sc.initial_state, **kw), 1e-2),
             (run_step_path(sc.initial_state, **kw), 1e-2)]
    for res, tol in cases:
        assert res.n_impacts == 4, res
        assert np.array_equal(res.impact_ends, sc.impact_ends[:4])
        assert np.max(np.abs(res.impact_times - sc.impact_times[:4])) < tol
        assert res.redetections == 0
        assert np.all(np.abs(res.wall_at_impact) < 1e-6)
    # the event solver restarts without re-detecting the impact it just applied
    res = solve_ivp_hybrid(sc.initial_state, method="DOP853", rtol=1e-12, **kw)
    assert np.min(np.diff(res.impact_times)) > 0.1


@needs_scipy
def test_bench_solvers_quick(reports_untouched):
    from studies import bench_solvers
    out = reports_untouched / "bench.md"
    rows = bench_solvers.main(["--quick", "--out", "bench.md"])
    text = out.read_text()
    for name in PAPER:
        assert f"| {name} |" in text
    assert "command: `python -m studies.bench_solvers --quick" in text and "CPU:" in text
    assert len(rows) == 4 and all(r["t_sim"] > 0 and r["t_ivp"] > 0 for r in rows)
    # elastic scenes: DOP853 at rtol 1e-12 finds all 20 impacts
    for r in rows:
        if r["scene"].endswith("elastic"):
            assert r["m_ivp"].matched == 20


@needs_scipy
@needs_matplotlib
def test_work_precision_quick(reports_untouched):
    from studies import work_precision
    tmp_path = reports_untouched / "sub"
    out = tmp_path / "wp.md"
    work_precision.main(["--quick", "--out", "sub/wp.md"])
    text = out.read_text()
    assert (tmp_path / "wp.png").stat().st_size > 10_000 and (tmp_path / "wp_state.png").stat().st_size > 10_000
    for label in ("penny_env simulate", "penny_env contact_tol sweep", "env step path", "solve_ivp RK45",
                  "solve_ivp DOP853", "RK4 + linear locator"):
        assert f"| {label}" in text
    for name in PAPER + ("stadium_elastic", "ellipse_elastic_controlled"):
        assert f"## {name}" in text
    assert "![work-precision, impact times](wp.png)" in text


def test_the_stability_hang_detector_has_ten_times_the_slowest_case(monkeypatch):
    # the long-horizon case took 112-117 s on a quiet 2-core machine, where the 120 s budget reported a FAIL
    from studies import stability
    budgets = []
    monkeypatch.setattr(stability, "run_case", lambda name, fn, quick, budget: (budgets.append(budget), ([], 0.0))[1])
    stability.main(["--only", "long horizon"])
    stability.main(["--quick", "--only", "long horizon"])
    assert budgets[0] >= 10 * 117 and budgets[1] >= 10 * 5


def test_stability_quick(reports_untouched):
    from studies import stability
    out = reports_untouched / "st.md"
    results = stability.main(["--quick", "--out", "st.md"])
    text = out.read_text()
    names = [name for name, _, _ in stability.CASES]
    assert [r[0] for r in results] == names
    for name in names:
        assert f"| {name} |" in text
    assert "checks passed" in text
    # every check reports a verdict and measurements; no case may hang or crash the runner (its budget, a hang
    # detector, is ten times the slowest case on a slow machine: issue 40)
    for name, _, rs, wall in results:
        assert rs
        for r in rs:
            assert isinstance(r["passed"], bool) and "measured" in r
            assert "no result within" not in " ".join(r["reasons"])
            # the small versions of every case keep the invariants: finite, inside, energy as the law says
            assert r["passed"], (name, r["label"], r["reasons"])
            assert r["measured"].get("finite", True) is True, (name, r["label"])


def test_progress_bars_are_optional(monkeypatch):
    """tqdm (and rich, for SB3's bar) are optional extras: without them the commands run without a bar."""
    from lab import common
    from training import train
    monkeypatch.setitem(sys.modules, "tqdm", None)  # import tqdm raises ImportError
    items = [1, 2, 3]
    assert common.progress(items, disable=False) is items
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name in ("tqdm", "rich") else object())
    assert train._progress_bar_installed() is False


def test_stability_expects_the_documented_refusal():
    # tables narrower than R (1 + MIN_GAP) are refused with a ValueError naming MIN_GAP; the harness
    # counted that refusal as a failure (3 of 64 checks)
    from studies import stability
    from penny_env.physics import Circle, PennyParams
    P = PennyParams()
    s0 = [0.0, 0.0, 0.0, 0.7, 2.0, 1.0]
    narrow = stability.sim_case(s0, P, Circle(P.R * (1 + 1e-8)), "elastic", t_final=0.1)
    assert narrow["passed"] and "MIN_GAP" in narrow["measured"]["refused"]
    wide = stability.sim_case(s0, P, Circle(P.R * (1 + 1e-3)), "elastic", t_final=0.1)
    assert "refused" not in wide["measured"] and wide["measured"]["impacts"] > 0
    accepted = stability.refused_case(lambda: None, "MIN_GAP")
    assert not accepted["passed"] and "accepted" in accepted["reasons"][0]
