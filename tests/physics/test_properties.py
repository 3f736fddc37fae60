"""Property-based and extreme-case tests of simulate(): no NaN, never outside the table (checked
by dense sampling, which is also how a missed impact would show), elastic energy kept, dissipative
laws never gain energy, bounded work on degenerate cases."""
import numpy as np
import pytest
from hypothesis import given, strategies as st

import penny_env as pe
from penny_env.physics.flows import kinetic_energy
from conftest import random_inside_state

tables_st = st.one_of(
    st.builds(pe.Ellipse, st.floats(0.05, 0.5), st.floats(0.05, 0.5)),
    st.builds(pe.Circle, st.floats(0.05, 0.5)),
    st.builds(pe.Stadium, st.floats(0.05, 0.3), st.floats(0.0, 0.5)),
    # rounded rectangles from a stadium-like radius = min/2 down to nearly sharp corners
    st.builds(lambda w, hgt, f: pe.RoundedRectangle(w, hgt, f * 0.5 * min(w, hgt)),
              st.floats(0.06, 0.6), st.floats(0.06, 0.6), st.floats(0.02, 1.0)),
)
params_st = st.builds(
    lambda R, m, ri, rj: pe.PennyParams(R=R, m=m, I=ri * m * R * R, J=rj * m * R * R),
    st.floats(0.002, 0.03), st.floats(1e-3, 1.0), st.sampled_from([1e-4, 0.01, 0.5, 1.0, 3.0, 100.0]),
    st.sampled_from([1e-4, 0.01, 0.25, 1.0, 5.0, 100.0]))
laws_st = st.sampled_from(["elastic", "plastic", 0.0, 0.5, 0.95])


def max_wall_value(tr, params, table, n=400):
    """Largest h over both ends, sampled densely along the trajectory and at every impact."""
    t = np.linspace(0.0, tr.final_time, n)
    t = np.concatenate([t, tr.impact_times, np.nextafter(tr.impact_times, np.inf)])
    t = t[t <= tr.final_time]
    S = tr.states_at(t)
    worst = -np.inf
    for sgn in (1, -1):
        worst = max(worst, np.max(table.h(S[:, 0] + sgn * params.R * np.cos(S[:, 3]),
                                          S[:, 1] + sgn * params.R * np.sin(S[:, 3]))))
    return worst


@given(params=params_st, table=tables_st, law=laws_st, seed=st.integers(0, 2**31 - 1),
       controlled=st.booleans(), speed=st.sampled_from([1e-6, 1.0, 30.0, 300.0]))
def test_invariants_random(params, table, law, seed, controlled, speed):
    if table.inradius <= params.R * 1.05:
        return
    rng = np.random.default_rng(seed)
    s0 = random_inside_state(rng, params, table, speed=speed, spin=speed)
    kw = {}
    if controlled:
        scale = np.array([params.J, params.rolling_inertia]) * speed
        kw = dict(controls=rng.normal(size=(20, 2)) * scale, control_dt=0.05)
    tr = pe.simulate(s0, params=params, table=table, law=law, t_final=1.0, **kw)
    assert np.all(np.isfinite(tr.final_state)) and np.all(np.isfinite(tr.impact_states))
    assert max_wall_value(tr, params, table) <= 64 * 2.2e-16 * table.size
    e0 = kinetic_energy(s0[:, None], params)[0]
    if not controlled and tr.n_impacts:
        energies = tr.energies()
        if law == "elastic" and not len(tr.rest_times):
            np.testing.assert_allclose(energies, e0, rtol=1e-12)
        else:
            assert np.all(np.diff(np.concatenate([[e0], energies])) <= 1e-12 * e0)
    # each impact's end lies on the wall
    for s, end in zip(tr.impact_states, tr.impact_ends):
        px, py = s[0] + end * params.R * np.cos(s[3]), s[1] + end * params.R * np.sin(s[3])
        assert abs(table.h(px, py)) <= 64 * 2.2e-16 * table.size * 4


def test_fast_spin_and_fast_rolling_stay_inside():
    params, table = pe.PennyParams(), pe.Ellipse(0.15, 0.2)
    for s0 in ([0, 0, 0, 0.3, 1e3, 1e4], [0, 0, 0, 0.3, 1e3, -1e4], [0.02, -0.01, 0, 2.0, 5.0, 1e4]):
        tr = pe.simulate(s0, params=params, table=table, law="elastic", t_final=0.05,
                         controls=[[1e-6, 1e-5]], control_dt=0.05)
        assert np.all(np.isfinite(tr.final_state))
        assert max_wall_value(tr, params, table, n=4000) <= 64 * 2.2e-16 * table.size


