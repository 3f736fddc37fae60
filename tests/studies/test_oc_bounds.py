"""The certified lower bounds of studies/oc_bounds.py on the plans that make them tight (issue 39, items 1 and 8).

Random plans never come near a bound (issue 39 item 1: halving the torque term of the old drive-only bound made it
wrong on 15 of 24 study pairs and every test passed). Here each bound meets the **extremal** plans: bang-bang
torques that move the end point farthest along a direction, and the plan nearest the target, computed by the test
from the simulator itself (the drive-only end point is affine in the torques: its generators are the simulated
responses to one row of torque each, not the module's formulas). Each check has a mutation test: with the torque
term halved (or the heading tube frozen) the same check must fail.
"""
import math

import numpy as np
import pytest

pytest.importorskip("scipy")
pytest.importorskip("mpmath")

import penny_env as pe  # noqa: E402
from studies import both_bound, drive_zonotope, oc_bounds  # noqa: E402
from studies import impact_oc as io  # noqa: E402
from studies.optimal_control import Problem  # noqa: E402

DRIVE_PAIRS = [("ellipse", 0), ("ellipse", 10), ("stadium", 0), ("stadium", 4)]  # bounds of 14 to 23 rows


def _plane_end(prob, v2):
    """The contact point after the drive-only rows v2 (scaled rolling torques) on the open plane."""
    u = np.zeros((len(v2), 2))
    u[:, 1] = np.asarray(v2, float) * prob.limits[1]
    tr = pe.simulate(prob.start, params=prob.params, table=None, law=prob.law, controls=u, control_dt=prob.dt)
    return tr.final_state[:2]


def _simulated_zonotopes(prob, K):
    """[(c, g)] for K' = 1..K rows: the end point of zero torques at K' dt and the responses to each row's full
    torque, read from K + 1 simulations on the open plane (the end point is affine in the torques)."""
    def run(v2):
        u = np.zeros((K, 2))
        u[:, 1] = v2 * prob.limits[1]
        tr = pe.simulate(prob.start, params=prob.params, table=None, law=prob.law, controls=u, control_dt=prob.dt)
        return tr.states_at(prob.dt * np.arange(1, K + 1))[:, :2]
    zero = run(np.zeros(K))
    resp = np.array([run(np.eye(K)[k]) - zero for k in range(K)])  # (row k, K', 2)
    return [(zero[n - 1], resp[:n, n - 1]) for n in range(1, K + 1)]


def _simulated_zonotope(prob, K):
    return _simulated_zonotopes(prob, K)[-1]


def _nearest(c, g, target):
    from scipy.optimize import lsq_linear

    return np.clip(lsq_linear(g.T, np.asarray(target) - c, bounds=(-1.0, 1.0), tol=1e-14).x, -1.0, 1.0)


