"""The simulator against the independent 50-digit mpmath reference (tests/reference/).

Impact times are compared to 1e-10 s and post-impact states to 1e-9 relative wherever the
impact is well conditioned. A grazing impact is not: its time moves by (position round-off) /
(normal speed), and float64 positions carry ~4e-17 m of round-off on a 0.2 m table. The
reference records each impact's relative normal speed; below 1e-5 the tolerance becomes that
conditioning bound (docs/physics.md, "Accuracy limits").
"""
import json
from pathlib import Path

import numpy as np
import pytest

import penny_env as pe

DATA = Path(__file__).parents[2] / "studies" / "reference_data"
WELL_CONDITIONED = 1e-5  # relative normal speed at impact
POSITION_ROUNDOFF = 64 * 2.2e-16 * 0.2  # metres: a few ulps of the table's size


def _load(name):
    return json.loads((DATA / name).read_text())["scenes"]


def _table(spec):
    f = {k: float(v) for k, v in spec.items() if k != "type"}
    if spec["type"] == "stadium":
        return pe.Stadium(f["radius"], f["length"])
    if spec["type"] == "rounded_rectangle":
        return pe.RoundedRectangle(f["width"], f["height"], f["radius"])
    return pe.Circle(f["a"]) if f["a"] == f["b"] else pe.Ellipse(f["a"], f["b"])


def _params(spec):
    return pe.PennyParams(**{k: float(v) for k, v in spec.items()})


def _law(sc):
    return float(sc["restitution"]) if sc["law"] == "restitution" else sc["law"]


def _arr(v):
    return np.array(v, dtype=float) if not isinstance(v[0], list) else np.array([[float(x) for x in r] for r in v])


def _state_close(ours, ref, rtol):
    """Componentwise, relative to the component's own size or its group's scale."""
    scale = np.array([np.hypot(ref[0], ref[1]), np.hypot(ref[0], ref[1]), 1 + abs(ref[2]), 1 + abs(ref[3]),
                      np.hypot(ref[4], ref[5]), np.hypot(ref[4], ref[5])])
    return np.abs(ours - ref) <= rtol * np.maximum(np.abs(ref), scale)


def _speed_of_end(state, params):
    return params.R * np.hypot(state[4], state[5])


def _ulp_spread(run, state):
    """How far impact times move when the initial state is nudged by a few ulps: the float64
    sensitivity of the scene (chaotic scenes amplify round-off impact by impact)."""
    base = run(state).impact_times
    spread = np.zeros_like(base)
    for k in range(6):
        nudged = state.copy()
        nudged[k] = np.nextafter(np.nextafter(state[k], np.inf), np.inf)
        other = run(nudged).impact_times
        n = min(len(other), len(base))
        spread[:n] = np.maximum(spread[:n], np.abs(other[:n] - base[:n]))
    return spread


PAPER = _load("paper_scenes.json")
EXTRA = _load("extra_scenes.json")
ROUNDED = _load("rounded_rectangle_scenes.json")


@pytest.mark.parametrize("sc", PAPER, ids=[s["name"] for s in PAPER])
def test_paper_scene_first_20_impacts(sc):
    params, table = _params(sc["params"]), _table(sc["table"])
    tr = pe.simulate(_arr(sc["initial_state"]), params=params, table=table, law=_law(sc), n_impacts=20)
    ref_t, ref_e = _arr(sc["impact_times"])[:20], np.array(sc["impact_ends"][:20])
    ref_s = _arr(sc["impact_states"])[:20]
    rel_speed = np.array(sc["diagnostics"]["impact_rel_normal_speed"][:20])
    well = rel_speed >= WELL_CONDITIONED
    k = int(np.argmin(well)) if not well.all() else 20  # well conditioned up to here
    assert tr.n_impacts == 20
    assert np.array_equal(tr.impact_ends[:k], ref_e[:k])
    # 1e-10 s, or the scene's own float64 sensitivity where that is larger (the elastic ellipse
    # amplifies round-off ~5e3-fold over 20 impacts: a 2-ulp nudge of the start moves impact 20 by ~1e-10 s)
    spread = _ulp_spread(lambda s0: pe.simulate(s0, params=params, table=table, law=_law(sc), n_impacts=20),
                         _arr(sc["initial_state"]))
    assert np.all(np.abs(tr.impact_times[:k] - ref_t[:k]) <= np.maximum(1e-10, 4 * spread[:k]))
    for i in range(k):
        assert _state_close(tr.impact_states[i], ref_s[i], 1e-9).all(), i
    # grazing impacts: found, with the end sequence kept, as long as float64 can resolve them
    # (normal speed above the speed at which a round-off-deep graze hits: sqrt(2 a delta))
    for i in range(k, 20):
        v_n = rel_speed[i] * _speed_of_end(ref_s[i - 1], params)
        if v_n < 1e-7:
            break
        assert tr.impact_ends[i] == ref_e[i], i
        assert abs(tr.impact_times[i] - ref_t[i]) <= 1e-10 + 100 * POSITION_ROUNDOFF / v_n, i


@pytest.mark.parametrize("sc", PAPER, ids=[s["name"] for s in PAPER])
def test_paper_scene_state_at_5s(sc):
    params, table = _params(sc["params"]), _table(sc["table"])
    tr = pe.simulate(_arr(sc["initial_state"]), params=params, table=table, law=_law(sc), t_final=5.0)
    assert tr.final_time == 5.0
    assert tr.n_impacts == sc["n_impacts_before_t_final"]
    assert _state_close(tr.final_state, _arr(sc["state_at_5"]), 1e-9).all()


