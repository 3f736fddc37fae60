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
"""
from __future__ import annotations

import numpy as np

from .flow import THETA_DOT, PHI_DOT, flow, end_kinematics
from .kernels import acceleration_bound, newton_polish, search_step, safe_step  # noqa: F401


def wall_value(s, sigma, params, table):
    """g = h(end) and g' = grad h(end) . end' for (6, N) states."""
    px, py, vx, vy = end_kinematics(s, sigma, params.R)
    hx, hy = table.grad(px, py)
    return table.h(px, py), hx * vx + hy * vy


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
    act = np.arange(n)
    t = np.zeros(n)
    for _ in range(settings.max_search_steps):
        if act.size == 0:
            break
        ta = t[act]
        st = flow(s0[:, act], acc1[act], acc2[act], ta, params.R) if ta.any() else s0[:, act]
        gf, gdf = wall_value(st, 1.0, params, table)
        gb, gdb = wall_value(st, -1.0, params, table)
        hit_f = (gf >= -delta) & (gdf > 0.0)
        hit_b = (gb >= -delta) & (gdb > 0.0)
        hit = hit_f | hit_b
        M = acceleration_bound(st[THETA_DOT], W_end[act], st[PHI_DOT], w_end[act], acc1[act], acc2[act],
                               params.R, table.grad_bound, table.hessian_bound)
        if hit.any():
            front = hit_f & (~hit_b | (gdf >= gdb))
            g = np.where(front, gf, gb)[hit]
            gd = np.where(front, gdf, gdb)[hit]
            idx = act[hit]
            t_hit[idx] = np.minimum(np.maximum(ta[hit] + newton_polish(g, gd, M[hit], delta), 0.0), horizon[idx])
            end[idx] = np.where(front[hit], 1, -1)
        tau = np.minimum(search_step(gf, gdf, M, delta), search_step(gb, gdb, M, delta))
        t_next = ta + tau
        keep = ~hit & (t_next < horizon[act])
        t[act] = t_next
        act = act[keep]
    if act.size:  # step budget spent (pathological tangency): report the certified time reached
        t_hit[act] = t[act]
        end[act] = 2  # "no impact yet" marker, resumed by the caller from t_hit
    return t_hit, end
