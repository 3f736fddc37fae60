"""Impact laws against the paper's formulas, solved independently here, and their invariants."""
import numpy as np
import pytest
from hypothesis import given, strategies as st

import penny_env as pe
from penny_env.physics.flows import kinetic_energy


def on_wall_state(rng, params, table, end):
    """A state whose given end lies on the ellipse wall, with random velocities."""
    tau = rng.uniform(0, 2 * np.pi)
    wx, wy = table.a * np.cos(tau), table.b * np.sin(tau)
    phi = rng.uniform(0, 2 * np.pi)
    x, y = wx - end * params.R * np.cos(phi), wy - end * params.R * np.sin(phi)
    return np.array([x, y, rng.uniform(-5, 5), phi, rng.normal(0, 10), rng.normal(0, 10)])


def grad_paper(table, px, py):
    return 2 * px / table.a**2, 2 * py / table.b**2  # the paper's h = x^2/a^2 + y^2/b^2 - 1


def paper_plastic(s, p, table, end):
    """var_penny followed by the pi_Delta matrix, written out as in the paper."""
    x, y, th, phi, W, w = s
    R, m, I, J = p.R, p.m, p.I, p.J
    c, sn = np.cos(phi), np.sin(phi)
    hx, hy = grad_paper(table, x + end * R * c, y + end * R * sn)
    xd, yd = R * W * c, R * W * sn
    tw = end * R * (hy * c - hx * sn)
    C = -2 * (hx * xd + hy * yd + tw * w) / ((hx**2 + hy**2) / m + tw**2 / J)
    q = np.array([xd + C * hx / m, yd + C * hy / m, W, w + C * tw / J])
    A = m * R**2 * np.array([[c * c, sn * c], [sn * c, sn * sn]])
    B = I * R * np.array([[c, 0], [sn, 0]])
    Cb = m * R * np.array([[c, sn], [0, 0]])
    D = np.array([[I, 0], [0, I + m * R**2]])
    pi = np.block([[A, B], [Cb, D]]) / (I + m * R**2)
    out = pi @ q
    return np.array([x, y, th, phi, out[2], out[3]]), out


def var_impact_elastic(s, p, table, end):
    """Solve the paper's system var_impact: p+ = p- + l1 w1 + l2 w2 + alpha dS, constraints, energy."""
    x, y, th, phi, W, w = s
    R, m, I, J = p.R, p.m, p.I, p.J
    c, sn = np.cos(phi), np.sin(phi)
    hx, hy = grad_paper(table, x + end * R * c, y + end * R * sn)
    g_inv = np.diag([1 / m, 1 / m, 1 / I, 1 / J])
    qd = np.array([R * W * c, R * W * sn, W, w])
    pm = np.diag([m, m, I, J]) @ qd
    w1, w2 = np.array([1, 0, -R * c, 0]), np.array([0, 1, -R * sn, 0])
    dS = np.array([hx, hy, 0, end * R * (hy * c - hx * sn)])
    ip = lambda a, b: a @ g_inv @ b  # noqa: E731
    Amat = np.array([[ip(w1, w1), ip(w2, w1)], [ip(w1, w2), ip(w2, w2)]])
    lam_per_alpha = np.linalg.solve(Amat, -np.array([ip(dS, w1), ip(dS, w2)]))
    v = lam_per_alpha[0] * w1 + lam_per_alpha[1] * w2 + dS
    alpha = -2 * ip(pm, v) / ip(v, v)  # the nonzero root of 2 alpha <p, v> + alpha^2 <v, v> = 0
    qp = g_inv @ (pm + alpha * v)
    return np.array([x, y, th, phi, qp[2], qp[3]]), qp


params_st = st.builds(
    lambda R, m, ri, rj: pe.PennyParams(R=R, m=m, I=ri * m * R * R, J=rj * m * R * R),
    st.floats(1e-3, 0.05), st.floats(1e-3, 1.0), st.floats(1e-3, 10.0), st.floats(1e-3, 10.0))


@given(p=params_st, seed=st.integers(0, 2**31 - 1), end=st.sampled_from([1, -1]))
def test_elastic_is_the_solution_of_var_impact(p, seed, end):
    rng = np.random.default_rng(seed)
    table = pe.Ellipse(rng.uniform(0.2, 0.5), rng.uniform(0.2, 0.5))
    s = on_wall_state(rng, p, table, end)
    ours = pe.impact_map(s, params=p, table=table, end=end, law="elastic")
    ref, qp = var_impact_elastic(s, p, table, end)
    np.testing.assert_allclose(ours, ref, rtol=1e-10, atol=1e-12 * np.abs(s[4:]).max())
    # the solution lies on the constraint distribution
    assert abs(qp[0] - p.R * qp[2] * np.cos(s[3])) <= 1e-12 * p.R * abs(qp[2]) + 1e-15
    assert abs(qp[1] - p.R * qp[2] * np.sin(s[3])) <= 1e-12 * p.R * abs(qp[2]) + 1e-15


