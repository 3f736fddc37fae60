"""One penny in plain Python floats: the event loop of events.py / advance.py, step for step.

The single environment and simulate() advance one penny at a time, where numpy's per-call
overhead would dominate. These functions run the same kernels (kernels.py) in the same order
as the batched code, so a penny gives bitwise the same trajectory here and inside a batch
(tests/test_scalar_batch.py checks this). States are 6-tuples (x, y, theta, phi, theta_dot, phi_dot).
"""
from __future__ import annotations

import math

from .flow import MAX_PHASE_PER_PANEL, RULES, phase_sweep
from .events import third_order
from .kernels import (SCALAR, acceleration_bound, angles_at, curvature_bounds, curvature_step, displacement_closed,
                      end_point, law_update, local_curvature, motion_bounds, newton_polish, search_step,
                      time_resolution)


def displacement1(W, w, ph, acc1, acc2, t, R):
    """flow.displacement_quadrature for one penny, in the same order of operations."""
    sweep = phase_sweep(w, acc1, t, SCALAR)
    k = max(1, math.ceil(sweep / MAX_PHASE_PER_PANEL))
    per_panel = sweep / k
    _, nodes, weights = next((r for r in RULES[:-1] if per_panel <= r[0]), RULES[-1])
    width = t / k
    dx = dy = 0.0
    cos, sin = math.cos, math.sin
    for p in range(k):
        px = py = 0.0
        for u, wt in zip(nodes, weights):
            s = (p + u) * width
            phase = ph + s * (w + 0.5 * acc1 * s)
            amp = (W + acc2 * s) * wt
            px += amp * cos(phase)
            py += amp * sin(phase)
        dx += px * width
        dy += py * width
    return R * dx, R * dy


def flow1(s, acc1, acc2, t, R):
    """State after time t with constant angular accelerations (see flow.flow)."""
    x, y, th, ph, W, w = s
    th1, ph1, W1, w1 = angles_at(th, ph, W, w, acc1, acc2, t)
    if acc1 == 0.0:
        dx, dy = displacement_closed(W, w, ph, acc2, t, R, SCALAR)
    else:
        dx, dy = displacement1(W, w, ph, acc1, acc2, t, R)
    return (x + dx, y + dy, th1, ph1, W1, w1)


def wall1(s, sigma, R, table):
    """(h(end), d/dt h(end)) for end sigma."""
    px, py, vx, vy = end_point(s[0], s[1], s[3], s[4], s[5], sigma, R, SCALAR)
    hx, hy = table.grad(px, py)
    return table.h(px, py), hx * vx + hy * vy


def end_step1(s, sigma, acc1, acc2, R, table, M, K, V2, delta, third, jump):
    """(g, g', certified step) of one end (see events.end_step)."""
    px, py, vx, vy = end_point(s[0], s[1], s[3], s[4], s[5], sigma, R, SCALAR)
    hx, hy = table.grad(px, py)
    g = table.h(px, py)
    gd = hx * vx + hy * vy
    step = search_step(g, gd, M, delta, SCALAR)
    if third and (gd <= 0.0 or gd * gd < 2.0 * M * abs(g)):
        hxx, hxy, hyy = table.hessian(px, py)
        A = local_curvature(s[3], s[4], s[5], acc1, acc2, sigma, R, hx, hy, hxx, hxy, hyy, SCALAR)
        step = max(step, curvature_step(g, gd, A + jump * V2, M, K, delta, SCALAR))
    return g, gd, step


def first_impact1(s0, acc1, acc2, horizon, params, table, settings):
    """(t_hit, end) as events.first_impact: end 0 = none (t_hit inf), 2 = step budget spent."""
    R = params.R
    delta = settings.contact_tol * table.size
    W_end = s0[4] + acc2 * horizon
    w_end = s0[5] + acc1 * horizon
    G, L = table.grad_bound, table.hessian_bound
    third, D3, jump = third_order(table)
    t = 0.0
    for _ in range(settings.max_search_steps):
        st = flow1(s0, acc1, acc2, t, R) if t != 0.0 else s0
        V2, A, J = motion_bounds(st[4], W_end, st[5], w_end, acc1, acc2, R, SCALAR)
        M, K = curvature_bounds(V2, A, J, G, L, D3, SCALAR)
        gf, gdf, step_f = end_step1(st, 1.0, acc1, acc2, R, table, M, K, V2, delta, third, jump)
        gb, gdb, step_b = end_step1(st, -1.0, acc1, acc2, R, table, M, K, V2, delta, third, jump)
        hit_f = gf >= -delta and gdf > 0.0
        hit_b = gb >= -delta and gdb > 0.0
        if hit_f or hit_b:
            front = hit_f and (not hit_b or gdf >= gdb)
            g, gd = (gf, gdf) if front else (gb, gdb)
            return min(max(t + newton_polish(g, gd, M, delta, SCALAR), 0.0), horizon), (1 if front else -1)
        t = t + min(step_f, step_b)
        if not t < horizon:
            return math.inf, 0
    return t, 2


