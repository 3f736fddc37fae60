"""Derivatives through impacts: simulate(..., sensitivities=True) (penny_env/physics/sensitivity.py).

Checked against 50-digit finite differences of an independent mpmath simulator
(tests/reference/make_sensitivity_reference.py, data committed), against float64 finite differences
on random inputs (hypothesis), and by the volume law det(jacobian) = prod e_i^2 (elastic: 1)."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

import penny_env as pe
from penny_env.physics import Circle, ConvexTable, Ellipse, Stadium
from penny_env.physics.laws import normal_form
from penny_env.physics.laws import law_jacobian
from penny_env.physics.sensitivity import phase_moments

DATA = Path(__file__).parents[2] / "studies" / "reference_data" / "sensitivity_cases.json"
TABLES = {"ellipse": Ellipse(0.15, 0.2), "circle": Circle(0.2), "stadium": Stadium(0.1, 0.2)}
STATE_SCALE = np.array([0.1, 0.1, 1.0, 1.0, 10.0, 1.0])


def central_differences(fun, x, steps):
    cols = []
    for i, h in enumerate(steps):
        e = np.zeros(len(x))
        e[i] = h
        cols.append((fun(x + e) - fun(x - e)) / (2.0 * h))
    return np.array(cols).T


def richardson_differences(fun, x, steps):
    """(estimate, error bound) of the Jacobian of fun: central differences at steps and steps / 2,
    Richardson-extrapolated; the bound is 10 x their difference (truncation) plus the round-off
    64 eps |fun| / step, so the tolerance follows the step size and the function's curvature."""
    big = central_differences(fun, x, steps)
    small = central_differences(fun, x, np.asarray(steps) / 2)
    scale = np.max(np.abs(fun(x)))
    err = 10.0 * np.abs(small - big) + 64 * np.finfo(float).eps * scale / (np.asarray(steps)[None, :] / 2)
    return (4.0 * small - big) / 3.0, err


def _reference_cases():
    return json.loads(DATA.read_text())["cases"]


@pytest.mark.parametrize("case", _reference_cases(), ids=lambda c: c["name"])
def test_jacobians_match_50_digit_reference(case):
    t = case["table"]
    table = (Ellipse(float(t["a"]), float(t["b"])) if t["kind"] == "ellipse"
             else Stadium(float(t["radius"]), float(t["length"])))
    law = float(case["e"]) if case["law"] == "restitution" else case["law"]
    kw = dict(table=table, law=law, sensitivities=True)
    if case["controls"] is not None:
        kw.update(controls=np.array(case["controls"], dtype=float), control_dt=float(case["control_dt"]))
    else:
        kw.update(t_final=float(case["t_final"]))
    traj = pe.simulate(np.array(case["state"], dtype=float), **kw)
    assert traj.impact_ends.tolist() == case["impact_ends"]
    assert traj.n_impacts >= 2 and traj.jacobian_valid, traj.jacobian_reason
    ref = np.array(case["jacobian"], dtype=float)
    # float64 trajectories through a few impacts agree with the reference to ~1e-12 (the final state's own
    # error); the Jacobian's relative error is of the same order
    assert np.max(np.abs(traj.jacobian - ref)) <= 1e-10 * np.max(np.abs(ref))
    if case["controls"] is not None:
        cref = np.array(case["control_jacobian"], dtype=float)
        col = np.max(np.abs(cref), axis=0)
        assert np.all(np.max(np.abs(traj.control_jacobian - cref), axis=0) <= 1e-10 * col)


def test_reference_covers_tables_laws_ends_and_controls():
    cases = _reference_cases()
    assert {c["table"]["kind"] for c in cases} == {"ellipse", "stadium"}
    assert {c["law"] for c in cases} == {"elastic", "plastic", "restitution"}
    assert {e for c in cases for e in c["impact_ends"]} == {1, -1}
    assert sum(c["controls"] is not None for c in cases) >= 3


