"""Certified search for the first impact of either end with the wall.

For an end p(t), g(t) = h(p(t)) is the wall function along the flow. While the end is on the
table, |p'| <= V and |p''| <= A (bounds from the linear-in-time angular velocities), so

    g'' <= M = L V^2 + G A          (L, G: the table's Hessian and gradient bounds).

From a time t with g(t) <= 0 the quadratic g(t) + g'(t) tau + M tau^2 / 2 bounds g from above,
and it stays <= 0 up to its positive root tau*. Stepping by tau* therefore never passes over an
impact, however grazing (an impact that enters and leaves between two samples of any grid is
still inside some step's bound). Near a transversal crossing the steps are Newton steps from
below and converge quadratically; near a tangency they shrink geometrically. An impact is
declared where g >= -delta with g' > 0 (delta = contact_tol * table size, a few ulps), then
polished by one Newton step. Steps are at least sqrt(2 delta / M), which bounds any
penetration by delta and the number of steps by settings.max_search_steps.
"""
from __future__ import annotations

import numpy as np

from .flow import THETA_DOT, PHI_DOT, flow, end_kinematics


def acceleration_bound(W_lo, W_hi, w_lo, w_hi, acc1, acc2, params, table):
    """M = L V^2 + G A over a time interval whose end-point angular speeds are given."""
    R = params.R
    Wm = np.maximum(np.abs(W_lo), np.abs(W_hi))
    wm = np.maximum(np.abs(w_lo), np.abs(w_hi))
    V2 = R * R * (Wm * Wm + wm * wm)
    A = R * np.hypot(np.abs(acc2) + wm * wm, np.abs(acc1) + wm * Wm)
    return table.hessian_bound * V2 + table.grad_bound * A


def safe_step(g, gd, M):
    """Largest tau with g + gd tau + M tau^2 / 2 <= 0 (g clamped to <= 0); inf if none bounds it."""
    gc = np.minimum(g, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        sq = np.sqrt(gd * gd - 2.0 * M * gc)
        tau = np.where(gd <= 0.0, (sq - gd) / M, -2.0 * gc / (gd + sq))
        # M == 0: no acceleration; only a linear approach can reach the wall
        lin = np.where(gd > 0.0, -gc / gd, np.inf)
    return np.where(M > 0.0, tau, lin)


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
        M = acceleration_bound(st[THETA_DOT], W_end[act], st[PHI_DOT], w_end[act], acc1[act], acc2[act], params, table)
        tau_min = np.sqrt(2.0 * delta / np.where(M > 0, M, np.inf))
        if hit.any():
            front = hit_f & (~hit_b | (gdf >= gdb))
            g = np.where(front, gf, gb)
            gd = np.where(front, gdf, gdb)
            with np.errstate(divide="ignore", invalid="ignore"):
                newton = np.where(g < 0.0, np.minimum(-g / gd, tau_min), 0.0)
            idx = act[hit]
            t_hit[idx] = np.minimum(ta[hit] + newton[hit], horizon[idx])
            end[idx] = np.where(front[hit], 1, -1)
        tau = np.maximum(np.minimum(safe_step(gf, gdf, M), safe_step(gb, gdb, M)), tau_min)
        t_next = ta + tau
        keep = ~hit & (t_next < horizon[act])
        t[act] = t_next
        act = act[keep]
    if act.size:  # step budget spent (pathological tangency): report the certified time reached
        t_hit[act] = t[act]
        end[act] = 2  # "no impact yet" marker, resumed by the caller from t_hit
    return t_hit, end