def drive_violations(pairs):
    """Where the drive-only bound is wrong or not attained, on extremal plans: at every K' below the bound the plan
    nearest the target (bounded least squares on the simulated generators), and at K' = bound - 1 64 bang-bang plans
    (v_k = sign(d . g_k)), must end farther than the tolerance; at K = bound the nearest plan must end within it (the
    bound is the exact fewest rows of the plane)."""
    bad = []
    for scene, i in pairs:
        start, target = io.draw_pairs(scene, i + 1, 0)[i]
        prob = Problem(scene, "reach", start, target, impacts=True, actuation="drive")
        tol = prob.tolerance * (1 + oc_bounds.SLACK)
        K, reason = oc_bounds.rows_lower_bound(prob, "drive", max_rows=120)
        zonos = _simulated_zonotopes(prob, K)
        for n, (c, g) in enumerate(zonos[:-1], 1):  # every K' < K: the plan nearest the target
            v = _nearest(c, g, target)
            if np.linalg.norm(c + g.T @ v - target) <= tol * (1 + 1e-9):
                d = np.linalg.norm(_plane_end(prob, np.concatenate([v, np.zeros(K - n)])[:n]) - target)
                if d <= tol:
                    bad.append(f"{scene} {i}: a {n}-row plan ends {d:.5f} m from the target, bound {K}")
                    break
        c, g = zonos[-2] if K > 1 else (prob.start[:2], np.zeros((0, 2)))
        for t in np.linspace(0, 2 * math.pi, 64, endpoint=False):  # K - 1 rows: bang-bang along 64 directions
            sg = np.sign(g @ np.array([math.cos(t), math.sin(t)]))
            if len(sg) and np.linalg.norm(_plane_end(prob, np.where(sg == 0, 1.0, sg)) - target) <= tol:
                bad.append(f"{scene} {i}: a bang-bang plan of {K - 1} rows reaches the target, bound {K}")
                break
        c, g = _simulated_zonotope(prob, K)
        d = np.linalg.norm(_plane_end(prob, _nearest(c, g, target)) - target)
        if "exact" not in reason or d > tol * (1 + 1e-9):
            bad.append(f"{scene} {i}: the bound {K} ({reason}) is not attained: the nearest plan ends {d:.6f} m away")
    return bad


def test_drive_bound_is_exact_on_extremal_plans():
    assert drive_violations(DRIVE_PAIRS) == []


def test_drive_bound_check_fails_when_the_torque_term_is_halved(monkeypatch):
    true = oc_bounds.accelerations
    monkeypatch.setattr(oc_bounds, "accelerations", lambda prob: (true(prob)[0], 0.5 * true(prob)[1]))
    assert len(drive_violations(DRIVE_PAIRS)) >= 3


def test_drive_bound_check_fails_when_the_certificates_generators_are_halved(monkeypatch):
    """The float64 search cannot make the bound wrong (a float error only stops the certificate early); the
    interval formula can, and the check sees it."""
    true_iv, true_float = drive_zonotope.interval_zonotope, drive_zonotope.generators
    monkeypatch.setattr(drive_zonotope, "interval_zonotope",
                        lambda *a, **k: (lambda c, g: (c, [(x / 2, y / 2) for x, y in g]))(*true_iv(*a, **k)))
    monkeypatch.setattr(drive_zonotope, "generators", lambda *a, **k: (lambda c, g: (c, g / 2))(*true_float(*a, **k)))
    assert len(drive_violations(DRIVE_PAIRS)) >= 3


def test_drive_zonotope_is_the_simulators_end_point():
    start, target = io.draw_pairs("stadium", 1, 3)[0]
    prob = Problem("stadium", "reach", start, target, impacts=True, actuation="drive")
    a2 = oc_bounds.accelerations(prob)[1]
    c, g = drive_zonotope.generators(start[:2], start[3], start[5], start[4], prob.params.R, a2, prob.dt, 12)
    cs, gs = _simulated_zonotope(prob, 12)
    assert np.abs(c - cs).max() < 1e-15 and np.abs(g - gs).max() < 1e-15
    dist, angle = drive_zonotope.distance(target, c, g)
    assert dist == pytest.approx(np.linalg.norm(c + g.T @ _nearest(c, g, target) - target), abs=1e-12)


# -- both controls ------------------------------------------------------------------------------------------
def _both_plan_rows(prob, v):
    """The first row whose end is in the terminal set for the plan v (K, 2), on the open plane (impact-free)."""
    u = np.asarray(v, float) * prob.limits[None, :]
    tr = pe.simulate(prob.start, params=prob.params, table=None, law=prob.law, controls=u, control_dt=prob.dt)
    ends = tr.states_at(prob.dt * np.arange(1, len(v) + 1))
    hit = np.flatnonzero(io.in_set(prob, ends))
    return int(hit[0]) + 1 if hit.size else None


