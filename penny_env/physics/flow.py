"""Exact flow of the controlled penny between impacts, batched over states.

States are (6, N) arrays (state, num_envs): rows x, y, theta, phi, theta_dot, phi_dot.
With constant controls the angles are polynomials, phi'' = acc1 = u1/J and
theta'' = acc2 = u2/(I + m R^2), and the contact point z = x + i y obeys

    z(t) - z0 = R * int_0^t (theta_dot0 + acc2 s) exp(i phi(s)) ds.

acc1 == 0 (no steering torque): closed form in the stable kernels j0(x) = sin(x)/x and
j1(x) = (sin x - x cos x)/x^2 (a series below |x| = 1), with x = phi_dot0 t / 2:

    z(t) - z0 = R t e^{i(phi0 + x)} [theta_dot0 j0 + acc2 t (j0 + i j1) / 2],

exact for phi_dot -> 0, long intervals and fast spin alike (no division by phi_dot).

acc1 != 0: composite Gauss-Legendre with 16 nodes per panel and at most 3 rad of phase per
panel. The integrand is entire, the quadrature error is below 3^32/32! ~ 1e-20 relative, so
the result is exact to round-off for any acc1 (no cancellation as acc1 -> 0, where Fresnel
closed forms subtract large numbers). Work grows with the phase swept, |phi_dot| t / 3 panels.
"""
from __future__ import annotations

import numpy as np

from .kernels import angles_at, displacement_closed, end_point, sinc_kernels  # noqa: F401

X, Y, THETA, PHI, THETA_DOT, PHI_DOT = range(6)

_GL_NODES, _GL_WEIGHTS = np.polynomial.legendre.leggauss(16)
_GL_U = 0.5 * (_GL_NODES + 1.0)  # nodes on [0, 1]
_GL_W = 0.5 * _GL_WEIGHTS
MAX_PHASE_PER_PANEL = 3.0


def panel_counts(w, acc1, t):
    """Gauss-Legendre panels needed to integrate over [0, t] with <= 3 rad of phase each."""
    sweep = np.maximum(np.abs(w), np.abs(w + acc1 * t)) * np.abs(t) + 0.5 * np.abs(acc1) * t * t
    return np.maximum(1, np.ceil(sweep / MAX_PHASE_PER_PANEL)).astype(np.int64)


def displacement_quadrature(W, w, ph, acc1, acc2, t, R):
    """Contact-point displacement over [0, t] with steering torque, (N,) arrays; per-penny sums
    run in a fixed order, so a penny's result does not depend on the rest of the batch."""
    n = W.shape[0]
    k = panel_counts(w, acc1, t)
    owner = np.repeat(np.arange(n), k)
    first = np.repeat(np.cumsum(k) - k, k)
    panel = np.arange(owner.shape[0]) - first
    width = (t / k)[owner]
    s = (panel[:, None] + _GL_U[None, :]) * width[:, None]  # (panels, 16) nodes
    o = owner[:, None]
    phase = ph[o] + s * (w[o] + 0.5 * acc1[o] * s)
    amp = (W[o] + acc2[o] * s) * _GL_W[None, :]
    px = np.sum(amp * np.cos(phase), axis=1) * width
    py = np.sum(amp * np.sin(phase), axis=1) * width
    dx = np.bincount(owner, weights=px, minlength=n)
    dy = np.bincount(owner, weights=py, minlength=n)
    return R * dx, R * dy


def flow(s, acc1, acc2, t, R):
    """States after time t >= 0 under constant angular accelerations (acc1, acc2).

    s: (6, N); acc1, acc2, t: (N,) arrays (or scalars, broadcast). Returns a new (6, N) array."""
    s = np.asarray(s, dtype=float)
    n = s.shape[1]
    acc1 = np.broadcast_to(np.asarray(acc1, dtype=float), (n,))
    acc2 = np.broadcast_to(np.asarray(acc2, dtype=float), (n,))
    t = np.broadcast_to(np.asarray(t, dtype=float), (n,))
    out = np.empty_like(s)
    out[THETA], out[PHI], out[THETA_DOT], out[PHI_DOT] = angles_at(
        s[THETA], s[PHI], s[THETA_DOT], s[PHI_DOT], acc1, acc2, t)
    steer = acc1 != 0.0
    if not steer.any():
        dx, dy = displacement_closed(s[THETA_DOT], s[PHI_DOT], s[PHI], acc2, t, R)
    elif steer.all():
        dx, dy = displacement_quadrature(s[THETA_DOT], s[PHI_DOT], s[PHI], acc1, acc2, t, R)
    else:
        dx, dy = np.empty(n), np.empty(n)
        i, j = np.flatnonzero(~steer), np.flatnonzero(steer)
        dx[i], dy[i] = displacement_closed(s[THETA_DOT, i], s[PHI_DOT, i], s[PHI, i], acc2[i], t[i], R)
        dx[j], dy[j] = displacement_quadrature(s[THETA_DOT, j], s[PHI_DOT, j], s[PHI, j], acc1[j], acc2[j], t[j], R)
    out[X] = s[X] + dx
    out[Y] = s[Y] + dy
    return out


def end_kinematics(s, sigma, R):
    """Position and velocity of an end (sigma=+1 front, -1 back) for (6, N) states."""
    return end_point(s[X], s[Y], s[PHI], s[THETA_DOT], s[PHI_DOT], sigma, R)


def kinetic_energy(s, params):
    """0.5 (I + m R^2) theta_dot^2 + 0.5 J phi_dot^2 for states on the constraint distribution."""
    return 0.5 * (params.rolling_inertia * s[THETA_DOT] ** 2 + params.J * s[PHI_DOT] ** 2)