@given(p=params_st, seed=st.integers(0, 2**31 - 1), end=st.sampled_from([1, -1]))
def test_plastic_equals_var_penny_then_pi_delta(p, seed, end):
    rng = np.random.default_rng(seed)
    table = pe.Ellipse(rng.uniform(0.2, 0.5), rng.uniform(0.2, 0.5))
    s = on_wall_state(rng, p, table, end)
    ref, q = paper_plastic(s, p, table, end)
    ours = pe.impact_map(s, params=p, table=table, end=end, law="plastic")
    # normal velocity of the end before and after the paper's map
    c, sn = np.cos(s[3]), np.sin(s[3])
    hx, hy = grad_paper(table, s[0] + end * p.R * c, s[1] + end * p.R * sn)
    normal = lambda W, w: p.R * W * (hx * c + hy * sn) + end * p.R * w * (hy * c - hx * sn)  # noqa: E731
    vn_before, vn_after = normal(s[4], s[5]), normal(ref[4], ref[5])
    # pi_Delta o P lands on the distribution
    assert abs(q[0] - p.R * q[2] * c) <= 1e-12 * p.R * (abs(q[2]) + 1)
    if vn_before > 0 and vn_after > 0:
        # the paper's map leaves the end moving outward: ours removes the normal velocity
        if vn_after > 1e-9 * vn_before:
            # exactly when 2 m R^2 cos^2(beta) / (I + m R^2) + m R^2 sin^2(beta) / J < 1, beta the angle
            # between the heading and the wall normal (so I > m R^2 head-on, or J > m R^2 sideways)
            cos_b = (hx * c + hy * sn) / np.hypot(hx, hy)
            mR2 = p.m * p.R**2
            assert 2 * mR2 * cos_b**2 / (p.I + mR2) + mR2 * (1 - cos_b**2) / p.J < 1 + 1e-9
        assert abs(normal(ours[4], ours[5])) <= 1e-10 * abs(vn_before)
    else:
        np.testing.assert_allclose(ours, ref, rtol=1e-10, atol=1e-12 * np.abs(s[4:]).max())


@given(p=params_st, seed=st.integers(0, 2**31 - 1), end=st.sampled_from([1, -1]),
       law=st.sampled_from(["elastic", "plastic", 0.0, 0.3, 0.9]))
def test_energy_and_normal_velocity(p, seed, end, law):
    rng = np.random.default_rng(seed)
    table = pe.Ellipse(rng.uniform(0.2, 0.5), rng.uniform(0.2, 0.5))
    s = on_wall_state(rng, p, table, end)
    post = pe.impact_map(s, params=p, table=table, end=end, law=law)
    e0, e1 = kinetic_energy(s[:, None], p)[0], kinetic_energy(post[:, None], p)[0]
    assert np.array_equal(post[:4], s[:4])
    if law == "elastic":
        assert abs(e1 - e0) <= 1e-13 * e0
    else:
        assert e1 <= e0 * (1 + 1e-13)
    if isinstance(law, float):
        c, sn = np.cos(s[3]), np.sin(s[3])
        hx, hy = table.grad(s[0] + end * p.R * c, s[1] + end * p.R * sn)
        normal = lambda W, w: p.R * W * (hx * c + hy * sn) + end * p.R * w * (hy * c - hx * sn)  # noqa: E731
        assert abs(normal(post[4], post[5]) + law * normal(s[4], s[5])) <= 1e-12 * (abs(normal(s[4], s[5])) + 1e-300)


@pytest.mark.fast
def test_elastic_map_is_an_involution():
    rng = np.random.default_rng(0)
    p, table = pe.PennyParams(), pe.Ellipse(0.15, 0.2)
    s = on_wall_state(rng, p, table, 1)
    twice = pe.impact_map(pe.impact_map(s, table=table, end=1, law="elastic"), table=table, end=1, law="elastic")
    np.testing.assert_allclose(twice, s, rtol=1e-13)


@pytest.mark.fast
def test_sticking_when_rolling_inertia_exceeds_m_r2():
    # head-on impact, I = 3 m R^2: pi_Delta o P leaves the end moving outward; we stop it at the wall
    p = pe.PennyParams(I=3 * 0.0025 * 0.01**2)
    table = pe.Circle(0.2)
    s = np.array([0.19, 0.0, 0.0, 0.0, 5.0, 0.0])
    ref, _ = paper_plastic(s, p, table, 1)
    assert ref[4] > 0  # the paper's map keeps rolling into the wall
    ours = pe.impact_map(s, params=p, table=table, end=1, law="plastic")
    assert ours[4] == pytest.approx(0.0, abs=1e-12) and ours[5] == pytest.approx(0.0, abs=1e-12)