def _extremal_both_cases():
    """Problems with known bang-bang plans: rolling straight at a target ahead (full torque, then full braking to
    park), rolling away from a target behind (full braking, full reverse, full braking), and a target abeam reached
    by turning at full steering torque while rolling. Start at the stadium's centre, heading along x."""
    cases = []
    for w0, target, plan in (
            (3.0, (0.09, 0.0), "ahead"),
            (8.0, (-0.06, 0.0), "behind"),
            (6.0, (0.035, 0.035), "turn")):
        start = np.array([0.0, 0.0, 0.0, 0.0, w0, 0.0])
        prob = Problem("stadium", "park", start, np.array(target), impacts=True, actuation="both")
        cases.append((prob, plan))
    return cases


def _bang_bang_plans(prob, kind, K=40):
    """Plans of the kind, over every switching row: the test's own extremal candidates."""
    out = []
    for k1 in range(1, K):
        for k2 in range(k1, K):
            v = np.zeros((K, 2))
            if kind == "ahead":
                v[:k1, 1], v[k1:k2, 1], v[k2:, 1] = 1.0, -1.0, 0.0
            elif kind == "behind":
                v[:k1, 1], v[k1:k2, 1] = -1.0, 1.0
                v[k2:, 1] = 0.0
            else:  # turn left at full torque for k1 rows, back for k1 rows; brake from row k2
                v[:k1, 0], v[k1:2 * k1, 0] = 1.0, -1.0
                v[k2:, 1] = -1.0
            out.append(v)
    return out


def both_violations():
    """Where the both-controls bound (tent, then the directional programme) is above the rows a simulated bang-bang
    plan needs, or (rolling straight) more than 6 rows below the best of them (a check of tightness, not validity)."""
    bad = []
    for prob, kind in _extremal_both_cases():
        rows = [r for v in _bang_bang_plans(prob, kind) if (r := _both_plan_rows(prob, v)) is not None]
        assert rows, kind
        best = min(rows)
        K, _ = oc_bounds.rows_lower_bound(prob, "both", max_rows=best + 1)
        if best < K:
            bad.append(f"{kind}: a bang-bang plan parks in {best} rows, the bound says {K}")
        elif kind != "turn" and K < best - 6:
            bad.append(f"{kind}: the bound {K} is far below the best bang-bang plan's {best} rows")
    return bad


def test_both_bound_holds_and_is_near_tight_on_bang_bang_plans():
    assert both_violations() == []


def test_both_bound_check_fails_when_the_torque_term_is_halved(monkeypatch):
    true = oc_bounds.accelerations
    monkeypatch.setattr(oc_bounds, "accelerations", lambda prob: (true(prob)[0], 0.5 * true(prob)[1]))
    assert len([b for b in both_violations() if "the bound says" in b]) >= 2


def test_both_bound_check_fails_when_the_heading_tube_is_frozen(monkeypatch):
    """The directional programme without the steering's reach (the heading kept at phi0) is wrong for a penny
    that turns toward a target abeam."""
    def frozen(phi0, w, a1, psi, dt, K, m=both_bound.PARTS):
        c = math.cos(phi0 - psi)
        return np.full((K, m), c), np.full((K, m), c)
    monkeypatch.setattr(both_bound, "heading_cos_rows", frozen)
    both_bound._COS_CACHE.clear()
    try:
        assert any(b.startswith("turn") and "the bound says" in b for b in both_violations())
    finally:
        both_bound._COS_CACHE.clear()


