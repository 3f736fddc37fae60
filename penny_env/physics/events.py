"""Certified search for the first impact of either end with the wall.

For an end p(t), g(t) = h(p(t)) is the wall function along the flow. While the end is on the
table, |p'| <= V and |p''| <= A (bounds from the linear-in-time angular velocities), so

    g'' <= M = L V^2 + G A          (L, G: the table's Hessian and gradient bounds).

From a time t the quadratic g(t) + g'(t) tau + M tau^2 / 2 bounds g from above, and it stays
<= delta up to its positive root tau* (delta = contact_tol * table size, a few ulps of the
table). Stepping by tau* therefore never passes over an impact deeper than delta, however
grazing: an impact that enters and leaves between two samples of any grid is still inside some
step's bound. Shallower "impacts" are below the round-off of the positions themselves. Near a
transversal crossing the steps are Newton steps from below and converge quadratically; near a
tangency they shrink geometrically (about 40% per step), so the step count stays small and is
capped by settings.max_search_steps. An impact is declared where g >= -delta with g' > 0, then
polished by one Newton step limited to sqrt(2 delta / M).

Tables that offer a Hessian add a third-order certificate: g''(s) <= g''(t) + jump V^2 + K (s - t)
with K >= |d^3 g / dt^3| (kernels.curvature_step). Near a tangency g''(t) is strongly negative and that
step crosses it at once; each step taken is the larger of the two certified ones.
"""
from __future__ import annotations

import numpy as np

from .flow import PHI, THETA_DOT, PHI_DOT, flow, end_kinematics
from .kernels import (curvature_bounds, curvature_step, local_curvature, motion_bounds, newton_polish,
                      search_step)


def wall_value(s, sigma, params, table):
    """g = h(end) and g' = grad h(end) . end' for (6, N) states."""
    px, py, vx, vy = end_kinematics(s, sigma, params.R)
    hx, hy = table.grad(px, py)
    return table.h(px, py), hx * vx + hy * vy


def third_order(table):
    """(use it, third-derivative bound, Hessian jump) for tables that offer a Hessian."""
    if getattr(table, "hessian", None) is None:
        return False, 0.0, 0.0
    return True, float(getattr(table, "third_derivative_bound", 0.0)), float(getattr(table, "hessian_jump", 0.0))


def end_step(s, sigma, acc1, acc2, params, table, M, K, V2, delta, third, jump, rem):
    """(g, g', certified step) of one end for (6, N) states; rem: time left to the horizon (the
    curvature step is not needed where the plain step already reaches it)."""
    R = params.R
    px, py, vx, vy = end_kinematics(s, sigma, R)
    hx, hy = table.grad(px, py)
    g = table.h(px, py)
    gd = hx * vx + hy * vy
    step = search_step(g, gd, M, delta)
    if third:
        # moving away, or near a tangency (curvature dominates the approach speed): try the local curvature
        near = (step < rem) & ((gd <= 0.0) | (gd * gd < 2.0 * M * np.abs(g)))
        if near.any():
            i = np.flatnonzero(near)
            hxx, hxy, hyy = table.hessian(px[i], py[i])
            A = local_curvature(np.cos(s[PHI, i]), np.sin(s[PHI, i]), s[THETA_DOT, i], s[PHI_DOT, i], acc1[i],
                                acc2[i], sigma, R, hx[i], hy[i], hxx, hxy, hyy)
            step[i] = np.maximum(step[i], curvature_step(g[i], gd[i], A + jump * V2[i], M[i], K[i], delta))
    return g, gd, step


def first_impact(s0, acc1, acc2, horizon, params, table, settings):
    """First impact time in (0, horizon] for each column of s0 (flowing with constant accelerations).

    Returns (t_hit, end): t_hit is inf where no impact happens; end is +1 (front), -1 (back), 0.
    """
    n = s0.shape[1]
    t_hit = np.full(n, np.inf)
    end = np.zeros(n, dtype=np.int8)
    delta = settings.contact_tol * table.size
    W_end = s0[THETA_DOT] + acc2 * horizon
    w_end = s0[PHI_DOT] + acc1 * horizon
    third, D3, jump = third_order(table)
    act = np.arange(n)
    t = np.zeros(n)
    for _ in range(settings.max_search_steps):
        if act.size == 0:
            break
        ta = t[act]
        a1, a2 = acc1[act], acc2[act]
        st = flow(s0[:, act], a1, a2, ta, params.R) if ta.any() else s0[:, act]
        V2, A, J = motion_bounds(st[THETA_DOT], W_end[act], st[PHI_DOT], w_end[act], a1, a2, params.R)
        M, K = curvature_bounds(V2, A, J, table.grad_bound, table.hessian_bound, D3)
        rem = horizon[act] - ta
        gf, gdf, step_f = end_step(st, 1.0, a1, a2, params, table, M, K, V2, delta, third, jump, rem)
        gb, gdb, step_b = end_step(st, -1.0, a1, a2, params, table, M, K, V2, delta, third, jump, rem)
        hit_f = (gf >= -delta) & (gdf > 0.0)
        hit_b = (gb >= -delta) & (gdb > 0.0)
        hit = hit_f | hit_b
        if hit.any():
            front = hit_f & (~hit_b | (gdf >= gdb))
            g = np.where(front, gf, gb)[hit]
            gd = np.where(front, gdf, gdb)[hit]
            idx = act[hit]
            t_hit[idx] = np.minimum(np.maximum(ta[hit] + newton_polish(g, gd, M[hit], delta), 0.0), horizon[idx])
            end[idx] = np.where(front[hit], 1, -1)
        tau = np.minimum(step_f, step_b)
        t_next = ta + tau
        keep = ~hit & (t_next < horizon[act])
        t[act] = t_next
        act = act[keep]
    if act.size:  # step budget spent (pathological tangency): report the certified time reached
        t_hit[act] = t[act]
        end[act] = 2  # "no impact yet" marker, resumed by the caller from t_hit
    return t_hit, end
