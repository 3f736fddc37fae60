"""Certified lower bounds on the control rows of every impact-free plan (docs/optimal_control.md).

Without an impact the penny moves exactly as on the open plane, so a bound for the plane holds for every
impact-free plan on a table. A plan reaches the terminal set at the end of a control row (the shooting problems of
studies/optimal_control.py: |contact - target| <= tol, and for a park |R theta_dot| <= v_tol, each with the
verification's relative slack 1e-6). :func:`rows_lower_bound` gives K such that no impact-free plan reaches the set
in fewer than K rows:

* drive only: the heading is phi0 + phi_dot0 t exactly (T3.1), so the end point is affine in the torques and the
  K-row end points form a zonotope; studies/drive_zonotope.py computes the **exact** fewest rows of the plane, with
  every smaller K certified unreachable in interval arithmetic (mpmath.iv). It replaces the earlier bound along the
  target's direction with continuous-time torques, which was valid but loose;
* both controls: first the tent bound (the rolling speed limited by its start and the torque, |contact(T) - start|
  <= R int |theta_dot|, a park brought below v_tol by the end); then the directional bound of studies/both_bound.py
  (the heading within its reachable tube, the displacement along a direction bounded by a validated dynamic
  programme over theta_dot), which certifies the K the tent leaves open;
* steer only: theta_dot is constant (T2.1); from |R theta_dot| > v_tol a park is infeasible (T2).

A plan with impacts that reaches the set in fewer rows is certified better than every impact-free plan, whatever a
local search finds.
"""
from __future__ import annotations

import math

SLACK = 1e-6  # the verification's relative slack on tolerance and speed_tolerance (impact_oc.in_set)


def accelerations(prob):
    """(a1, a2): the largest |phi''| and |theta''| the problem's torque limits allow (0 for an input it lacks)."""
    return prob.limits[0] / prob.params.J, prob.limits[1] / prob.params.rolling_inertia


def tent_distance(w0, wf, a, T):
    """int_0^T min(|w0| + a t, wf + a (T - t)) dt (the largest int |theta_dot| with |theta''| <= a, |theta_dot(0)| =
    |w0|, |theta_dot(T)| <= wf), or -inf when |w0| - a T > wf (the end speed cannot be met)."""
    w0 = abs(w0)
    if w0 - a * T > wf:
        return -math.inf
    if a == 0.0:
        return w0 * T
    if math.isinf(wf):
        return w0 * T + 0.5 * a * T * T
    ts = min(max((wf - w0 + a * T) / (2 * a), 0.0), T)  # where the rising and falling lines cross
    rise = w0 * ts + 0.5 * a * ts * ts
    rest = T - ts
    fall = wf * rest + 0.5 * a * rest * rest  # (wf + a (T - t)) from ts to T
    return rise + fall


def tent_rows(prob, max_rows):
    """The fewest K whose tent distance reaches the target's distance less the tolerance (every smaller K cannot)."""
    R, dt = prob.params.R, prob.dt
    a2 = accelerations(prob)[1]
    tol = prob.tolerance * (1 + SLACK)
    wf = prob.speed_tolerance * (1 + SLACK) / R if prob.task == "park" else math.inf
    s, g = prob.start, prob.target
    need = math.hypot(g[0] - s[0], g[1] - s[1]) - tol
    for K in range(1, max_rows + 1):
        if R * tent_distance(s[4], wf, a2, K * dt) >= need:
            return K
    return max_rows + 1


def rows_lower_bound(prob, actuation, max_rows=400):
    """(K, reason): no impact-free plan of the problem (its start, target, task, limits, control period) reaches the
    terminal set in fewer than K rows; K = max_rows + 1 where none can within max_rows. reason names the bound."""
    from studies import both_bound, drive_zonotope

    R, dt = prob.params.R, prob.dt
    a1, a2 = accelerations(prob)
    tol = prob.tolerance * (1 + SLACK)
    wf = prob.speed_tolerance * (1 + SLACK) / R if prob.task == "park" else math.inf
    s, g = prob.start, prob.target
    if actuation == "steer":
        if prob.task == "park" and abs(R * s[4]) > prob.speed_tolerance * (1 + SLACK):
            return max_rows + 1, "T2: theta_dot is conserved without impacts"
        return 1, "none (steer only)"
    if actuation == "drive":
        K, exact = drive_zonotope.fewest_rows(s[:2], s[3], s[5], s[4], R, a2, dt, g, tol, max_rows=max_rows)
        if prob.task == "park":  # the end speed too: |theta_dot(T)| >= |w0| - a2 T
            K = max(K, next((k for k in range(1, max_rows + 1) if abs(s[4]) - a2 * k * dt <= wf), max_rows + 1))
            exact = False
        return K, ("exact fewest rows of the plane (drive-only end points: a zonotope)" if exact else
                   "drive-only end points (a zonotope), certified")
    K0 = tent_rows(prob, max_rows)
    if K0 > max_rows:
        return K0, "distance and end speed at the rolling torque limit"
    K, _ = both_bound.fewest_rows(s, g, R, a1, a2, dt, tol, wf, max_rows=max_rows, first=K0)
    if K == K0:
        return K, "distance and end speed at the rolling torque limit"
    return K, "heading tube and rolling speed, along a direction (validated)"