@pytest.mark.parametrize("sc", EXTRA + ROUNDED, ids=[s["name"] for s in EXTRA + ROUNDED])
def test_extra_scenes(sc):
    params, table = _params(sc["params"]), _table(sc["table"])
    kw = {}
    if "controls" in sc:
        kw = dict(controls=_arr(sc["controls"]), control_dt=float(sc["control_interval"]))
    t_final = float(sc["t_final"])
    tr = pe.simulate(_arr(sc["initial_state"]), params=params, table=table, law=_law(sc),
                     t_final=t_final if kw else None, n_impacts=None if kw else len(sc["impact_times"]), **kw)
    n = len(sc["impact_times"])
    assert tr.n_impacts == n
    assert np.array_equal(tr.impact_ends, np.array(sc["impact_ends"]))
    spread = _ulp_spread(lambda s0: pe.simulate(s0, params=params, table=table, law=_law(sc),
                                                t_final=t_final if kw else None, n_impacts=None if kw else n, **kw),
                         _arr(sc["initial_state"]))
    assert np.all(np.abs(tr.impact_times - _arr(sc["impact_times"])) <= 1e-10 + 100 * spread)
    sensitive = spread > 1e-12
    for i, (ours, ref) in enumerate(zip(tr.impact_states, _arr(sc["impact_states"]))):
        assert _state_close(ours, ref, 1e-9 if not sensitive[: i + 1].any() else 1e-6).all(), i
    key = next(k for k in sc if k.startswith("state_at_"))
    at = tr if kw else pe.simulate(_arr(sc["initial_state"]), params=params, table=table, law=_law(sc), t_final=t_final, **kw)
    assert _state_close(at.final_state, _arr(sc[key]), 1e-9).all()


@pytest.mark.parametrize("backend", ["python", "numba"])
@pytest.mark.parametrize("sc", ROUNDED, ids=[s["name"] for s in ROUNDED])
def test_rounded_rectangle_batch_against_reference(sc, backend):
    # the batch API (the per-penny loop, plain and compiled) to t = 3 s: the impacts before 3 s and
    # the state at 3 s; the reference also records which piece of the wall each impact hit
    if backend == "numba":
        pytest.importorskip("numba", reason="the compiled backend needs numba")
    import penny_env.batch as pb
    params, table = _params(sc["params"]), _table(sc["table"])
    s0 = _arr(sc["initial_state"])
    res = pb.simulate(s0[None], params=params, table=table, law=_law(sc), t_final=3.0, backend=backend)
    n = sc["n_impacts_before_t_final"]
    assert res.impact_counts[0] == n
    ref_t = _arr(sc["impact_times"])[:n]
    assert np.all(np.abs(res.impact_times[: len(ref_t)] - ref_t) <= 1e-9)
    assert np.array_equal(res.impact_ends[: len(ref_t)], np.array(sc["impact_ends"][:n]))
    assert _state_close(res.final_states[0], _arr(sc["state_at_3"]), 1e-8).all()
    assert {"corner" in p for p in sc["impact_wall_pieces"]} == {True, False} or sc["law"] != "elastic"


FLOWS = json.loads((DATA / "flow_cases.json").read_text())["cases"]
MAPS = json.loads((DATA / "impact_map_cases.json").read_text())["cases"]


@pytest.mark.parametrize("case", FLOWS, ids=[c["tag"] for c in FLOWS])
def test_flow_cases(case):
    from penny_env.physics.flows import flow

    p = _params(case["params"])
    s0, ref = _arr(case["state0"]), _arr(case["state_t"])
    acc1, acc2, t = float(case["u1"]) / p.J, float(case["u2"]) / p.rolling_inertia, float(case["t"])
    out = flow(s0[:, None], acc1, acc2, t, p.R)[:, 0]
    # round-off of the phase argument (eps |phi|) moves the contact point by R |theta_dot| t eps |phi|
    phase = abs(ref[3]) + abs(s0[3])
    travel = p.R * max(abs(s0[4]), abs(ref[4])) * t
    pos_tol = 8e-16 * (abs(s0[0]) + abs(s0[1]) + abs(ref[0]) + abs(ref[1]) + travel * (1 + phase))
    assert abs(out[0] - ref[0]) <= pos_tol and abs(out[1] - ref[1]) <= pos_tol, case["tag"]
    np.testing.assert_allclose(out[2:], ref[2:], rtol=2e-15, atol=1e-300)


@pytest.mark.parametrize("case", MAPS, ids=[f"case{c['case']}" for c in MAPS])
def test_impact_map_cases(case):
    p = _params(case["params"])
    table = _table(case["table"])
    pre, end = _arr(case["pre_state"]), int(case["end"])
    scale = np.hypot(pre[4], pre[5])
    for law, key in (("elastic", "post_elastic"), (float(case["restitution_e"]), "post_restitution"),
                     ("plastic", "post_plastic")):
        ours = pe.impact_map(pre, params=p, table=table, end=end, law=law)
        ref = _arr(case[key])
        if law == "plastic" and case["plastic_end_still_moving_outward"]:
            # documented: the normal velocity left by pi_Delta o P is removed (sticking)
            c, sn = np.cos(pre[3]), np.sin(pre[3])
            hx, hy = table.grad(pre[0] + end * p.R * c, pre[1] + end * p.R * sn)
            vn = p.R * ours[4] * (hx * c + hy * sn) + end * p.R * ours[5] * (hy * c - hx * sn)
            assert abs(vn) <= 1e-12 * p.R * scale
            continue
        np.testing.assert_array_equal(ours[:4], pre[:4])
        np.testing.assert_allclose(ours[4:], ref[4:], rtol=1e-12, atol=1e-13 * scale)
