"""The penny's formulas, written once for numpy arrays and for Python floats.

Every kernel takes the math namespace ``xp`` last: :data:`ARRAY` (numpy) for batches (elementwise
over (N,) arrays) or :data:`SCALAR` for one penny in plain floats (what the single environment and
simulate() run: numpy on size-1 arrays costs ~1 us per call). Both evaluate the same IEEE
operations in the same order, so batched and scalar results agree bitwise on a given machine.
Branches are written as ``xp.where`` over expressions that are finite in both branches.
"""
from __future__ import annotations

import math
import types

import numpy as np


def math_namespace(name, scalar, **functions):
    """A module object holding the math functions the kernels call as ``xp.<name>``.

    ``scalar`` tells a kernel whether it runs on one penny (plain floats: take the branch, skip
    the other) or on arrays (evaluate both branches, select with ``xp.where``). A module, not a
    class instance, so numba can compile the kernels with such a namespace (backends/physics.py)."""
    ns = types.ModuleType(name)
    ns.scalar = scalar
    for key, value in functions.items():
        setattr(ns, key, value)
    return ns


def _where(cond, a, b):
    return a if cond else b


ARRAY = math_namespace("penny_env_array_math", False, sin=np.sin, cos=np.cos, sqrt=np.sqrt, abs=np.abs,
                       minimum=np.minimum, maximum=np.maximum, where=np.where, inf=np.inf)
SCALAR = math_namespace("penny_env_scalar_math", True, sin=math.sin, cos=math.cos, sqrt=math.sqrt, abs=abs,
                        minimum=min, maximum=max, where=_where, inf=math.inf, pi=math.pi,
                        # 64-bit integers of the counter-based draws (step/draws.py): Python ints, masked there
                        u64=int, to_float=float, ONE=1, GOLDEN=0x9E3779B97F4A7C15, M1=0xBF58476D1CE4E5B9,
                        M2=0x94D049BB133111EB, MASK=(1 << 64) - 1, U11=11, U27=27, U30=30, U31=31)

# j1(x) = sum_k (-1)^k (2k+2) x^(2k+1) / (2k+3)!, truncated where terms drop below 1e-19 for |x| < 1
_J1_COEFFS = []
_f = 6.0
for _k in range(10):
    _J1_COEFFS.append((-1) ** _k * (2 * _k + 2) / _f)
    _f *= (2 * _k + 4) * (2 * _k + 5)
_J1_REVERSED = tuple(_J1_COEFFS[::-1])


# cos z and sin z / z by their Taylor series, in two sizes. Through z^10: truncation below 3e-19
# for |z| <= SMALL_ANGLE; through z^14: below 3e-20 for |z| <= MEDIUM_ANGLE. There the Horner sums
# are as accurate as libm (about 1 ulp, tests/backends/test_compiled.py) and cost less than libm's sin and cos.
SMALL_ANGLE = 0.15
MEDIUM_ANGLE = 0.4
_C0, _C1, _C2, _C3, _C4, _C5, _C6, _C7 = ((-1) ** j / math.factorial(2 * j) for j in range(8))
_S0, _S1, _S2, _S3, _S4, _S5, _S6, _S7 = ((-1) ** j / math.factorial(2 * j + 1) for j in range(8))


def cis_small(z, xp=ARRAY):
    """(cos z, sin z) for |z| <= SMALL_ANGLE by polynomials: a handful of multiply-adds where
    libm's sin and cos cost tens of nanoseconds (the quadrature's inner loop, flows.py). Horner's
    scheme written out: a loop would cost Python more than the arithmetic."""
    z2 = z * z
    c = ((((_C5 * z2 + _C4) * z2 + _C3) * z2 + _C2) * z2 + _C1) * z2 + _C0
    sn = ((((_S5 * z2 + _S4) * z2 + _S3) * z2 + _S2) * z2 + _S1) * z2 + _S0
    return c, z * sn


def cis_medium(z, xp=ARRAY):
    """(cos z, sin z) for |z| <= MEDIUM_ANGLE: :func:`cis_small` with two more terms."""
    z2 = z * z
    c = ((((((_C7 * z2 + _C6) * z2 + _C5) * z2 + _C4) * z2 + _C3) * z2 + _C2) * z2 + _C1) * z2 + _C0
    sn = ((((((_S7 * z2 + _S6) * z2 + _S5) * z2 + _S4) * z2 + _S3) * z2 + _S2) * z2 + _S1) * z2 + _S0
    return c, z * sn


