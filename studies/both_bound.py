"""A validated lower bound on the control rows of every impact-free plan with both controls.

Without an impact the penny moves as on the open plane. With steering |phi''| <= a1 and rolling |theta''| <= a2
(a_i = u_i,max / inertia), piecewise constant over rows of length dt:

* the heading at time t lies in the tube [phi0 + w t - a1 t^2 / 2, phi0 + w t + a1 t^2 / 2] (w = phi_dot(0); every
  point of it is reached by some steering, so nothing tighter holds for the heading alone);
* theta_dot is piecewise linear, theta_dot(0) = w0, slopes in [-a2, a2]; a park ends with |R theta_dot(T)| <= v_tol;
* the contact point's displacement along a unit direction d = (cos psi, sin psi) is
  P = R int_0^T theta_dot(t) cos(phi(t) - psi) dt <= R int_0^T G_t(theta_dot(t)) dt,
  G_t(x) = max over the tube at t of x cos(phi - psi) = max(x Cmax(t), x Cmin(t)) (convex in x).

A plan that ends within tol of the target g at T = K dt has P >= d . (g - z0) - tol for every d. :func:`displacement_upper`
bounds the largest R int G_t(theta_dot) over all rolling plans of K rows by dynamic programming over cells of
theta_dot (width h, each row's end in a cell, the row's theta_dot between its ends, the row split into m parts, on
each the largest of G over the part's times and the enclosure of theta_dot there). If that bound is below
d . (g - z0) - tol for some d, **no impact-free plan of K rows reaches the terminal set**.

Validated numerics: the cosine bounds over each part's tube and the requirement d . (g - z0) - tol are mpmath
interval computations (iv.cos encloses the range of cos over an interval); the dynamic programme runs in float64
with every addition and multiplication rounded outward (np.nextafter after each IEEE-754 operation, which is
correctly rounded), so the float it returns is an upper bound of the exact programme's value, itself an upper bound
of P. No claim rests on sampling. The relaxation forgets that the heading is one function of time and that the
wall must be avoided, so the bound is valid and not tight; it is the fewest rows K for which no direction in a
scan certifies K unreachable (:func:`fewest_rows`).
"""
from __future__ import annotations

import math

import numpy as np

CELLS_PER_ROW_STEP = 20   # theta_dot cells per a2 dt (cell width h = a2 dt / 20: 0.1 rad/s for the probes' penny)
PARTS = 4                 # parts of a row (a power of two: the interpolation weights are exact)
ANGLES = 36               # directions scanned after the target's and the last certifying one


def _up(x):
    return np.nextafter(x, np.inf)


def _down(x):
    return np.nextafter(x, -np.inf)


def _iv_float(x, up):
    """A float64 bound of an mpmath interval: its upper end rounded up (up=True) or lower end rounded down."""
    v = float(x.b if up else x.a)
    return float(_up(v) if up else _down(v))


_COS_CACHE: dict = {}


def heading_cos_bounds(phi0, w, a1, psi, dt, K, m=PARTS):
    """:func:`heading_cos_rows` for the first K rows, cached per (phi0, w, a1, psi, dt, m): the bounds of row k do
    not depend on K, so a scan over K computes each once."""
    key = (float(phi0), float(w), float(a1), float(psi), float(dt), int(m))
    have = _COS_CACHE.get(key)
    if have is None or len(have[0]) < K:
        if len(_COS_CACHE) > 4096:
            _COS_CACHE.clear()
        have = heading_cos_rows(phi0, w, a1, psi, dt, max(K, 2 * len(have[0]) if have else K), m)
        _COS_CACHE[key] = have
    return have[0][:K], have[1][:K]


