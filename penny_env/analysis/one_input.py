"""The formulas of theorems T7.1, T7.2 and T7.4 (docs/controllability_theory.md, section T7): one input, approximately.

* T7.1 (drive only, from rest, every convex table): rolling slowly into a crossing of the heading line that is not
  head-on gives the spin :func:`post_impact_spin` (nonzero), after which the penny backs off to where it started and
  crawls (T3.3) to any point with clearance above R.
* T7.2 (steer only, the circle, dissipative walls): a penny rolling along a diameter bounces head-on, each impact
  multiplying theta_dot by -e0 (:func:`head_on_coefficient`), so after :func:`bounces_to_slow` impacts it creeps
  slower than any tolerance, and T6.1 parks it.
* T7.4 (steer only, the elastic circle): along a chord at :func:`stop_chord_distance` every impact is a full stop
  (all rolling into spin) or a full release (all spin into rolling); braking over :func:`circle_free_angle` between
  them lowers phi_dot^2 by 2 a1 times it per cycle (:func:`release_cycles`).
"""
from __future__ import annotations

import math

from ..physics.laws import make_law
from .impact_geometry import effective_plastic_coefficient


def head_on_coefficient(law, params) -> float:
    """e0, the factor a head-on impact (sin beta = 0, no spin) applies to theta_dot, with the sign reversed:
    theta_dot+ = -e0 theta_dot. Restitution e: e; elastic: 1; plastic: e(0) = 2 m R^2 / (I + m R^2) - 1 (T1.3;
    1/3 for the thin penny), or 0 where that is negative (sticking, T1.4)."""
    parsed = make_law(law)
    if parsed.kind == "elastic":
        return 1.0
    if parsed.kind == "restitution":
        return float(parsed.e)
    if parsed.kind == "plastic":
        return float(effective_plastic_coefficient(0.0, params))
    raise ValueError(f"head_on_coefficient: a built-in law, got {law!r}")


def ladder_rolling_speed(theta_dot0, e0, k):
    """theta_dot after k head-on impacts along a double normal: theta_dot0 (-e0)^k (T7.2)."""
    return theta_dot0 * (-e0) ** k


def bounces_to_slow(v0, v, e0) -> int:
    """The fewest head-on impacts after which a penny rolling at |R theta_dot| = v0 rolls slower than v (0 < e0 < 1)."""
    if not 0.0 < e0 < 1.0:
        raise ValueError(f"the ladder needs 0 < e0 < 1, got {e0!r}")
    if v0 < v:
        return 0
    return int(math.floor(math.log(v / v0) / math.log(e0))) + 1


def post_impact_spin(theta_dot, cos_beta, sin_beta, sigma, law, params, grad_norm=1.0):
    """phi_dot after an impact of end sigma of a penny with phi_dot = 0 rolling at theta_dot (T3.4's converse, used
    by T7.1): -(1 + e) u nu_u nu_w / |nu|^2 / sqrt(J), u = sqrt(I + m R^2) theta_dot, nu as in T1.2. Nonzero at an
    oblique impact (sin beta cos beta != 0) of a rolling penny, for every law (1 + e >= 1)."""
    from .impact_geometry import plastic_coefficient

    parsed = make_law(law)
    beta = math.atan2(sin_beta, cos_beta)
    e = {"elastic": 1.0, "restitution": getattr(parsed, "e", None)}.get(parsed.kind)
    if parsed.kind == "plastic":
        e = max(float(plastic_coefficient(beta, params)), 0.0)
    s_i, s_j = math.sqrt(params.rolling_inertia), math.sqrt(params.J)
    nu_u = grad_norm * params.R * cos_beta / s_i
    nu_w = grad_norm * params.R * sigma * sin_beta / s_j
    u = s_i * theta_dot
    return -(1.0 + e) * u * nu_u * nu_w / (nu_u * nu_u + nu_w * nu_w) / s_j


# -- T7.4: steer only, the elastic circle: stop and release -------------------------------------------------------
def stop_chord_distance(radius, beta) -> float:
    """Distance from the centre of a disk of the given radius of the lines that meet its wall at incidence beta at
    both crossings (a chord meets a circle at equal angles at both ends): radius sin(beta)."""
    return radius * math.sin(beta)


def stop_position_radius(radius, R, d) -> float:
    """|z| of the contact point when the leading end of a penny rolling along the line at distance d reaches the
    wall: z = C - R e with C = (sqrt(radius^2 - d^2), d) and e = (1, 0)."""
    return math.hypot(math.sqrt(radius * radius - d * d) - R, d)


def circle_free_angle(radius, R, d) -> float:
    """The angle the heading of a penny spinning in place (theta_dot = 0) at the stop position of the line at
    distance d can turn, starting with an end on the wall, before an end touches the wall again: pi - 2 chi, chi the
    angle between the end's direction and the outward radial direction at the contact point,
    cos chi = (sqrt(radius^2 - d^2) - R) / |z| (the end circle of radius R about z meets the wall at the two points at
    +-chi; both ends stay inside while the end's angle lies in [chi, pi - chi])."""
    r = stop_position_radius(radius, R, d)
    chi = math.acos(max(-1.0, min(1.0, (math.sqrt(radius * radius - d * d) - R) / r)))
    return math.pi - 2.0 * chi


def release_cycles(phi_dot_stop, a1, free_angle) -> int:
    """The stop-and-release cycles after which the spin left by a stop can be braked to 0 within the free angle: each
    cycle (brake at a1 over the free angle, then the release) lowers phi_dot_stop^2 by 2 a1 free_angle (T7.4)."""
    need = phi_dot_stop * phi_dot_stop - 2.0 * a1 * free_angle
    return 0 if need < 0 else int(math.floor(need / (2.0 * a1 * free_angle))) + 1


# -- the hypotheses ("room to aim") of T7.2 and T7.4 -------------------------------------------------------------
def circle_aim_time(phi_dot, a1, max_turn=math.pi) -> float:
    """tau0: brake the spin (|phi_dot| / a1), then a rest-to-rest turn by at most max_turn (2 sqrt(max_turn / a1)):
    T7.2 aims with turns up to pi, T7.4 up to pi / 2."""
    return abs(phi_dot) / a1 + 2.0 * math.sqrt(max_turn / a1)


def circle_ladder_room(radius, z0, v0, tau0, R):
    """T7.2's room: (holds, margins). The disk of radius rho = v0 tau0 about z0 has clearance > R (radius - |z0| - rho
    > R) and does not contain the centre (|z0| > rho)."""
    r, rho = math.hypot(z0[0], z0[1]), v0 * tau0
    margins = (radius - r - rho - R, r - rho)
    return all(m > 0 for m in margins), margins


def circle_stop_room(radius, z0, v0, tau0, R, beta):
    """T7.4's room: (holds, margins). With rho = v0 tau0 and d* = radius sin(beta): the disk of radius rho about z0
    has clearance > R, and rho < d* < |z0| - rho, so that the heading line's distance |z x e| from the centre is below
    d* where e is parallel to z0 and above it where e is perpendicular (both within a quarter turn either way)."""
    r, rho, d = math.hypot(z0[0], z0[1]), v0 * tau0, stop_chord_distance(radius, beta)
    margins = (radius - r - rho - R, d - rho, r - rho - d)
    return all(m > 0 for m in margins), margins