def sinc_kernels(x, xp=ARRAY):
    """j0(x) = sin(x)/x and j1(x) = (sin x - x cos x)/x^2, accurate to round-off for all x."""
    if xp.scalar:  # the same formulas, evaluating only the branch taken
        sn, cs = math.sin(x), math.cos(x)
        if abs(x) < 1.0:
            x2 = x * x
            series = 0.0
            for c in _J1_REVERSED:
                series = series * x2 + c
            j1 = x * series
        else:
            j1 = (sn - x * cs) / (x * x)
        return (1.0 if x == 0.0 else sn / x), j1
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


def displacement_closed(W, w, ph, acc2, t, R, xp=ARRAY):
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


def end_point(x, y, ph, W, w, sigma, R, xp=ARRAY):
    """Position and velocity of an end (sigma = +1 front, -1 back)."""
    c, sn = xp.cos(ph), xp.sin(ph)
    sR = sigma * R
    return x + sR * c, y + sR * sn, R * W * c - sR * w * sn, R * W * sn + sR * w * c


def motion_bounds(W_lo, W_hi, w_lo, w_hi, acc1, acc2, R, xp=ARRAY):
    """Bounds (V^2, A, J) on |p'|^2, |p''| and |p'''| of an end p over an interval, from the
    end-point angular speeds (theta_dot and phi_dot are linear in time, so extremes are at the
    ends). With s = +-1 the end, p' = R e^{i phi} (W + i s w),
    p'' = R e^{i phi} [(acc2 - s w^2) + i (w W + s acc1)],
    p''' = R e^{i phi} [(-w^2 W - 3 s w acc1) + i (2 w acc2 - s w^3 + acc1 W)]."""
    Wm = xp.maximum(xp.abs(W_lo), xp.abs(W_hi))
    wm = xp.maximum(xp.abs(w_lo), xp.abs(w_hi))
    a1, a2 = xp.abs(acc1), xp.abs(acc2)
    a_par = a2 + wm * wm
    a_perp = a1 + wm * Wm
    j_par = wm * wm * Wm + 3.0 * wm * a1
    j_perp = 2.0 * wm * a2 + wm * wm * wm + a1 * Wm
    return (R * R * (Wm * Wm + wm * wm), R * xp.sqrt(a_par * a_par + a_perp * a_perp),
            R * xp.sqrt(j_par * j_par + j_perp * j_perp))


def curvature_bounds(V2, A, J, grad_bound, hessian_bound, third_bound, xp=ARRAY):
    """M >= g'' = p'^T H p' + grad h . p'' and K >= |g'''| (between Hessian jumps), g = h(p(t))."""
    V = xp.sqrt(V2)
    M = hessian_bound * V2 + grad_bound * A
    K = third_bound * V2 * V + 3.0 * hessian_bound * V * A + grad_bound * J
    return M, K


def acceleration_bound(W_lo, W_hi, w_lo, w_hi, acc1, acc2, R, grad_bound, hessian_bound, xp=ARRAY):
    """M >= g'' over an interval (see motion_bounds)."""
    V2, A, _ = motion_bounds(W_lo, W_hi, w_lo, w_hi, acc1, acc2, R, xp)
    return hessian_bound * V2 + grad_bound * A


def local_curvature(c, sn, W, w, acc1, acc2, sigma, R, hx, hy, hxx, hxy, hyy, xp=ARRAY):
    """g''(t) = p'^T H p' + grad h . p'' at the current state (c, sn: cos, sin of the heading), exactly."""
    vx = R * (W * c - sigma * w * sn)
    vy = R * (W * sn + sigma * w * c)
    ar = acc2 - sigma * w * w
    ai = w * W + sigma * acc1
    ax = R * (ar * c - ai * sn)
    ay = R * (ar * sn + ai * c)
    return hxx * vx * vx + 2.0 * hxy * vx * vy + hyy * vy * vy + hx * ax + hy * ay


