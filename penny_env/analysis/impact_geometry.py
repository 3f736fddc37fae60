"""The impact geometry of the penny in scaled speeds: the formulas of docs/controllability_theory.md.

On the constraint distribution the kinetic energy is T = ((I + m R^2) theta_dot^2 + J phi_dot^2) / 2,
so in the scaled speeds (u, w) = (sqrt(I + m R^2) theta_dot, sqrt(J) phi_dot) it is (u^2 + w^2) / 2:
the metric is Euclidean. An end sigma (+1 front, -1 back) on the wall, with n the unit outward
normal of the wall there, e = (cos phi, sin phi) the heading and e_perp = (-sin phi, cos phi),
moves outward at R theta_dot (grad h . e) + sigma R phi_dot (grad h . e_perp) = nu . (u, w) with

    nu = |grad h| R (cos beta / sqrt(I + m R^2), sigma sin beta / sqrt(J)),
    cos beta = n . e,  sin beta = n . e_perp   (beta: the incidence angle, heading vs normal).

Every law of the package is v+ = v - (1 + e) (v . nu) nu / |nu|^2 in these coordinates (T1): the
reflection across nu (elastic, e = 1), a restitution e in [0, 1], or the paper's plastic law with
the angle-dependent e(beta) of :func:`plastic_coefficient`.

numpy only (no scipy): the witness controllers and the tests import it. Arrays broadcast.
"""
from __future__ import annotations

import math

import numpy as np

from ..physics.flows import PHI, X, Y
from ..physics.laws import make_law


def scaled_speeds(theta_dot, phi_dot, params):
    """(u, w) = (sqrt(I + m R^2) theta_dot, sqrt(J) phi_dot): the kinetic energy is (u^2 + w^2) / 2."""
    return math.sqrt(params.rolling_inertia) * np.asarray(theta_dot, float), math.sqrt(params.J) * np.asarray(phi_dot, float)


def unscaled_speeds(u, w, params):
    """(theta_dot, phi_dot) of scaled speeds (u, w)."""
    return np.asarray(u, float) / math.sqrt(params.rolling_inertia), np.asarray(w, float) / math.sqrt(params.J)


def incidence(state, end, params, table):
    """(cos beta, sin beta, |grad h|) at the end `end` (+1 front, -1 back) of (6,) or (N, 6) states:
    cos beta = n . e, sin beta = n . e_perp, n = grad h / |grad h| at the end's position."""
    s = np.asarray(state, float)
    phi = s[..., PHI]
    c, sn = np.cos(phi), np.sin(phi)
    px = s[..., X] + end * params.R * c
    py = s[..., Y] + end * params.R * sn
    hx, hy = table.grad(px, py)
    g = np.hypot(hx, hy)
    return (hx * c + hy * sn) / g, (hy * c - hx * sn) / g, g


def impact_normal(state, end, params, table):
    """The impact normal nu = (nu_u, nu_w) in scaled speeds: the end's outward normal speed is nu . (u, w)."""
    cb, sb, g = incidence(state, end, params, table)
    return g * params.R * cb / math.sqrt(params.rolling_inertia), end * g * params.R * sb / math.sqrt(params.J)


def restitution_map(u, w, nu_u, nu_w, e):
    """v+ = v - (1 + e) (v . nu) nu / |nu|^2: the reflection across nu (e = 1) or a restitution."""
    k = (1.0 + np.asarray(e, float)) * (u * nu_u + w * nu_w) / (nu_u * nu_u + nu_w * nu_w)
    return u - k * nu_u, w - k * nu_w


def plastic_coefficient(beta, params):
    """The paper's plastic law pi_Delta o P as a restitution coefficient, e(beta) = 2 k - 1 with
    k = (R^2 cos^2 beta / (I + m R^2) + R^2 sin^2 beta / J) / (1 / m + R^2 sin^2 beta / J)
    (T1.3). The thin uniform penny (I = m R^2 / 2, J = m R^2 / 4): (cos^2/3 + 3 sin^2) / (1 + 4 sin^2),
    1/3 head-on, 3/5 sideways. May be negative (I > m R^2 head-on, or J > m R^2 sideways): the
    simulator then removes the normal speed, see :func:`effective_plastic_coefficient`."""
    c2, s2 = np.cos(beta) ** 2, np.sin(beta) ** 2
    R2 = params.R * params.R
    k = (R2 * c2 / params.rolling_inertia + R2 * s2 / params.J) / (1.0 / params.m + R2 * s2 / params.J)
    return 2.0 * k - 1.0


