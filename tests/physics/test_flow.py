"""Exact flow: against mpmath quadrature at 30 digits, near the cancellation points and at the
extremes, plus the semigroup property and the constraints (hypothesis)."""
import numpy as np
import pytest

mp = pytest.importorskip("mpmath", reason="mpmath (the penny-env[test] extra) is the reference of these tests")
from hypothesis import given, strategies as st

from penny_env.physics.flows import RULE_LIMITS, flow
from penny_env.physics.kernels import sinc_kernels

R = 0.01


def mp_flow_xy(s, acc1, acc2, t, dps=25):
    """Contact point after time t, by mpmath (tanh-sinh) quadrature split into pieces of a few rad."""
    with mp.workdps(dps):
        x, y, th, ph, W, w = (mp.mpf(float(v)) for v in s)
        a1, a2, T = mp.mpf(float(acc1)), mp.mpf(float(acc2)), mp.mpf(float(t))
        f = lambda u: (W + a2 * u) * mp.expj(ph + w * u + a1 * u * u / 2)  # noqa: E731
        sweep = (abs(w) + abs(a1) * T) * T
        pieces = int(min(max(4, sweep / 4), 4000))
        z = mp.quad(f, mp.linspace(0, T, pieces + 1))
        return x + R * z.real, y + R * z.imag


CASES = [
    # (state, acc1, acc2, t): cancellation points and extremes
    ((0.1, -0.2, 0.0, 0.3, 10.0, 0.0), 0.0, 0.0, 3.0),          # phi_dot = 0
    ((0.1, -0.2, 0.0, 0.3, 10.0, 1e-12), 0.0, 0.0, 3.0),        # phi_dot -> 0
    ((0.1, -0.2, 0.0, 0.3, 10.0, 1e-8), 0.0, 2.0, 3.0),         # with u2
    ((0.0, 0.0, 0.0, 0.3, 10.0, 0.7), 1e-20, 0.0, 3.0),         # u1 -> 0
    ((0.0, 0.0, 0.0, 0.3, 10.0, 0.0), 1e-16, 1e-16, 3.0),       # u1, u2 -> 0, phi_dot = 0
    ((0.0, 0.0, 0.0, 0.3, 10.0, 1e-9), 1e-12, 0.0, 50.0),       # both tiny, long interval
    ((0.0, 0.0, 0.0, 0.3, -3.0, 0.5), 0.0, 0.0, 1000.0),        # long interval
    ((0.0, 0.0, 0.0, 0.3, 1e3, 1e4), 0.0, 0.0, 0.05),           # fast spin, fast rolling
    ((0.0, 0.0, 0.0, 0.3, 1e3, 1e4), 3.0e3, -2e2, 0.05),        # fast spin with both torques
    ((0.0, 0.0, 0.0, 0.3, 5.0, -1e4), 50.0, 7.0, 0.25),         # fast spin, 400 rad, steering
    ((0.0, 0.0, 0.0, 0.3, 5.0, -2.0), 40.0, 3.0, 0.3),          # phase turning point inside
    ((0.0, 0.0, 0.0, 0.3, 1e-9, 1e-9), 1e-9, 1e-9, 0.05),       # tiny speeds
]


@pytest.mark.fast
@pytest.mark.parametrize("s, acc1, acc2, t", CASES)
def test_flow_matches_mpmath(s, acc1, acc2, t):
    out = flow(np.array(s, float)[:, None], acc1, acc2, t, R)[:, 0]
    rx, ry = mp_flow_xy(s, acc1, acc2, t)
    # the displacement is computed to round-off; allow for the rounding of the phase argument
    phase = abs(s[3]) + (abs(s[5]) + abs(acc1) * t) * t
    travel = R * (abs(s[4]) + abs(acc2) * t) * t
    tol = 8e-16 * (abs(s[0]) + abs(s[1]) + travel * (1 + phase)) + 1e-300
    assert abs(out[0] - float(rx)) <= tol
    assert abs(out[1] - float(ry)) <= tol
    np.testing.assert_allclose(out[2:], [s[2] + t * (s[4] + acc2 * t / 2), s[3] + t * (s[5] + acc1 * t / 2),
                                         s[4] + acc2 * t, s[5] + acc1 * t], rtol=1e-15, atol=1e-300)