def relocate1(s, R, table):
    """Move the contact point so that neither end is outside the wall (round-off repairs)."""
    x, y = s[0], s[1]
    for sigma in (1.0, -1.0):
        px, py, _, _ = end_point(x, y, s[3], s[4], s[5], sigma, R, SCALAR)
        g = table.h(px, py)
        if g > 0.0:
            hx, hy = table.grad(px, py)
            k = g / (hx * hx + hy * hy)
            x -= k * hx
            y -= k * hy
    return (x, y) + tuple(s[2:])


def law1(s, sigma, params, table, law):
    """Post-impact state of end sigma (see laws.apply_law)."""
    R = params.R
    px, py, _, _ = end_point(s[0], s[1], s[3], s[4], s[5], sigma, R, SCALAR)
    hx, hy = table.grad(px, py)
    c, sn = math.cos(s[3]), math.sin(s[3])
    a = R * (hx * c + hy * sn)
    b = sigma * R * (hy * c - hx * sn)
    W, w = law_update(s[4], s[5], a, b, hx * hx + hy * hy, law.e, law.kind == "plastic",
                      params.rolling_inertia, params.J, params.m, SCALAR)
    return tuple(s[:4]) + (W, w)


def pushes_out1(s, acc1, acc2, R, table, delta):
    """At rest, would the controls drive an end that touches the wall outward?"""
    c, sn = math.cos(s[3]), math.sin(s[3])
    for sigma in (1.0, -1.0):
        px, py, _, _ = end_point(s[0], s[1], s[3], s[4], s[5], sigma, R, SCALAR)
        hx, hy = table.grad(px, py)
        ax = R * (acc2 * c - sigma * acc1 * sn)
        ay = R * (acc2 * sn + sigma * acc1 * c)
        if table.h(px, py) >= -delta and hx * ax + hy * ay > 0.0:
            return True
    return False


def advance1(s, acc1, acc2, dt, params, table, law, settings, stop_after=None):
    """One penny over one control interval (see advance.advance).

    Returns (state, impacts, rests, elapsed): impacts is a list of (time, end, post_state),
    rests a list of (time, pinned)."""
    R = params.R
    if table is None:
        return flow1(s, acc1, acc2, dt, R), [], [], dt
    impacts, rests = [], []
    if not dt > 0.0:
        return s, impacts, rests, 0.0
    elapsed = 0.0
    n_events = 0
    streak = 0
    delta = settings.contact_tol * table.size
    while True:
        rem = dt - elapsed
        t_hit, end = first_impact1(s, acc1, acc2, rem, params, table, settings)
        if end == 0:
            return flow1(s, acc1, acc2, rem, R), impacts, rests, dt
        pre = relocate1(flow1(s, acc1, acc2, t_hit, R), R, table)
        if end == 2 or wall1(pre, float(end), R, table)[1] <= 0.0:
            # search budget spent on a tangency, or a grazing touch that turned inward: go on from there
            s = pre
            elapsed += t_hit
            continue
        post = law1(pre, float(end), params, table, law)
        elapsed += t_hit
        t_impact = elapsed
        n_events += 1
        left = dt - elapsed
        M = acceleration_bound(pre[4], pre[4] + acc2 * left, pre[5], pre[5] + acc1 * left, acc1, acc2, R,
                               table.grad_bound, table.hessian_bound, SCALAR)
        window = max(settings.zeno_window, 8.0 * time_resolution(delta, M, SCALAR))
        streak = streak + 1 if t_hit < window else 0
        done = False
        if streak >= settings.zeno_impacts or n_events >= settings.max_events_per_interval:
            post = tuple(post[:4]) + (0.0, 0.0)
            streak = 0
            pinned = pushes_out1(post, acc1, acc2, R, table, 64 * delta)
            rests.append((t_impact, pinned))
            if pinned:
                done = True
                elapsed = dt
        impacts.append((t_impact, end, post))
        if stop_after is not None and n_events >= stop_after:
            done = True
        s = post
        if done:
            return s, impacts, rests, elapsed
