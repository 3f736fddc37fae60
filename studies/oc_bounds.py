"""Certified lower bounds on the time of every impact-free plan (docs/optimal_control.md, issue 32 item 5).

Without an impact the rolling speed obeys |theta''| <= a2 = u2_max / (I + m R^2) (0 steering only) and the contact
point moves at R |theta_dot|. A plan reaches the terminal set at the end of a control row (the shooting problems of
studies/optimal_control.py: |contact - target| <= tol, and for a park |R theta_dot| <= v_tol, each with the
verification's relative slack 1e-6). So at the end time T = K dt:

* both controls (the heading is free): |contact(T) - start| <= R int_0^T |theta_dot|, and |theta_dot(t)| <=
  min(|w0| + a2 t, wf + a2 (T - t)) pointwise (wf = v_tol / R for a park, +inf for a reach), so the displacement is
  at most R times the integral of that tent; a park needs |w0| - a2 T <= wf besides;
* drive only: the heading is phi0 + phi_dot0 t exactly (T3.1, no impact), so the displacement along the target's
  direction alpha is R int theta_dot(t) cos(phi(t) - alpha) dt <= R (w0 C(0) + a2 int_0^T |C(s)| ds),
  C(s) = int_s^T cos(phi(t) - alpha) dt (integrate by parts, |theta''| <= a2), which must reach D - tol;
* steer only: theta_dot is constant (T2.1); from |R theta_dot| > v_tol a park is infeasible (T2).

:func:`rows_lower_bound` gives the fewest rows K for which the necessary condition holds: no impact-free plan
reaches the set in fewer rows. A plan with impacts that reaches it in fewer rows is certified better than every
impact-free plan, whatever a local search finds.
"""
from __future__ import annotations

import math

import numpy as np

SLACK = 1e-6  # the verification's relative slack on tolerance and speed_tolerance (impact_oc.in_set)
QUAD = 4000   # quadrature points of the drive-only bound (rigorous: the integrand is 1-Lipschitz, see below)


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


def drive_projection_bound(w0, phi0, phi_dot, alpha, a, T, n=QUAD):
    """An upper bound of int_0^T theta_dot(t) cos(phi0 + phi_dot t - alpha) dt over theta_dot(0) = w0,
    |theta''| <= a: w0 C(0) + a int |C|, with int |C| bounded by the left Riemann sum of |C| plus T h / 2 (|C| is
    1-Lipschitz: |C'| = |cos| <= 1)."""
    def C(s):  # int_s^T cos(phi0 + phi_dot t - alpha) dt
        if abs(phi_dot) < 1e-12:
            return (T - s) * math.cos(phi0 - alpha)
        return (np.sin(phi0 + phi_dot * T - alpha) - np.sin(phi0 + phi_dot * s - alpha)) / phi_dot
    h = T / n
    s = np.arange(n) * h
    integral = h * float(np.sum(np.abs(C(s)))) + 0.5 * T * h
    return w0 * float(C(0.0)) + a * integral


def rows_lower_bound(prob, actuation, max_rows=4000):
    """(K, reason): no impact-free plan of the problem (its start, target, task, limits, control period) reaches the
    terminal set in fewer than K rows; K = max_rows + 1 where none can within max_rows. reason names the bound."""
    R, dt = prob.params.R, prob.dt
    a2 = prob.limits[1] / prob.params.rolling_inertia
    tol = prob.tolerance * (1 + SLACK)
    wf = prob.speed_tolerance * (1 + SLACK) / R if prob.task == "park" else math.inf
    s, g = prob.start, prob.target
    D = math.hypot(g[0] - s[0], g[1] - s[1])
    need = D - tol
    if actuation == "steer":
        if prob.task == "park" and abs(R * s[4]) > prob.speed_tolerance * (1 + SLACK):
            return max_rows + 1, "T2: theta_dot is conserved without impacts"
        return 1, "none (steer only)"
    alpha = math.atan2(g[1] - s[1], g[0] - s[0])
    for K in range(1, max_rows + 1):
        T = K * dt
        if actuation == "drive":
            reach = R * drive_projection_bound(s[4], s[3], s[5], alpha, a2, T) if need > 0 else math.inf
            ok = reach >= need and (prob.task != "park" or abs(s[4]) - a2 * T <= wf)
        else:
            ok = R * tent_distance(s[4], wf, a2, T) >= need
        if ok:
            return K, ("distance along the turning heading" if actuation == "drive" else
                       "distance and end speed at the rolling torque limit")
    return max_rows + 1, "no impact-free plan within the rows searched"