def heading_cos_rows(phi0, w, a1, psi, dt, K, m=PARTS):
    """(Cmax, Cmin), arrays (K, m): float64 bounds, outward, of the max and min of cos(phi - psi) over the heading tube
    on each part of each row (mpmath intervals). On a part [ta, tb] the tube's lower edge is concave and its upper
    edge convex in t, so their extremes over the part are at ta or tb."""
    from mpmath import iv, mpf

    old = iv.dps
    iv.dps = 30
    try:
        p0, w_, ps, dt_ = iv.mpf(phi0), iv.mpf(w), iv.mpf(psi), iv.mpf(dt)
        a_ = iv.mpf(a1) * iv.mpf([1 - 1e-12, 1 + 1e-12])  # (the simulator's float64 torque / inertia)
        cmax, cmin = np.empty((K, m)), np.empty((K, m))
        for k in range(K):
            for s in range(m):
                ends = [dt_ * (iv.mpf(k) + iv.mpf(s + j) / m) for j in (0, 1)]
                low = min(mpf((p0 + w_ * t - a_ * t * t / 2).a) for t in ends)
                high = max(mpf((p0 + w_ * t + a_ * t * t / 2).b) for t in ends)
                c = iv.cos(iv.mpf([low, high]) - ps)
                cmax[k, s], cmin[k, s] = _iv_float(c, True), _iv_float(c, False)
        return cmax, cmin
    finally:
        iv.dps = old


def _g_upper(x, cmax, cmin):
    """Upper bound of max(x cmax, x cmin) for x (array) with cmax, cmin outward bounds (rounded up)."""
    return np.where(x >= 0, _up(x * cmax), _up(x * cmin))


def cell_enclosures(w0, h, N):
    """(lo, hi), arrays (2 N,): float64 bounds, outward, of the theta_dot cells [w0 + i h, w0 + (i + 1) h],
    i = -N .. N - 1. The edges w0 + i h are two roundings off in float64; the margin is far above those. The
    programme takes every theta_dot in a cell to be anywhere in [lo, hi]: a bound only if the cell lies inside it (a
    cell's midpoint in its place would miss the plans that run along the cells' edges, such as full torque)."""
    idx = np.arange(-N, N + 1, dtype=float)
    edge = w0 + idx * h
    margin = 1e-12 + 1e-15 * (abs(w0) + N * h)   # >> the two roundings (each <= 1.2e-16 of |w0| + N h)
    e_lo, e_hi = _down(edge - margin), _up(edge + margin)
    return e_lo[:-1], e_hi[1:]


def displacement_upper(w0, phi0, w, psi, R, a1, a2, dt, K, wf, h_steps=CELLS_PER_ROW_STEP, m=PARTS):
    """A float64 upper bound (rounded outward throughout) of R int_0^{K dt} G_t(theta_dot) dt over every rolling plan of
    K rows from theta_dot(0) = w0 with |theta_dot(K dt)| <= wf (wf = inf: no end condition); see the module docstring."""
    cmax, cmin = heading_cos_bounds(phi0, w, a1, psi, dt, K, m)
    A = _up(_up(a2 * (1 + 1e-12)) * dt)      # >= a2 dt: the most a row changes theta_dot
    h = _up(A / h_steps)                      # h_steps * h >= A: a row moves at most h_steps cells
    n = h_steps
    N = K * n                                 # cells -N .. N-1: cell i = [w0 + i h, w0 + (i + 1) h]
    lo, hi = cell_enclosures(w0, h, N)
    coef_up = _up(_up(R * dt) / m)
    coef_lo = _down(_down(R * dt) / m)
    wf_up = math.inf if math.isinf(wf) else float(_up(wf * (1 + 1e-12)))  # (the set's float R * theta_dot test)
    V = np.where((hi >= -wf_up) & (lo <= wf_up), 0.0, -np.inf)
    taus = [s / m for s in range(m + 1)]

    def row_reward(k, Ilo, Ihi, Jlo, Jhi):
        r = np.zeros(np.broadcast(Ilo, Jlo).shape)
        for s in range(m):
            ta, tb = taus[s], taus[s + 1]
            l_ = np.minimum(_down(_down((1 - ta) * Ilo) + _down(ta * Jlo)), _down(_down((1 - tb) * Ilo) + _down(tb * Jlo)))
            u_ = np.maximum(_up(_up((1 - ta) * Ihi) + _up(ta * Jhi)), _up(_up((1 - tb) * Ihi) + _up(tb * Jhi)))
            g = np.maximum(_g_upper(l_, cmax[k, s], cmin[k, s]), _g_upper(u_, cmax[k, s], cmin[k, s]))
            r = _up(r + _up(np.where(g >= 0, g * coef_up, g * coef_lo)))
        return r

    offs = np.arange(-n, n + 1)
    cells = np.arange(2 * N)
    for k in range(K - 1, 0, -1):
        live = slice(N - k * n, N + k * n)  # the cells theta_dot can be in at row k's start
        I = cells[live]
        J = I[:, None] + offs[None, :]
        ok = (J >= 0) & (J < 2 * N)
        Jc = np.clip(J, 0, 2 * N - 1)
        r = row_reward(k, lo[I][:, None], hi[I][:, None], lo[Jc], hi[Jc])
        cand = np.where(ok & np.isfinite(V[Jc]), _up(r + np.where(np.isfinite(V[Jc]), V[Jc], 0.0)), -np.inf)
        newV = np.full(2 * N, -np.inf)
        newV[live] = cand.max(axis=1)
        V = newV
    J = N + np.arange(-n, n)  # the cells of theta_dot after the first row, from w0 exactly
    r0 = row_reward(0, np.full(len(J), w0), np.full(len(J), w0), lo[J], hi[J])
    fin = np.isfinite(V[J])
    if not fin.any():
        return -math.inf
    return float(np.max(_up(r0[fin] + V[J][fin])))