def effective_plastic_coefficient(beta, params):
    """The restitution coefficient the simulator's plastic law applies: max(e(beta), 0) (sticking)."""
    return np.maximum(plastic_coefficient(beta, params), 0.0)


def full_conversion_angle(params) -> float:
    """beta* with tan beta* = sqrt(J / (I + m R^2)): an elastic impact at this incidence of a penny
    that does not spin (phi_dot = 0) leaves theta_dot = 0, all its energy in spin (T2.4).
    atan(sqrt(1/6)) = 22.2 degrees for the thin uniform penny."""
    return math.atan(math.sqrt(params.J / params.rolling_inertia))


def stopping_angle(law, params) -> float:
    """The incidence beta at which an impact of a penny that does not spin (phi_dot = 0) leaves theta_dot = 0
    (T2.4): tan^2 beta = e J / (I + m R^2) for a restitution e ("elastic": e = 1, :func:`full_conversion_angle`);
    for "plastic" the root of tan^2 beta = e(beta) J / (I + m R^2) (sin beta = 1/4 for the thin uniform penny)."""
    parsed = make_law(law)  # a clear TypeError / ValueError naming the law for anything else
    ratio = params.J / params.rolling_inertia
    if parsed.kind == "elastic":
        return full_conversion_angle(params)
    if parsed.kind == "restitution":
        return math.atan(math.sqrt(parsed.e * ratio))
    if parsed.kind != "plastic":
        raise ValueError(f"stopping_angle: law must be 'elastic', 'plastic' or a restitution e in [0, 1], got {law!r}")
    lo, hi = 0.0, 0.5 * math.pi  # tan^2 - e(beta) ratio rises from -e(0) ratio <= 0 to +inf
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid in (lo, hi):
            break
        if math.tan(mid) ** 2 < float(effective_plastic_coefficient(mid, params)) * ratio:
            lo = mid
        else:
            hi = mid
    return lo


def rest_making_spin(u, nu_u, nu_w, e):
    """The pre-impact scaled spin w* that leaves u+ = 0 for a restitution e across nu (T2.4):
    w* = u (|nu|^2 - (1 + e) nu_u^2) / ((1 + e) nu_u nu_w); needs an oblique impact (nu_u nu_w != 0).
    The end then moves outward at u |nu|^2 / ((1 + e) nu_u): an impact iff u nu_u > 0."""
    n2 = nu_u * nu_u + nu_w * nu_w
    return u * (n2 - (1.0 + e) * nu_u * nu_u) / ((1.0 + e) * nu_u * nu_w)


def free_angle(beta) -> float:
    """The most the heading of a penny that stopped rolling at an impact of incidence beta can turn, spinning in
    place, before one of its ends reaches the impact point's tangent line again: pi - 2 |beta| (T2.8; the contact
    point is R cos beta inside the tangent, the back end reaches it first). On a convex table, which lies on one side
    of that tangent, the next impact comes no later."""
    return math.pi - 2.0 * abs(float(beta))


def stopping_spin(u, nu_u, nu_w, e):
    """The scaled spin w+ right after a stopping impact (u+ = 0, T2.4) of a penny rolling at scaled speed u:
    -e u / ((1 + e) n_u n_w), n = nu / |nu| (the tangential part of v is kept and the normal part scaled by -e,
    with v+ = (0, w+)). Since |n_u n_w| <= 1/2, |w+| >= 2 e |u| / (1 + e), with equality where |n_u| = |n_w|
    (T2.8)."""
    n = np.hypot(nu_u, nu_w)
    return -np.asarray(e, float) * u / ((1.0 + np.asarray(e, float)) * (nu_u / n) * (nu_w / n))


