"""The penny's formulas, written once for numpy arrays and for Python floats.

Every kernel takes the math namespace ``xp`` last: ``numpy`` for batches (elementwise over
(N,) arrays) or :data:`SCALAR` for one penny in plain floats (what the single environment and
simulate() run: numpy on size-1 arrays costs ~1 us per call). Both evaluate the same IEEE
operations in the same order, so batched and scalar results agree bitwise on a given machine.
Branches are written as ``xp.where`` over expressions that are finite in both branches.
"""
from __future__ import annotations

import math

import numpy as np


class _ScalarMath:
    """The subset of numpy used by the kernels, for Python floats."""

    sin = staticmethod(math.sin)
    cos = staticmethod(math.cos)
    sqrt = staticmethod(math.sqrt)
    abs = staticmethod(abs)
    minimum = staticmethod(min)
    maximum = staticmethod(max)
    inf = math.inf

    @staticmethod
    def where(cond, a, b):
        return a if cond else b


SCALAR = _ScalarMath()

# j1(x) = sum_k (-1)^k (2k+2) x^(2k+1) / (2k+3)!, truncated where terms drop below 1e-19 for |x| < 1
_J1_COEFFS = []
_f = 6.0
for _k in range(10):
    _J1_COEFFS.append((-1) ** _k * (2 * _k + 2) / _f)
    _f *= (2 * _k + 4) * (2 * _k + 5)
_J1_REVERSED = tuple(_J1_COEFFS[::-1])


def sinc_kernels(x, xp=np):
    """j0(x) = sin(x)/x and j1(x) = (sin x - x cos x)/x^2, accurate to round-off for all x."""
    sn, cs = xp.sin(x), xp.cos(x)
    small = xp.abs(x) < 1.0
    x2 = x * x
    series = 0.0
    for c in _J1_REVERSED:
        series = series * x2 + c
    safe = xp.where(small, 1.0, x)
    j1 = xp.where(small, x * series, (sn - x * cs) / (safe * safe))
    nonzero = xp.where(x == 0.0, 1.0, x)
    j0 = xp.where(x == 0.0, 1.0, sn / nonzero)
    return j0, j1


def angles_at(th, ph, W, w, acc1, acc2, t):
    """theta, phi, theta_dot, phi_dot after time t (polynomials in t)."""
    return th + t * (W + 0.5 * acc2 * t), ph + t * (w + 0.5 * acc1 * t), W + acc2 * t, w + acc1 * t


def displacement_closed(W, w, ph, acc2, t, R, xp=np):
    """Contact-point displacement over [0, t] without steering torque (acc1 = 0), exact:
    z(t) - z0 = R t e^{i(phi0 + x)} [theta_dot0 j0 + acc2 t (j0 + i j1) / 2], x = phi_dot0 t / 2."""
    half = 0.5 * w * t
    j0, j1 = sinc_kernels(half, xp)
    mid = ph + half
    cm, sm = xp.cos(mid), xp.sin(mid)
    half_gain = 0.5 * acc2 * t
    br = W * j0 + half_gain * j0
    bi = half_gain * j1
    Rt = R * t
    return Rt * (cm * br - sm * bi), Rt * (sm * br + cm * bi)


def end_point(x, y, ph, W, w, sigma, R, xp=np):
    """Position and velocity of an end (sigma = +1 front, -1 back)."""
    c, sn = xp.cos(ph), xp.sin(ph)
    sR = sigma * R
    return x + sR * c, y + sR * sn, R * W * c - sR * w * sn, R * W * sn + sR * w * c


def acceleration_bound(W_lo, W_hi, w_lo, w_hi, acc1, acc2, R, grad_bound, hessian_bound, xp=np):
    """M >= g'' = end'^T H end' + grad h . end'' over an interval, from end-point angular speeds:
    |end'| <= R sqrt(W^2 + w^2), |end''| <= R sqrt((|acc2| + w^2)^2 + (|acc1| + |w W|)^2)."""
    Wm = xp.maximum(xp.abs(W_lo), xp.abs(W_hi))
    wm = xp.maximum(xp.abs(w_lo), xp.abs(w_hi))
    a_par = xp.abs(acc2) + wm * wm
    a_perp = xp.abs(acc1) + wm * Wm
    return hessian_bound * (R * R * (Wm * Wm + wm * wm)) + grad_bound * (R * xp.sqrt(a_par * a_par + a_perp * a_perp))


def safe_step(g, gd, M, xp=np):
    """Largest tau with g + gd tau + M tau^2 / 2 <= 0 (g clamped to <= 0), inf when unbounded."""
    gc = xp.minimum(g, 0.0)
    pos = M > 0.0
    Ms = xp.where(pos, M, 1.0)
    sq = xp.sqrt(gd * gd - 2.0 * Ms * gc)
    inward = gd <= 0.0
    den = xp.where(inward, 1.0, gd + sq)
    quad = xp.where(inward, (sq - gd) / Ms, -2.0 * gc / den)
    gds = xp.where(gd > 0.0, gd, 1.0)
    lin = xp.where(gd > 0.0, -gc / gds, xp.inf)  # M == 0: only a linear approach reaches the wall
    return xp.where(pos, quad, lin)


def search_step(g, gd, M, delta, xp=np):
    """Certified step for one end: the largest tau with g + gd tau + M tau^2 / 2 <= delta.
    Allowing a penetration of delta (a few ulps of the table) makes every step positive."""
    return safe_step(g - delta, gd, M, xp)


def newton_polish(g, gd, M, delta, xp=np):
    """Newton correction -g/gd (gd > 0) of a time where the end is within delta of the wall,
    limited to sqrt(2 delta / M), the time over which the curvature can matter at that depth."""
    cap = xp.where(M > 0.0, xp.sqrt(2.0 * delta / xp.where(M > 0.0, M, 1.0)), xp.inf)
    return xp.minimum(xp.maximum(-g / gd, -cap), cap)


def law_update(W, w, a, b, grad2, e, plastic, Itot, J, m, xp=np):
    """Post-impact (theta_dot, phi_dot) for the normal form n = a W + b w (see laws.py).

    e: restitution coefficient (ignored when plastic). plastic: the paper's pi_Delta o P,
    k = 2 n / (|grad h|^2/m + b^2/J); an end still moving outward after it gets n = 0."""
    vn = a * W + b * w
    metric = a * a / Itot + b * b / J
    if plastic:
        k = 2.0 * vn / (grad2 / m + b * b / J)
        k = xp.where((vn > 0.0) & (vn - k * metric > 0.0), vn / metric, k) if xp is np else (
            vn / metric if (vn > 0.0 and vn - k * metric > 0.0) else k)
    else:
        k = (1.0 + e) * vn / metric
    return W - k * a / Itot, w - k * b / J