@given(x=st.floats(-50, 50))
def test_sinc_kernels_against_mpmath(x):
    j0, j1 = sinc_kernels(np.array([x]))
    with mp.workdps(40):
        X = mp.mpf(x)
        r0 = mp.sin(X) / X if X != 0 else mp.mpf(1)
        r1 = (mp.sin(X) - X * mp.cos(X)) / X**2 if X != 0 else mp.mpf(0)
    assert abs(j0[0] - float(r0)) <= 4e-16 * max(abs(float(r0)), 1e-3)
    # near a zero of j1 the accuracy is absolute: eps / |x| (cancellation of sin x and x cos x)
    assert abs(j1[0] - float(r1)) <= 4e-16 * (abs(float(r1)) + 1 / (1 + abs(x)))


@given(seed=st.integers(0, 2**31 - 1), steer=st.booleans())
def test_semigroup(seed, steer):
    rng = np.random.default_rng(seed)
    s = rng.normal(size=6) * np.array([0.1, 0.1, 1, 1, 20, 10])
    a1, a2 = rng.normal(0, 5) * steer, rng.normal(0, 5)
    t1, t2 = rng.uniform(0, 2, size=2)
    once = flow(s[:, None], a1, a2, t1 + t2, R)[:, 0]
    twice = flow(flow(s[:, None], a1, a2, t1, R), a1, a2, t2, R)[:, 0]
    scale = np.array([1, 1, 1 + abs(once[2]), 1 + abs(once[3]), 1 + abs(once[4]), 1 + abs(once[5])])
    assert np.all(np.abs(once - twice) <= 1e-13 * scale)


@given(seed=st.integers(0, 2**31 - 1), steer=st.booleans())
def test_velocity_is_on_the_distribution(seed, steer):
    # d/dt (x, y) = R theta_dot (cos phi, sin phi), checked by a centred difference of the flow
    rng = np.random.default_rng(seed)
    s = rng.normal(size=6) * np.array([0.1, 0.1, 1, 1, 20, 10])
    a1, a2 = rng.normal(0, 5) * steer, rng.normal(0, 5)
    t, h = rng.uniform(0.1, 2), 1e-6
    pm = flow(np.repeat(s[:, None], 3, axis=1), a1, a2, np.array([t - h, t, t + h]), R)
    v = (pm[:2, 2] - pm[:2, 0]) / (2 * h)
    expected = R * pm[4, 1] * np.array([np.cos(pm[3, 1]), np.sin(pm[3, 1])])
    np.testing.assert_allclose(v, expected, rtol=1e-6, atol=1e-9 * R * (1 + abs(pm[4, 1])))


@pytest.mark.parametrize("limit", RULE_LIMITS)
@pytest.mark.parametrize("split", [1.0, 0.6, 0.2, 0.0])
def test_quadrature_rules_reach_round_off_at_their_limits(limit, split):
    # phase sweep exactly at a rule's limit, shared between the linear (phi_dot) and quadratic (u1) parts
    t = 0.05
    w = split * limit / t
    acc1 = (1 - split) * limit / (1.5 * t * t)
    s = (0.01, -0.02, 0.0, 0.4, 30.0, w)
    out = flow(np.array(s, float)[:, None], acc1, 3.0, t, R)[:, 0]
    rx, ry = mp_flow_xy(s, acc1, 3.0, t)
    disp = np.hypot(float(rx) - s[0], float(ry) - s[1])
    assert np.hypot(out[0] - float(rx), out[1] - float(ry)) <= 2e-15 * disp + 4e-17