def test_sensitivities_do_not_change_the_trajectory():
    s0 = np.array([0.01, -0.02, 0.3, 1.1, 40.0, 0.5])
    u = np.array([[3e-8, 1e-6], [-2e-8, -2e-6]])
    for kw in (dict(t_final=0.6), dict(controls=u, control_dt=0.3), dict(n_impacts=3)):
        a = pe.simulate(s0, table=TABLES["ellipse"], law="plastic", **kw)
        b = pe.simulate(s0, table=TABLES["ellipse"], law="plastic", sensitivities=True, **kw)
        assert np.array_equal(a.final_state, b.final_state) and np.array_equal(a.impact_times, b.impact_times)
        assert a.jacobian is None and b.jacobian.shape == (6, 6)


def test_sensitivities_must_be_bool():
    with pytest.raises(TypeError, match="sensitivities"):
        pe.simulate(np.zeros(6), table=TABLES["circle"], t_final=1.0, sensitivities="yes")


def test_stop_at_impact_moves_the_final_time():
    """n_impacts: the run ends at the impact, whose time depends on the start: final_time_gradient."""
    s0 = np.array([0.01, -0.02, 0.3, 1.1, 40.0, 0.5])
    kw = dict(table=TABLES["stadium"], law=0.7, n_impacts=3)
    traj = pe.simulate(s0, sensitivities=True, **kw)
    assert traj.jacobian_valid
    steps = 1e-7 * STATE_SCALE
    fd = central_differences(lambda s: pe.simulate(s, **kw).final_state, s0, steps)
    fd_t = central_differences(lambda s: np.array([pe.simulate(s, **kw).final_time]), s0, steps)[0]
    assert np.max(np.abs(traj.jacobian - fd)) <= 1e-5 * np.max(np.abs(fd))
    assert np.max(np.abs(traj.final_time_gradient - fd_t)) <= 1e-5 * np.max(np.abs(fd_t))
    assert np.abs(traj.final_time_gradient).max() > 0


def test_open_plane_and_convex_table_without_hessian():
    s0 = np.array([0.0, 0.01, 0.0, 0.7, 45.0, -0.6])
    side = 0.15
    table = ConvexTable(lambda x, y: (x**4 + y**4 - side**4) / (4 * side**3),
                        lambda x, y: (x**3 / side**3, y**3 / side**3),
                        grad_bound=2 ** 0.25, hessian_bound=3 * 2 ** 0.5 / side, extent=(-0.2, 0.2, -0.2, 0.2))
    for tab, tol in ((None, 1e-6), (table, 1e-5)):
        kw = dict(table=tab, t_final=0.5)
        traj = pe.simulate(s0, sensitivities=True, **kw)
        assert traj.jacobian_valid
        if tab is not None:
            assert traj.n_impacts >= 2
        fd = central_differences(lambda s: pe.simulate(s, **kw).final_state, s0, 1e-7 * STATE_SCALE)
        assert np.max(np.abs(traj.jacobian - fd)) <= tol * np.max(np.abs(fd))


def test_zeno_rest_has_no_derivative():
    traj = pe.simulate(np.array([0.185, 0.0, 0.0, 0.0, 5.0, 0.0]), table=TABLES["circle"], law=0.3,
                       controls=np.array([[0.0, 2e-5]] * 2), control_dt=0.25, sensitivities=True)
    assert traj.rest_times.size and traj.jacobian_valid is False and "Zeno" in traj.jacobian_reason
    assert np.isnan(traj.jacobian).all() and np.isnan(traj.control_jacobian).all()


def _grazing_start(eps):
    """A start whose ends circle (uncontrolled) with their circle eps outside the round table's wall."""
    R, r, W, w = 0.01, 0.2, 5.0, 1.0
    rho = R * W / w
    c = r + eps - math.hypot(R, rho)
    return np.array([math.sqrt(c * c - rho * rho), 0.0, 0.0, 0.0, W, w])