def test_both_bound_validated_pieces():
    """The heading bounds enclose cos over the tube (sampled densely: a check of the code, not the proof); the
    programme's value is at least the displacement of simulated plans along the direction."""
    cmax, cmin = both_bound.heading_cos_rows(0.3, -0.7, 10.0, 1.1, 0.05, 8)
    rng = np.random.default_rng(2)
    for k in range(8):
        for s in range(both_bound.PARTS):
            t = 0.05 * (k + (s + rng.uniform(0, 1, 400)) / both_bound.PARTS)
            phi = 0.3 - 0.7 * t + rng.uniform(-1, 1, 400) * 5.0 * t * t
            c = np.cos(phi - 1.1)
            assert cmin[k, s] <= c.min() and c.max() <= cmax[k, s]
    prob = _extremal_both_cases()[1][0]
    for v in _bang_bang_plans(prob, "behind", K=12)[::7]:
        u = v * prob.limits[None, :]
        tr = pe.simulate(prob.start, params=prob.params, table=None, law=prob.law, controls=u, control_dt=prob.dt)
        psi = math.pi
        moved = math.cos(psi) * (tr.final_state[0] - prob.start[0]) + math.sin(psi) * (tr.final_state[1] - prob.start[1])
        a1, a2 = oc_bounds.accelerations(prob)
        up = both_bound.displacement_upper(prob.start[4], prob.start[3], prob.start[5], psi, prob.params.R, a1, a2,
                                           prob.dt, 12, math.inf)
        assert moved <= up


def enclosure_violations(Ks=(4, 10, 20), h_steps=2, m=64):
    """Where the directional programme's value is below what a simulated plan travels along the direction, or more
    than R a2 dt T / m above it: rolling at full torque along the heading (psi = phi0) and at full reverse torque
    against it (psi = phi0 + pi), no steering, on the open plane, no end condition. The programme runs at 2 cells per
    a2 dt and 64 parts per row (every resolution is rigorous): the parts' slack (about R a2 dt T / (2 m)) is then far
    below half a cell, so a programme that took each theta_dot cell to be its midpoint (not an enclosure) falls below
    these plans, which run along the cells' edges, by about R h T / 2."""
    prob = _extremal_both_cases()[0][0]
    a1, a2 = oc_bounds.accelerations(prob)
    s0, R, dt = prob.start, prob.params.R, prob.dt
    bad = []
    for K in Ks:
        for sign in (1.0, -1.0):
            u = np.zeros((K, 2))
            u[:, 1] = sign * prob.limits[1]
            tr = pe.simulate(s0, params=prob.params, table=None, law=prob.law, controls=u, control_dt=dt)
            psi = s0[3] + (0.0 if sign > 0 else math.pi)
            moved = math.cos(psi) * (tr.final_state[0] - s0[0]) + math.sin(psi) * (tr.final_state[1] - s0[1])
            up = both_bound.displacement_upper(s0[4], s0[3], s0[5], psi, R, a1, a2, dt, K, math.inf, h_steps, m)
            if not moved <= up <= moved + R * a2 * dt * K * dt / m:
                bad.append(f"K = {K}, torque {sign:+.0f}: the programme's {up:.6g} m, the plan's {moved:.6g} m")
    return bad


def test_both_bound_encloses_the_rolling_speed_cells():
    """The directional programme is at least the displacement of the full-torque plans, which run along the cells'
    edges, and within R a2 dt T / m of it (tight on these plans)."""
    assert enclosure_violations() == []


def test_both_bound_check_fails_when_the_cells_are_their_midpoints(monkeypatch):
    """The mutation of the referee: the rolling-speed cells replaced by their midpoints (no enclosure), which changes
    none of the 5 certified bounds, falls below every full-torque plan here."""
    def midpoints(w0, h, N):
        mid = w0 + (np.arange(-N, N, dtype=float) + 0.5) * h
        return mid, mid
    monkeypatch.setattr(both_bound, "cell_enclosures", midpoints)
    assert len(enclosure_violations()) == 6


# -- the certified pairs of the report (docs/optimal_control_certificates.json) -------------------------------
def _certificates():
    import json
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "docs" / "optimal_control_certificates.json"
    return json.loads(path.read_text())


