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


def table_terms(table):
    """(x, y) -> (h, hx, hy) and (x, y) -> Hessian for floats: the built-in tables' formulas inlined
    (the same expressions as their methods, so the same values), any other table through its methods."""
    from .tables import Circle, Ellipse, Stadium

    if type(table) in (Ellipse, Circle):
        ia2, ib2, hc = table._ia2, table._ib2, table._half_c
        c2 = 2.0 * hc
        hess = (c2 * ia2, 0.0, c2 * ib2)

        def terms(x, y):
            return (x * x * ia2 + y * y * ib2 - 1.0) * hc, c2 * x * ia2, c2 * y * ib2
        return terms, lambda x, y: hess
    if type(table) is Stadium:
        half, r = table._half, table.radius
        r2, two_r, inv = r ** 2, 2.0 * r, 1.0 / r

        def terms(x, y):
            dx = x - min(max(x, -half), half)
            return (dx * dx + y * y - r2) / two_r, dx / r, y / r

        def hess(x, y):
            return (inv if x - min(max(x, -half), half) != 0.0 else 0.0), 0.0, inv
        return terms, hess

    def terms(x, y):
        hx, hy = table.grad(x, y)
        return table.h(x, y), hx, hy
    return terms, getattr(table, "hessian", None)


def end_plain1(x, y, c, sn, W, w, sigma, R, terms, M, delta):
    """(g, g', plain certified step, end position, gradient) of one end (see events.end_step);
    c, sn = cos, sin of the heading."""
    sR = sigma * R
    px, py = x + sR * c, y + sR * sn
    g, hx, hy = terms(px, py)
    gd = hx * (R * W * c - sR * w * sn) + hy * (R * W * sn + sR * w * c)
    return g, gd, search_step(g, gd, M, delta, SCALAR), px, py, hx, hy


def with_curvature1(end, c, sn, W, w, sigma, acc1, acc2, R, hess, M, K, V2, delta, jump, rem):
    """The end's step, improved by the curvature step where that can help (see events.end_step)."""
    g, gd, step, px, py, hx, hy = end
    if step < rem and (gd <= 0.0 or gd * gd < 2.0 * M * abs(g)):
        hxx, hxy, hyy = hess(px, py)
        A = local_curvature(c, sn, W, w, acc1, acc2, sigma, R, hx, hy, hxx, hxy, hyy, SCALAR)
        step = max(step, curvature_step(g, gd, A + jump * V2, M, K, delta, SCALAR))
    return step


def first_impact1(s0, acc1, acc2, horizon, params, table, settings):
    """(t_hit, end) as events.first_impact: end 0 = none (t_hit inf), 2 = step budget spent."""
    R = params.R
    delta = settings.contact_tol * table.size
    W_end = s0[4] + acc2 * horizon
    w_end = s0[5] + acc1 * horizon
    G, L = table.grad_bound, table.hessian_bound
    third, D3, jump = third_order(table)
    terms, hess = table_terms(table)
    t = 0.0
    free = acc1 == 0.0 and acc2 == 0.0  # constant angular velocities: the bounds never change
    if free:
        V2, A, J = motion_bounds(s0[4], W_end, s0[5], w_end, acc1, acc2, R, SCALAR)
        M, K = curvature_bounds(V2, A, J, G, L, D3, SCALAR)
    for _ in range(settings.max_search_steps):
        x, y, _, ph, W, w = flow1(s0, acc1, acc2, t, R) if t != 0.0 else s0
        c, sn = math.cos(ph), math.sin(ph)
        if not free:
            V2, A, J = motion_bounds(W, W_end, w, w_end, acc1, acc2, R, SCALAR)
            M, K = curvature_bounds(V2, A, J, G, L, D3, SCALAR)
        ef = end_plain1(x, y, c, sn, W, w, 1.0, R, terms, M, delta)
        eb = end_plain1(x, y, c, sn, W, w, -1.0, R, terms, M, delta)
        gf, gdf, step_f = ef[:3]
        gb, gdb, step_b = eb[:3]
        hit_f = gf >= -delta and gdf > 0.0
        hit_b = gb >= -delta and gdb > 0.0
        if hit_f or hit_b:
            front = hit_f and (not hit_b or gdf >= gdb)
            g, gd = (gf, gdf) if front else (gb, gdb)
            return min(max(t + newton_polish(g, gd, M, delta, SCALAR), 0.0), horizon), (1 if front else -1)
        if third:
            # tau = min over ends of max(plain, curvature step): the other end's curvature step only
            # matters when the first end's step exceeds the other's plain step (same tau as events.py)
            rem = horizon - t
            (e1, sg1), (e2, sg2) = ((ef, 1.0), (eb, -1.0)) if step_f <= step_b else ((eb, -1.0), (ef, 1.0))
            s1 = with_curvature1(e1, c, sn, W, w, sg1, acc1, acc2, R, hess, M, K, V2, delta, jump, rem)
            s2 = e2[2]
            if s1 > s2:
                s2 = with_curvature1(e2, c, sn, W, w, sg2, acc1, acc2, R, hess, M, K, V2, delta, jump, rem)
            step_f, step_b = s1, s2
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