def test_grazing_impact_has_no_derivative():
    graze = pe.simulate(_grazing_start(2e-15), table=TABLES["circle"], t_final=2.0, sensitivities=True)
    assert graze.n_impacts >= 1 and graze.impact_normal_speeds[0] < 1e-6
    assert graze.jacobian_valid is False and "grazing" in graze.jacobian_reason and np.isnan(graze.jacobian).all()
    shallow = pe.simulate(_grazing_start(1e-7), table=TABLES["circle"], t_final=2.0, sensitivities=True)
    assert shallow.jacobian_valid and 1e-4 < shallow.impact_normal_speeds[0] < 1e-2


def test_incomplete_run_has_no_derivative_at_fixed_time():
    # circles far from the wall: n_impacts never reached, the run stops after a period set by phi_dot
    traj = pe.simulate(np.array([0.0, 0.0, 0.0, 0.0, 8.0, 3.0]), table=TABLES["ellipse"], n_impacts=2,
                       sensitivities=True)
    assert not traj.complete and traj.jacobian_valid is False and "n_impacts" in traj.jacobian_reason


def test_phase_moments_against_closed_form():
    # phi = phi0 + w s (acc1 = 0): int_0^t s^k e^{i phi} ds in closed form by repeated integration by parts
    phi0, w, t = 0.4, 7.0, 1.3
    C, S = phase_moments(phi0, w, 0.0, t)
    z = np.exp(1j * phi0)
    I0 = z * (np.exp(1j * w * t) - 1) / (1j * w)
    I1 = z * (t * np.exp(1j * w * t) / (1j * w)) - I0 / (1j * w)
    assert abs(C[0] + 1j * S[0] - I0) < 1e-15 and abs(C[1] + 1j * S[1] - I1) < 1e-15


def test_law_jacobian_against_finite_differences():
    p = pe.PennyParams()
    args = (3.0, -1.5, 0.004, -0.007, 0.9)
    for e, plastic in ((1.0, False), (0.4, False), (0.0, True)):
        f = lambda v: np.array(law_jacobian(*v, e, plastic, p.rolling_inertia, p.J, p.m)[0])  # noqa: E731
        _, D = law_jacobian(*args, e, plastic, p.rolling_inertia, p.J, p.m)
        x = np.array(args)
        fd = central_differences(f, x, 1e-6 * np.abs(x))
        assert np.allclose(D, fd, rtol=1e-6, atol=1e-9 * np.abs(fd).max())


def test_plastic_sticking_branch_derivative():
    """A heavy rolling inertia (I > m R^2) makes the plastic law leave a nearly head-on end moving outward:
    the simulator removes the normal velocity (the e = 0 law); the Jacobian follows that branch."""
    p = pe.PennyParams(I=3e-7)
    s0 = np.array([-0.011, -0.043, 0.0, -0.14, 33.0, -1.2])
    # one interval (zero torques held 0.6 s): the stuck end sits on the wall, where flowing across an interval
    # boundary (runs to t_final alone take 0.1 s intervals) can round into a repeated touch, i.e. a Zeno rest
    kw = dict(params=p, table=TABLES["circle"], law="plastic", controls=[[0.0, 0.0]], control_dt=0.6)
    traj = pe.simulate(s0, sensitivities=True, **kw)
    assert traj.n_impacts == 1 and traj.jacobian_valid
    a, b, _ = normal_form(traj.impact_states.T, float(traj.impact_ends[0]), p, TABLES["circle"])
    post = traj.impact_states[0]
    assert abs(a[0] * post[4] + b[0] * post[5]) < 1e-12  # stuck: no normal velocity left
    fd = central_differences(lambda s: pe.simulate(s, **kw).final_state, s0, 1e-7 * STATE_SCALE)
    assert np.max(np.abs(traj.jacobian - fd)) <= 1e-5 * np.max(np.abs(fd))
    # e = 0: the normal direction of the velocity is lost, the Jacobian is singular
    assert abs(np.linalg.det(traj.jacobian)) < 1e-8


hypothesis = pytest.importorskip("hypothesis", reason="property tests need hypothesis")
from hypothesis import HealthCheck, assume, event, given, settings, strategies as st  # noqa: E402