def curvature_step(g, gd, A, M, K, delta, xp=ARRAY):
    """Certified step from the local curvature A >= g''(t) (Hessian-jump allowance included) and
    |d^3 g/dt^3| <= K. By Taylor, g(t + s) <= g + gd s + (A + K tau / 3) s^2 / 2 for s <= tau, so
    two windows are certified: tau = 3 (M - A) / (2 K) with curvature (A + M) / 2, and, when the end
    curves away from the wall (A < 0), tau = 3 |A| / (2 K) with the concave curvature A / 2. Near a
    tangency the second one turns the geometric shrinking of the global-bound steps into
    Newton-like steps from below."""
    gap = xp.maximum(M - A, 0.0)
    if xp.scalar:
        if not K > 0.0:
            return search_step(g, gd, A, delta, xp)  # g'' is constant
        step = min(search_step(g, gd, 0.5 * (A + M), delta, xp), 1.5 * gap / K)
        if A < 0.0:
            step = max(step, min(search_step(g, gd, 0.5 * A, delta, xp), -1.5 * A / K))
        return step
    pos = K > 0.0
    Ks = xp.where(pos, K, 1.0)
    step = xp.minimum(search_step(g, gd, 0.5 * (A + M), delta, xp), 1.5 * gap / Ks)
    concave = xp.minimum(search_step(g, gd, 0.5 * A, delta, xp), -1.5 * A / Ks)
    step = xp.where(A < 0.0, xp.maximum(step, concave), step)
    return xp.where(pos, step, search_step(g, gd, A, delta, xp))


def safe_step(g, gd, M, xp=ARRAY):
    """Largest tau such that g + gd s + M s^2 / 2 <= 0 for all s in [0, tau] (g clamped to <= 0);
    inf when the bound never reaches 0. M may be negative (a concave bound)."""
    r = -xp.minimum(g, 0.0)
    disc = gd * gd + 2.0 * M * r
    if xp.scalar:
        if gd > 0.0:
            return 2.0 * r / (gd + math.sqrt(disc)) if disc >= 0.0 else math.inf
        return (math.sqrt(disc) - gd) / M if M > 0.0 else math.inf
    ok = disc >= 0.0
    sq = xp.sqrt(xp.where(ok, disc, 0.0))
    rising = gd > 0.0
    towards = xp.where(ok, 2.0 * r / xp.where(rising, gd + sq, 1.0), xp.inf)
    away = xp.where(M > 0.0, (sq - gd) / xp.where(M > 0.0, M, 1.0), xp.inf)
    return xp.where(rising, towards, away)


def search_step(g, gd, M, delta, xp=ARRAY):
    """Certified step for one end: the largest tau with g + gd tau + M tau^2 / 2 <= delta.
    Allowing a penetration of delta (a few ulps of the table) makes every step positive."""
    if xp.scalar:  # safe_step(g - delta, ...) inlined: this is the scalar search's innermost call
        r = -min(g - delta, 0.0)
        disc = gd * gd + 2.0 * M * r
        if gd > 0.0:
            return 2.0 * r / (gd + math.sqrt(disc)) if disc >= 0.0 else math.inf
        return (math.sqrt(disc) - gd) / M if M > 0.0 else math.inf
    return safe_step(g - delta, gd, M, xp)


def time_resolution(delta, M, xp=ARRAY):
    """sqrt(2 delta / M): the time over which the search cannot tell a graze of depth delta from
    a touch. Impacts closer together than a few of these are an accumulation (Zeno)."""
    if xp.scalar:
        return math.sqrt(2.0 * delta / M) if M > 0.0 else math.inf
    return xp.where(M > 0.0, xp.sqrt(2.0 * delta / xp.where(M > 0.0, M, 1.0)), xp.inf)


def newton_polish(g, gd, M, delta, xp=ARRAY):
    """Newton correction -g/gd (gd > 0) of a time where the end is within delta of the wall,
    limited to sqrt(2 delta / M), the time over which the curvature can matter at that depth."""
    cap = time_resolution(delta, M, xp)
    return xp.minimum(xp.maximum(-g / gd, -cap), cap)


def law_update(W, w, a, b, grad2, e, plastic, Itot, J, m, xp=ARRAY):
    """Post-impact (theta_dot, phi_dot) for the normal form n = a W + b w (see laws.py).

    e: restitution coefficient (ignored when plastic). plastic: the paper's pi_Delta o P,
    k = 2 n / (|grad h|^2/m + b^2/J); an end still moving outward after it gets n = 0."""
    vn = a * W + b * w
    metric = a * a / Itot + b * b / J
    if plastic:
        k = 2.0 * vn / (grad2 / m + b * b / J)
        if xp.scalar:
            k = vn / metric if (vn > 0.0 and vn - k * metric > 0.0) else k
        else:
            k = xp.where((vn > 0.0) & (vn - k * metric > 0.0), vn / metric, k)
    else:
        k = (1.0 + e) * vn / metric
    return W - k * a / Itot, w - k * b / J