def required_lower(start, target, psi, tol):
    """A float64 lower bound (mpmath intervals) of d . (target - z0) - tol, d = (cos psi, sin psi)."""
    from mpmath import iv

    d = iv.cos(iv.mpf(psi)) * (iv.mpf(target[0]) - iv.mpf(start[0])) + iv.sin(iv.mpf(psi)) * (
        iv.mpf(target[1]) - iv.mpf(start[1])) - iv.mpf(tol) * (1 + 1e-12)  # (the set's float hypot test)
    return _iv_float(d, False)


def unreachable(start, target, R, a1, a2, dt, K, tol, wf, psi, h_steps=CELLS_PER_ROW_STEP, m=PARTS):
    """True if no impact-free plan of K rows ends within tol of the target (and, for finite wf, with |theta_dot| <= wf),
    certified along the direction psi (with h_steps cells per a2 dt and m parts per row)."""
    return margin(start, target, R, a1, a2, dt, K, tol, wf, psi, h_steps, m) > 0


def margin(start, target, R, a1, a2, dt, K, tol, wf, psi, h_steps=CELLS_PER_ROW_STEP, m=PARTS):
    """The certified gap (a float64 lower bound) between what a K-row plan must travel along psi and the most it can;
    > 0 certifies K unreachable."""
    need = required_lower(start, target, psi, tol)
    if need <= 0:
        return need
    up = displacement_upper(start[4], start[3], start[5], psi, R, a1, a2, dt, K, wf, h_steps, m)
    return -math.inf if up == math.inf else float(_down(need - up))


SCREEN = (5, 2)   # (cells per a2 dt, parts per row) of the cheap pass over every direction
FINE_TRIES = 3    # directions re-run at the full resolution when the cheap pass certifies none


def fewest_rows(start, target, R, a1, a2, dt, tol, wf, max_rows=60, angles=ANGLES, first=1):
    """(K, psis): every K' < K is certified unreachable by impact-free plans, psis the directions that certified
    K' = first, first + 1, ... (the K' < first are taken as certified by the caller: the tent bound); K = max_rows + 1
    when every K' <= max_rows is. Per K: the direction that certified K - 1 (cheap, then full resolution); then every
    direction of the scan (the target's and `angles` within 90 degrees of it) at the cheap resolution; then the
    FINE_TRIES best of them at the full one. Every resolution is rigorous; the finer is tighter."""
    alpha = math.atan2(target[1] - start[1], target[0] - start[0])
    scan = [alpha] + [alpha + x for x in np.linspace(-0.5 * math.pi, 0.5 * math.pi, angles + 2)[1:-1]]
    psis = []
    args = (start, target, R, a1, a2, dt)
    for K in range(first, max_rows + 1):
        hit = None
        if psis and (unreachable(*args, K, tol, wf, psis[-1], *SCREEN) or unreachable(*args, K, tol, wf, psis[-1])):
            hit = psis[-1]
        if hit is None:
            gaps = [margin(*args, K, tol, wf, p, *SCREEN) for p in scan]
            order = np.argsort(gaps)[::-1]
            if gaps[order[0]] > 0:
                hit = scan[order[0]]
            else:
                hit = next((scan[i] for i in order[:FINE_TRIES] if unreachable(*args, K, tol, wf, scan[i])), None)
        if hit is None:
            return K, psis
        psis.append(hit)
    return max_rows + 1, psis
