"""Exact flow of the controlled penny between impacts, batched over states.

States are (6, N) arrays (state, num_envs): rows x, y, theta, phi, theta_dot, phi_dot.
With constant controls the angles are polynomials, phi'' = acc1 = u1/J and
theta'' = acc2 = u2/(I + m R^2), and the contact point z = x + i y obeys

    z(t) - z0 = R * int_0^t (theta_dot0 + acc2 s) exp(i phi(s)) ds.

acc1 == 0 (no steering torque): closed form in the stable kernels j0(x) = sin(x)/x and
j1(x) = (sin x - x cos x)/x^2 (a series below |x| = 1), with x = phi_dot0 t / 2:

    z(t) - z0 = R t e^{i(phi0 + x)} [theta_dot0 j0 + acc2 t (j0 + i j1) / 2],

exact for phi_dot -> 0, long intervals and fast spin alike (no division by phi_dot).

acc1 != 0: composite Gauss-Legendre with at most 3 rad of phase per panel and 6 to 12
nodes by the phase a panel sweeps (RULES). The integrand is entire and the rules reach
round-off for their sweeps, so the result is exact to round-off for any acc1 (no cancellation
as acc1 -> 0, where Fresnel closed forms subtract large numbers). Work grows with the phase
swept, |phi_dot| t / 3 panels.
"""
from __future__ import annotations

import numpy as np

from .kernels import (MEDIUM_ANGLE, SMALL_ANGLE, angles_at, cis_medium, cis_small, displacement_closed,  # noqa: F401
                      end_point, sinc_kernels)

X, Y, THETA, PHI, THETA_DOT, PHI_DOT = range(6)

MAX_PHASE_PER_PANEL = 3.0
# Gauss-Legendre rules on [0, 1] by the phase a panel sweeps (phase_sweep): the integrand
# (W + acc2 s) e^{i phi(s)} is entire, and the n-node rule's truncation error stays below 5e-17 of
# the integral of |W + acc2 s| for sweeps up to its limit (the table made by
# tests/reference/quadrature_rules.py with mpmath; tests/physics/test_flow.py checks each limit against
# mpmath through flow()). Control periods of RL scenes sweep about 0.1 rad: 6 or 7 nodes.
RULE_SIZES = ((0.1, 6), (0.3, 7), (0.8, 8), (1.5, 9), (2.0, 10), (MAX_PHASE_PER_PANEL, 12))
# Each rule is (limit, centred nodes on [-1/2, 1/2], weights, cis): a panel's integrand is
# evaluated about its midpoint m, e^{i phi(m + u)} = e^{i phi(m)} e^{i psi(u)} with |psi| <= limit / 2,
# so one sin/cos pair per panel; e^{i psi} comes from kernels.cis_small's polynomials (cis = CIS_SMALL,
# limit <= 2 SMALL_ANGLE), from cis_medium's (CIS_MEDIUM, limit <= 2 MEDIUM_ANGLE) or from libm (CIS_LIBM).
CIS_LIBM, CIS_SMALL, CIS_MEDIUM = 0, 1, 2


def _cis_kind(limit):
    return CIS_SMALL if limit <= 2.0 * SMALL_ANGLE else (CIS_MEDIUM if limit <= 2.0 * MEDIUM_ANGLE else CIS_LIBM)


RULES = tuple((limit, tuple((0.5 * x).tolist()), tuple((0.5 * wt).tolist()), _cis_kind(limit))
              for limit, (x, wt) in ((limit, np.polynomial.legendre.leggauss(n)) for limit, n in RULE_SIZES))
# The same rules as equal-length tuples (zero-padded) with their node counts: the form the scalar
# loop (scalar.displacement_penny) indexes, in plain Python and compiled alike.
RULE_LIMITS = tuple(r[0] for r in RULES)
RULE_COUNTS = tuple(len(r[1]) for r in RULES)
RULE_CIS = tuple(r[3] for r in RULES)
_PAD = max(RULE_COUNTS)
RULE_NODES = tuple(r[1] + (0.0,) * (_PAD - len(r[1])) for r in RULES)
RULE_WEIGHTS = tuple(r[2] + (0.0,) * (_PAD - len(r[2])) for r in RULES)


def phase_sweep(w, acc1, t, xp=np):
    """A bound on the phase swept over [0, t]: int |phi'| <= max(|phi'(0)|, |phi'(t)|) t + |acc1| t^2 / 2."""
    return xp.maximum(xp.abs(w), xp.abs(w + acc1 * t)) * xp.abs(t) + 0.5 * xp.abs(acc1) * t * t


def panel_counts(w, acc1, t):
    """Gauss-Legendre panels needed to integrate over [0, t] with <= 3 rad of phase each."""
    return np.maximum(1, np.ceil(phase_sweep(w, acc1, t) / MAX_PHASE_PER_PANEL)).astype(np.int64)


def displacement_quadrature(W, w, ph, acc1, acc2, t, R):
    """Contact-point displacement over [0, t] with steering torque, (N,) arrays.

    Sums run in a fixed order (nodes in sequence, then panels in sequence), the order of
    scalar.displacement_penny, so a penny's result is bitwise the same alone or in any batch."""
    n = W.shape[0]
    k = panel_counts(w, acc1, t)
    per_panel = phase_sweep(w, acc1, t) / k
    dx, dy = np.zeros(n), np.zeros(n)
    rule = np.searchsorted(np.array(RULE_LIMITS[:-1]), per_panel, side="left")
    for r, (_, nodes, weights, cis) in enumerate(RULES):
        sel = np.flatnonzero(rule == r)
        if sel.size == 0:
            continue
        kk = k[sel]
        owner = np.repeat(sel, kk)
        panel = np.arange(owner.shape[0]) - np.repeat(np.cumsum(kk) - kk, kk)
        width = (t / k)[owner]
        a1, a2 = acc1[owner], acc2[owner]
        mid = (panel + 0.5) * width
        phm = ph[owner] + mid * (w[owner] + 0.5 * a1 * mid)
        wm = (w[owner] + a1 * mid)[:, None]
        Wm = (W[owner] + a2 * mid)[:, None]
        u = np.array(nodes)[None, :] * width[:, None]  # (panels, nodes)
        psi = u * (wm + 0.5 * a1[:, None] * u)
        amp = (Wm + a2[:, None] * u) * np.array(weights)[None, :]
        cs, sn = (cis_small(psi) if cis == CIS_SMALL else cis_medium(psi) if cis == CIS_MEDIUM
                  else (np.cos(psi), np.sin(psi)))
        # cumsum adds the nodes strictly in sequence (np.sum would add them pairwise)
        px = np.cumsum(amp * cs, axis=1)[:, -1]
        py = np.cumsum(amp * sn, axis=1)[:, -1]
        cm, sm = np.cos(phm), np.sin(phm)
        dx += np.bincount(owner, weights=(cm * px - sm * py) * width, minlength=n)
        dy += np.bincount(owner, weights=(sm * px + cm * py) * width, minlength=n)
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
    W, w = s[THETA_DOT], s[PHI_DOT]
    return 0.5 * (params.rolling_inertia * (W * W) + params.J * (w * w))  # products: libm's pow(x, 2) != x * x