def test_tiny_speeds():
    params, table = pe.PennyParams(), pe.Circle(0.2)
    tr = pe.simulate([0.0, 0.0, 0.0, 0.0, 1e-9, 1e-9], params=params, table=table, law="elastic", n_impacts=2)
    # the penny crawls in a circle of radius R |theta_dot / phi_dot| = R around its start: never hits
    assert tr.n_impacts == 0 and not tr.complete
    tr = pe.simulate([0.0, 0.0, 0.0, 0.0, 1e-9, 0.0], params=params, table=table, law="elastic", n_impacts=1)
    assert tr.impact_times[0] == pytest.approx((0.2 - params.R) / (params.R * 1e-9), rel=1e-12)


@pytest.mark.parametrize("ratio_I, ratio_J", [(1e-4, 1e-4), (1e-4, 1e2), (1e2, 1e-4), (1e2, 1e2)])
@pytest.mark.parametrize("law", ["elastic", "plastic"])
def test_stiff_inertia_ratios(ratio_I, ratio_J, law):
    m, R = 0.0025, 0.01
    params = pe.PennyParams(R=R, m=m, I=ratio_I * m * R * R, J=ratio_J * m * R * R)
    table = pe.Ellipse(0.15, 0.2)
    s0 = np.array([0.01, 0.02, 0.0, 0.7, 10.0, 3.0])
    tr = pe.simulate(s0, params=params, table=table, law=law, t_final=20.0)
    assert np.all(np.isfinite(tr.final_state))
    assert max_wall_value(tr, params, table, n=4000) <= 64 * 2.2e-16 * table.size
    e = np.concatenate([[kinetic_energy(s0[:, None], params)[0]], tr.energies()])
    if law == "elastic" and not len(tr.rest_times):
        np.testing.assert_allclose(e, e[0], rtol=1e-12)
    else:
        assert np.all(np.diff(e) <= 1e-12 * e[0])


def test_sticking_plastic_with_large_rolling_inertia_is_bounded():
    params = pe.PennyParams(I=5 * 0.0025 * 0.01**2, J=3 * 0.0025 * 0.01**2)
    table = pe.Circle(0.1)
    tr = pe.simulate([0.0, 0.0, 0.0, 0.2, 20.0, 0.5], params=params, table=table, law="plastic", t_final=10.0)
    assert np.all(np.isfinite(tr.final_state))
    assert max_wall_value(tr, params, table, n=4000) <= 64 * 2.2e-16 * table.size


def test_zeno_accumulation_comes_to_rest_against_the_wall():
    # restitution 0.5, a rolling torque driving the penny into the wall: impacts accumulate
    params, table = pe.PennyParams(), pe.Circle(0.1)
    u2 = 2e-5  # theta_ddot = u2 / (I + m R^2) = 53 rad/s^2 towards the wall
    tr = pe.simulate([0.0, 0.0, 0.0, 0.0, 5.0, 0.0], params=params, table=table, law=0.5,
                     controls=[[0.0, u2]] * 40, control_dt=0.05)
    assert len(tr.rest_times) >= 1
    assert np.all(np.isfinite(tr.final_state))
    assert max_wall_value(tr, params, table, n=4000) <= 64 * 2.2e-16 * table.size
    # pinned: at rest at the end, pressed against the wall
    assert tr.final_state[4] == 0.0 and tr.final_state[5] == 0.0


def test_both_ends_on_the_wall_in_a_thin_table():
    params = pe.PennyParams()
    table = pe.Ellipse(0.05, 0.0101)  # minor semi-axis barely above R: the penny spans it
    for law in ("elastic", "plastic", 0.3):
        tr = pe.simulate([0.0, 0.0, 0.0, np.pi / 2 - 0.05, 0.5, 2.0], params=params, table=table, law=law, t_final=2.0)
        assert np.all(np.isfinite(tr.final_state))
        assert max_wall_value(tr, params, table, n=4000) <= 64 * 2.2e-16 * table.size


def test_long_horizon_elastic_energy():
    params, table = pe.PennyParams(), pe.Ellipse(0.15, 0.2)
    s0 = np.array([0.0, 0.0, 0.0, np.pi / 2, 10.0, 0.2])
    tr = pe.simulate(s0, params=params, table=table, law="elastic", n_impacts=2000)
    assert tr.n_impacts == 2000
    e = tr.energies()
    assert np.max(np.abs(e / e[0] - 1)) < 1e-12