@st.composite
def scenes(draw):
    table = TABLES[draw(st.sampled_from(sorted(TABLES)))]
    law = draw(st.one_of(st.sampled_from(["elastic", "plastic"]), st.floats(0.2, 0.95)))
    x, y = draw(st.floats(-0.05, 0.05)), draw(st.floats(-0.05, 0.05))
    state = np.array([x, y, draw(st.floats(-3, 3)), draw(st.floats(-math.pi, math.pi)),
                      draw(st.floats(20.0, 50.0)) * draw(st.sampled_from([-1.0, 1.0])), draw(st.floats(-2.0, 2.0))])
    k = draw(st.integers(0, 3))
    controls = None
    if k:
        controls = np.array([[draw(st.floats(-5e-8, 5e-8)), draw(st.floats(-2e-6, 2e-6))] for _ in range(k)])
    return table, law, state, controls


def _run(table, law, state, controls, sens=False):
    if controls is None:
        return pe.simulate(state, table=table, law=law, t_final=1.0, sensitivities=sens)
    return pe.simulate(state, table=table, law=law, controls=controls, control_dt=1.0 / len(controls),
                       sensitivities=sens)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
@given(scenes())
def test_jacobian_matches_float64_finite_differences(scene):
    table, law, state, controls = scene
    traj = _run(table, law, state, controls, sens=True)
    assume(traj.jacobian_valid and traj.n_impacts <= 6)
    # finite differences are only meaningful where nearby starts have the same impacts, well off grazing
    assume(traj.n_impacts == 0 or traj.impact_normal_speeds.min() > 0.05)
    event(f"impacts: {min(traj.n_impacts, 3)}{'+' if traj.n_impacts >= 3 else ''}")
    ends = traj.impact_ends.tolist()

    def final(s):
        t = _run(table, law, s, controls)
        assume(t.impact_ends.tolist() == ends)
        return t.final_state

    fd, err = richardson_differences(final, state, 1e-6 * STATE_SCALE)
    scale = np.max(np.abs(fd))
    assert np.all(np.abs(traj.jacobian - fd) <= err + 1e-7 * scale)
    if controls is not None:

        def final_u(v):
            t = _run(table, law, state, v.reshape(-1, 2))
            assume(t.impact_ends.tolist() == ends)
            return t.final_state

        cfd, cerr = richardson_differences(final_u, controls.ravel(), 1e-4 * np.array([5e-8, 2e-6] * len(controls)))
        col = np.max(np.abs(cfd), axis=0)
        assert np.all(np.abs(traj.control_jacobian - cfd) <= cerr + 1e-7 * col)


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
@given(scenes())
def test_volume_law(scene):
    """det(jacobian) = prod over impacts of e^2: the flow keeps volume (its Jacobian is unit triangular) and
    an impact's saltation matrix has det = det(D Delta) (grad g . f+)/(grad g . f-) = (-e)(-e). Elastic: 1."""
    table, law, state, controls = scene
    assume(law != "plastic")
    traj = _run(table, law, state, controls, sens=True)
    assume(traj.jacobian_valid and traj.n_impacts <= 8)
    assume(traj.n_impacts == 0 or traj.impact_normal_speeds.min() > 1e-3)
    event(f"impacts: {min(traj.n_impacts, 3)}{'+' if traj.n_impacts >= 3 else ''}")
    e = 1.0 if law == "elastic" else law
    expected = e ** (2 * traj.n_impacts)
    assert np.linalg.det(traj.jacobian) == pytest.approx(expected, rel=1e-6)


def test_batched_flow_jacobians_match_one_at_a_time():
    from penny_env.physics.sensitivity import flow_jacobian, flow_jacobians

    state = np.array([0.01, -0.02, 0.3, 1.1, 37.0, -4.5])
    taus = np.array([0.01, 0.05, 0.2, 0.9])
    Phi, B = flow_jacobians(state, 8.0, -30.0, taus, 0.01)
    for i, tau in enumerate(taus):
        P1, B1 = flow_jacobian(state, 8.0, -30.0, tau, 0.01)
        assert np.allclose(Phi[i], P1, rtol=1e-13, atol=1e-15) and np.allclose(B[i], B1, rtol=1e-13, atol=1e-15)