def braking_threshold(params, a1, e=1.0, angle=math.pi) -> float:
    """T2.8: the pre-impact rolling speed |theta_dot| above which the spin left by a stopping impact with
    restitution e cannot be braked at |phi''| <= a1 within `angle` (the free angle, at most pi): the spin after
    it is at least (2 e / (1 + e)) sqrt((I + m R^2) / J) |theta_dot| (:func:`stopping_spin`), and braking it turns
    the heading by spin^2 / (2 a1): ((1 + e) / (2 e)) sqrt(2 a1 angle J / (I + m R^2)). 3.24 rad/s for the paper's
    penny with a1 = 10 rad/s^2 on elastic walls, 4.85 rad/s at e = 0.5 (angle pi). A plastic wall has e(beta) >= its
    smallest value (1/3 for the thin penny): use that e."""
    if not (e > 0.0):
        return math.inf
    return (1.0 + e) / (2.0 * e) * math.sqrt(2.0 * a1 * angle * params.J / params.rolling_inertia)


def energy_loss(u, w, nu_u, nu_w, e):
    """Kinetic energy removed by a restitution e across nu: (1 - e^2) (v . nu)^2 / (2 |nu|^2)."""
    vn = u * nu_u + w * nu_w
    return (1.0 - np.asarray(e, float) ** 2) * vn * vn / (2.0 * (nu_u * nu_u + nu_w * nu_w))


# -- heading lines and their crossings with the wall (T3.4) -------------------------------------
def wall_crossing(table, x, y, dx, dy):
    """The point where the ray (x, y) + t (dx, dy), t > 0, from a point inside the table meets the
    wall (h = 0), by bisection to round-off (the table is convex, so h changes sign once)."""
    d = math.hypot(dx, dy)
    if not (math.isfinite(d) and d > 0.0):
        raise ValueError(f"wall_crossing: the direction (dx, dy) must be finite and nonzero, got {(dx, dy)!r}")
    if not float(table.h(x, y)) < 0.0:
        raise ValueError(f"wall_crossing: the point (x, y) = {(x, y)!r} must lie inside the table")
    dx, dy = dx / d, dy / d
    lo, hi = 0.0, 1.0
    span = max(abs(v) for v in table.extent)
    while float(table.h(x + hi * dx, y + hi * dy)) < 0.0 and hi < 1e3 * span:
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid in (lo, hi):
            break
        if float(table.h(x + mid * dx, y + mid * dy)) < 0.0:
            lo = mid
        else:
            hi = mid
    return x + lo * dx, y + lo * dy


def line_incidence(table, x, y, phi):
    """(sin beta forward, sin beta backward): the incidence at the two points where the heading line
    through the contact point (x, y) meets the wall. A drive-only penny that does not spin stays on
    this line and its ends hit the wall exactly there; sin beta = 0 is a head-on hit (T3.4)."""
    c, sn = math.cos(phi), math.sin(phi)
    out = []
    for sigma in (1.0, -1.0):
        px, py = wall_crossing(table, x, y, sigma * c, sigma * sn)
        hx, hy = table.grad(px, py)
        out.append(float((hy * c - hx * sn) / math.hypot(hx, hy)))
    return out[0], out[1]


# -- drive only with spin: the crawl of T3.3 ----------------------------------------------------
def crawl_rolling_speed(phi, phi0, delta, alpha):
    """theta_dot = delta (cos(phi - alpha) - cos(phi0 - alpha)): with phi_dot = w != 0 constant and this
    rolling speed, each turn of the heading (period 2 pi / |w|) moves the contact point by
    :func:`crawl_displacement` and ends with theta_dot = 0 again (T3.3)."""
    return delta * (np.cos(phi - alpha) - np.cos(phi0 - alpha))


def crawl_displacement(R, w, delta, alpha):
    """Contact-point displacement over one turn of the crawl: pi R delta / |w| (cos alpha, sin alpha)."""
    step = math.pi * R * delta / abs(w)
    return step * math.cos(alpha), step * math.sin(alpha)