def test_custom_convex_table():
    # a rounded square |x|^4 + |y|^4 < s^4, scaled to metres
    s = 0.2
    h = lambda x, y: (x**4 + y**4 - s**4) / (4 * s**3)  # noqa: E731
    grad = lambda x, y: (x**3 / s**3, y**3 / s**3)  # noqa: E731
    # |grad| <= 1 on the table (max at the diagonal corners is 2^(1/4)/sqrt(2) < 1); Hessian 3 x^2 / s^3 <= 3 / s
    table = pe.ConvexTable(h, grad, grad_bound=1.0, hessian_bound=3 / s, extent=(-1.1 * s, 1.1 * s, -1.1 * s, 1.1 * s))
    params = pe.PennyParams()
    tr = pe.simulate([0.0, 0.0, 0.0, 0.3, 10.0, 0.7], params=params, table=table, law="elastic", t_final=20.0)
    assert tr.n_impacts > 5
    assert max_wall_value(tr, params, table, n=4000) <= 64 * 2.2e-16 * table.size
    np.testing.assert_allclose(tr.energies(), tr.energies()[0], rtol=1e-12)


def test_wall_check_catches_a_trajectory_outside():
    """The dense-sampling check above can fail: a trajectory pushed outside is caught."""
    params, table = pe.PennyParams(), pe.Circle(0.2)
    tr = pe.simulate([0.0, 0.0, 0.0, 0.0, 10.0, 0.2], params=params, table=table, law="elastic", t_final=3.0)
    assert max_wall_value(tr, params, table) <= 0
    tr._seg_s = tr._seg_s.copy()
    tr._seg_s[:, 0] += 0.02
    assert max_wall_value(tr, params, table) > 1e-3


class _CircleByProtocol:
    """A user table that follows the documented protocol without subclassing penny_env's tables."""
    grad_bound = 1.0
    hessian_bound = 1 / 0.2
    inradius = 0.2
    extent = (-0.2, 0.2, -0.2, 0.2)

    def h(self, x, y):
        return (x * x + y * y - 0.2**2) / (2 * 0.2)

    def grad(self, x, y):
        return x / 0.2, y / 0.2


def test_protocol_object_as_table():
    s0 = [0.0, 0.01, 0.0, 0.3, 10.0, 0.2]
    mine = pe.simulate(s0, table=_CircleByProtocol(), law="plastic", n_impacts=6)
    ref = pe.simulate(s0, table=pe.Circle(0.2), law="plastic", n_impacts=6)
    assert np.array_equal(mine.impact_ends, ref.impact_ends)
    np.testing.assert_allclose(mine.impact_times, ref.impact_times, rtol=1e-12)
    # the batch API and the environments take it too
    from penny_env import batch
    from penny_env.backends import choice as compiled
    compiled._WARNED.discard(type(pe.physics.tables.as_table(_CircleByProtocol())))
    with pytest.warns(RuntimeWarning, match="plain-Python event loop"):  # no compiled formulas: said once
        out = batch.simulate(np.array([s0]), table=_CircleByProtocol(), law="elastic", t_final=2.0)
    assert out is not None
    bad = _CircleByProtocol()
    bad.grad_bound = -1.0
    with pytest.raises(ValueError, match="grad_bound"):
        pe.simulate(s0, table=bad, t_final=1.0)
    class Incomplete:
        def h(self, x, y):
            return x
    with pytest.raises(TypeError, match="grad"):
        pe.simulate(s0, table=Incomplete(), t_final=1.0)


@given(w=st.floats(0.06, 0.6), hgt=st.floats(0.06, 0.6), f=st.floats(0.01, 1.0), seed=st.integers(0, 2**31 - 1),
       speed=st.sampled_from([1.0, 30.0, 300.0]))
def test_rounded_rectangle_no_escape_and_elastic_energy_kept(w, hgt, f, seed, speed):
    # corners from nearly sharp (radius 1% of the half-width) to fully round: the penny stays in, energy stays
    params, table = pe.PennyParams(), pe.RoundedRectangle(w, hgt, f * 0.5 * min(w, hgt))
    rng = np.random.default_rng(seed)
    s0 = random_inside_state(rng, params, table, speed=speed, spin=speed)
    tr = pe.simulate(s0, params=params, table=table, law="elastic", t_final=2.0)
    assert max_wall_value(tr, params, table, n=2000) <= 64 * 2.2e-16 * table.size
    if not len(tr.rest_times):
        np.testing.assert_allclose(tr.energies(), kinetic_energy(s0[:, None], params)[0], rtol=1e-12)