@pytest.mark.parametrize("actuation", ["both", "drive"])
def test_a_certified_pair_replays_in_the_env_and_beats_the_bound(actuation):
    """Issue 39 item 8: the report's certified pair with the fewest rows: its plan with impacts (found by the package's
    optimizer) is replayed as an episode of the probe's environment and succeeds at its row count with impacts, and
    the validated bound recomputed here allows no impact-free plan that many rows."""
    import gymnasium as gym

    cands = [c for c in _certificates() if c["actuation"] == actuation]
    assert cands, f"no certified {actuation} pair in the report"
    c = min(cands, key=lambda x: x["bound_rows"])
    env = gym.make(io.probe_id(c["scene"], actuation), **({"spin_tolerance": None} if c["task"] == "park" else {}))
    env.reset(options={"state": np.array(c["start"]), "target": np.array(c["target"])})
    impacts, steps, info = 0, 0, {}
    for a in np.array(c["plan"]):
        act = a if actuation == "both" else a[[1]]
        _, _, term, trunc, info = env.step(np.asarray(act, np.float64))
        impacts, steps = impacts + info["impacts"], steps + 1
        if term or trunc:
            break
    env.close()
    assert info["is_success"] and steps == c["rows"] == c["env_steps"] and impacts >= 1
    prob = Problem(c["scene"], c["task"], np.array(c["start"]), np.array(c["target"]), impacts=True,
                   actuation=actuation)
    K, _ = oc_bounds.rows_lower_bound(prob, actuation, max_rows=c["rows"] + 1)
    assert K > c["rows"]


def test_every_certified_plan_replays_with_a_margin():
    """Every certificate's plan replays in the probe's environment to success with its end at least REPLAY_MARGIN
    (1e-9) inside the success set, the margin the file records; a plan that met the strict test by a rounding (the
    referee's stadium pair 1 ended 3e-15 m inside its 0.015 m tolerance; three more did) is re-solved inside by
    `python -m studies.impact_oc --recertify`."""
    for c in _certificates():
        row = {k: c[k] for k in ("scene", "actuation", "task", "start", "target")}
        ok, steps, n_imp, margin = io.env_replay(row, np.asarray(c["plan"], float))
        assert ok and steps == c["env_steps"] == c["rows"] and n_imp == c["env_impacts"], (c["scene"], c["pair"])
        assert margin >= io.REPLAY_MARGIN and margin == pytest.approx(c["env_margin"], abs=1e-15), (c, margin)


def test_a_plan_that_ends_within_the_margin_is_resolved_inside():
    """The margin rule of studies.impact_oc.inside_plan: the same plan, with its target moved so that it ends 5e-10 m
    inside the tolerance, succeeds in the env yet is not counted as found: it is re-solved into the shrunk set and the
    re-solved plan replays with a margin."""
    c = min((c for c in _certificates() if c["actuation"] == "drive"), key=lambda c: c["rows"])
    row = {k: c[k] for k in ("scene", "actuation", "task", "start", "target")}
    v = np.asarray(c["plan"], float)
    prob = Problem(c["scene"], c["task"], np.array(c["start"]), np.array(c["target"]), impacts=True,
                   actuation="drive")
    u = np.zeros((len(v), 2))
    u[:, 1] = v[:, 1] * prob.limits[1]
    end = pe.simulate(prob.start, params=prob.params, table=prob.table, law=prob.law, controls=u,
                      control_dt=prob.dt).final_state[:2]
    away = (np.asarray(c["target"]) - end) / np.linalg.norm(np.asarray(c["target"]) - end)
    row["target"] = list(end + (prob.tolerance - 5e-10) * away)
    ok, _, _, margin = io.env_replay(row, v)
    assert ok and 0 < margin < io.REPLAY_MARGIN
    prob = Problem(c["scene"], c["task"], np.array(c["start"]), np.array(row["target"]), impacts=True,
                   actuation="drive")
    v2, ok2, _, _, how, margin2 = io.inside_plan(row, prob, v)
    assert how.startswith("re-solved") and ok2 and margin2 >= io.REPLAY_MARGIN
