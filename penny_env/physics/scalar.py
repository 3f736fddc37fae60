"""One penny in plain floats: the event loop of events.py / advance.py, step for step.

The single environment and simulate() advance one penny at a time, where numpy's per-call
overhead would dominate. These functions run the same kernels (kernels.py) in the same order
as the batched code, so a penny gives bitwise the same trajectory here and inside a batch
(tests/test_scalar_batch.py checks this). States are 6-tuples (x, y, theta, phi, theta_dot, phi_dot).

The code is also numba-compatible: everything a penny needs travels in a :class:`Model` of plain
numbers (the table's kind and constants included), so physics/compiled.py compiles these very
functions for the vector environment. In plain Python they run as they are.
"""
from __future__ import annotations

import math
import weakref
from functools import lru_cache
from typing import NamedTuple

from .flow import (CIS_MEDIUM, CIS_SMALL, MAX_PHASE_PER_PANEL, RULE_CIS, RULE_COUNTS, RULE_LIMITS, RULE_NODES,
                   RULE_WEIGHTS, phase_sweep)
from .kernels import (SCALAR, acceleration_bound, angles_at, cis_medium, cis_small, curvature_bounds, curvature_step, displacement_closed,
                      end_point, law_update, local_curvature, motion_bounds, newton_polish, search_step,
                      time_resolution)


ELLIPSE, STADIUM, OTHER = 0, 1, 2  # Model.kind: the table's formulas


class Model(NamedTuple):
    """Everything the scalar event loop needs, as plain numbers (see :func:`scalar_model`)."""

    R: float
    m: float
    Itot: float
    J: float
    G: float             # table.grad_bound
    L: float             # table.hessian_bound
    third: bool          # the table offers a Hessian: third-order certificate
    D3: float            # third_derivative_bound
    jump: float          # hessian_jump
    delta: float         # contact tolerance [m]
    e: float             # restitution coefficient
    plastic: bool
    max_search_steps: int
    zeno_impacts: int
    zeno_window: float
    max_events: int
    kind: int            # ELLIPSE (and Circle), STADIUM or OTHER (any table, through its methods)
    other: int           # OTHER: the key of the table in _OTHER_TABLES
    t0: float            # t0..t4: the built-in table's constants
    t1: float
    t2: float
    t3: float
    t4: float


# -- the tables' formulas: wall_terms(m, x, y) -> (h, hx, hy), wall_hess(m, x, y) -> (hxx, hxy, hyy) ------
# The built-in tables' are inlined (the same expressions as their methods, so the same values);
# any other table is called through its methods (plain Python only, see physics/compiled.py).
_OTHER_TABLES = weakref.WeakValueDictionary()


def ellipse_terms(m, x, y):
    ia2, ib2, hc = m.t0, m.t1, m.t2
    c2 = 2.0 * hc
    return (x * x * ia2 + y * y * ib2 - 1.0) * hc, c2 * x * ia2, c2 * y * ib2


def ellipse_hess(m, x, y):
    c2 = 2.0 * m.t2
    return c2 * m.t0, 0.0, c2 * m.t1


def stadium_terms(m, x, y):
    half, r, r2, two_r = m.t0, m.t1, m.t2, m.t3
    dx = x - min(max(x, -half), half)
    return (dx * dx + y * y - r2) / two_r, dx / r, y / r


def stadium_hess(m, x, y):
    half, inv = m.t0, m.t4
    return (inv if x - min(max(x, -half), half) != 0.0 else 0.0), 0.0, inv


def other_terms(m, x, y):
    table = _OTHER_TABLES[m.other]
    hx, hy = table.grad(x, y)
    return table.h(x, y), hx, hy


def other_hess(m, x, y):
    return _OTHER_TABLES[m.other].hessian(x, y)


def wall_terms(m, x, y):
    if m.kind == ELLIPSE:
        return ellipse_terms(m, x, y)
    if m.kind == STADIUM:
        return stadium_terms(m, x, y)
    return other_terms(m, x, y)


def wall_hess(m, x, y):
    if m.kind == ELLIPSE:
        return ellipse_hess(m, x, y)
    if m.kind == STADIUM:
        return stadium_hess(m, x, y)
    return other_hess(m, x, y)


def table_constants(table):
    """(kind, constants t0..t4) of a table."""
    from .tables import Circle, Ellipse, Stadium

    if type(table) in (Ellipse, Circle):
        return ELLIPSE, (table._ia2, table._ib2, table._half_c, 0.0, 0.0)
    if type(table) is Stadium:
        r = table.radius
        return STADIUM, (table._half, r, r ** 2, 2.0 * r, 1.0 / r)
    return OTHER, (0.0,) * 5


def scalar_model(params, table, law, settings) -> Model:
    """The Model of the physics objects (table None: the open plane)."""
    try:
        return _cached_model(params, table, law, settings)
    except TypeError:  # an unhashable user table
        return _build_model(params, table, law, settings)


def _build_model(params, table, law, settings):
    from .events import third_order

    if table is None:
        kind, consts, G, L, third, D3, jump, delta = OTHER, (0.0,) * 5, 0.0, 0.0, False, 0.0, 0.0, 0.0
        other = 0
    else:
        kind, consts = table_constants(table)
        other = 0
        if kind == OTHER:
            other = id(table)
            _OTHER_TABLES[other] = table
        third, D3, jump = third_order(table)
        G, L, delta = float(table.grad_bound), float(table.hessian_bound), settings.contact_tol * table.size
    return Model(params.R, params.m, params.rolling_inertia, params.J, G, L, bool(third), D3, jump, delta,
                 float(law.e), law.kind == "plastic", int(settings.max_search_steps), int(settings.zeno_impacts),
                 float(settings.zeno_window), int(settings.max_events_per_interval), kind, other, *consts)


_cached_model = lru_cache(maxsize=64)(_build_model)


# -- flow ------------------------------------------------------------------------------------------
def displacement1(W, w, ph, acc1, acc2, t, R):
    """flow.displacement_quadrature for one penny, in the same order of operations."""
    sweep = phase_sweep(w, acc1, t, SCALAR)
    k = max(1, math.ceil(sweep / MAX_PHASE_PER_PANEL))
    per_panel = sweep / k
    rule = 0
    while rule < len(RULE_LIMITS) - 1 and per_panel > RULE_LIMITS[rule]:
        rule += 1
    nodes, weights, cis = RULE_NODES[rule], RULE_WEIGHTS[rule], RULE_CIS[rule]
    width = t / k
    dx = dy = 0.0
    for p in range(k):
        mid = (p + 0.5) * width
        phm = ph + mid * (w + 0.5 * acc1 * mid)
        wm = w + acc1 * mid
        Wm = W + acc2 * mid
        px = py = 0.0
        for j in range(RULE_COUNTS[rule]):
            u = nodes[j] * width
            psi = u * (wm + 0.5 * acc1 * u)
            amp = (Wm + acc2 * u) * weights[j]
            if cis == CIS_SMALL:
                cs, sn = cis_small(psi, SCALAR)
            elif cis == CIS_MEDIUM:
                cs, sn = cis_medium(psi, SCALAR)
            else:
                cs, sn = math.cos(psi), math.sin(psi)
            px += amp * cs
            py += amp * sn
        cm, sm = math.cos(phm), math.sin(phm)
        dx += (cm * px - sm * py) * width
        dy += (sm * px + cm * py) * width
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


# -- impact search -----------------------------------------------------------------------------------
def wall1(s, sigma, m):
    """(h(end), d/dt h(end)) for end sigma."""
    px, py, vx, vy = end_point(s[0], s[1], s[3], s[4], s[5], sigma, m.R, SCALAR)
    g, hx, hy = wall_terms(m, px, py)
    return g, hx * vx + hy * vy


def end_plain1(x, y, c, sn, W, w, sigma, m, M):
    """(g, g', plain certified step, end position, gradient) of one end (see events.end_step);
    c, sn = cos, sin of the heading."""
    R = m.R
    sR = sigma * R
    px, py = x + sR * c, y + sR * sn
    g, hx, hy = wall_terms(m, px, py)
    gd = hx * (R * W * c - sR * w * sn) + hy * (R * W * sn + sR * w * c)
    return g, gd, search_step(g, gd, M, m.delta, SCALAR), px, py, hx, hy


def with_curvature1(end, c, sn, W, w, sigma, acc1, acc2, m, M, K, V2, rem):
    """The end's step, improved by the curvature step where that can help (see events.end_step)."""
    g, gd, step, px, py, hx, hy = end
    if step < rem and (gd <= 0.0 or gd * gd < 2.0 * M * abs(g)):
        hxx, hxy, hyy = wall_hess(m, px, py)
        A = local_curvature(c, sn, W, w, acc1, acc2, sigma, m.R, hx, hy, hxx, hxy, hyy, SCALAR)
        step = max(step, curvature_step(g, gd, A + m.jump * V2, M, K, m.delta, SCALAR))
    return step


def certified_free1(s, acc1, acc2, dt, m):
    """The first step of the impact search from t = 0 finds no end touching the wall and certifies
    the whole period [0, dt], so the period has no impact and advance() returns flow(s, dt)."""
    return certified_free_trig(s, math.cos(s[3]), math.sin(s[3]), acc1, acc2, dt, m)


def certified_flow1(s, acc1, acc2, dt, m):
    """(True, flow1(s, dt)) when :func:`certified_free1` shows the period free of impacts, else
    (False, s): the single environment's common step in one call (compiled: one unboxing of m)."""
    if certified_free1(s, acc1, acc2, dt, m):
        return True, flow1(s, acc1, acc2, dt, m.R)
    return False, s


def certified_free_trig(s, c, sn, acc1, acc2, dt, m):
    """:func:`certified_free1` given c, sn = math.cos, math.sin of the heading s[3] (which the
    vector env keeps from the previous step for its observations)."""
    R = m.R
    delta = m.delta
    x, y, _, _, W, w = s
    M = acceleration_bound(W, W + acc2 * dt, w, w + acc1 * dt, acc1, acc2, R, m.G, m.L, SCALAR)
    RW = R * W
    tau = math.inf
    for sR in (R, -R):
        g, hx, hy = wall_terms(m, x + sR * c, y + sR * sn)
        sRw = sR * w
        gd = hx * (RW * c - sRw * sn) + hy * (RW * sn + sRw * c)
        if g >= -delta and gd > 0.0:
            return False
        tau = min(tau, search_step(g, gd, M, delta, SCALAR))
    return not tau < dt


def first_impact_m(s0, acc1, acc2, horizon, m):
    """(t_hit, end) as events.first_impact: end 0 = none (t_hit inf), 2 = step budget spent."""
    R = m.R
    delta = m.delta
    W_end = s0[4] + acc2 * horizon
    w_end = s0[5] + acc1 * horizon
    G, L, D3 = m.G, m.L, m.D3
    t = 0.0
    free = acc1 == 0.0 and acc2 == 0.0  # constant angular velocities: the bounds never change
    V2, A, J = motion_bounds(s0[4], W_end, s0[5], w_end, acc1, acc2, R, SCALAR)
    M, K = curvature_bounds(V2, A, J, G, L, D3, SCALAR)
    for _ in range(m.max_search_steps):
        x, y, _, ph, W, w = flow1(s0, acc1, acc2, t, R) if t != 0.0 else s0
        c, sn = math.cos(ph), math.sin(ph)
        if not free and t != 0.0:
            V2, A, J = motion_bounds(W, W_end, w, w_end, acc1, acc2, R, SCALAR)
            M, K = curvature_bounds(V2, A, J, G, L, D3, SCALAR)
        ef = end_plain1(x, y, c, sn, W, w, 1.0, m, M)
        eb = end_plain1(x, y, c, sn, W, w, -1.0, m, M)
        gf, gdf, step_f = ef[0], ef[1], ef[2]
        gb, gdb, step_b = eb[0], eb[1], eb[2]
        hit_f = gf >= -delta and gdf > 0.0
        hit_b = gb >= -delta and gdb > 0.0
        if hit_f or hit_b:
            front = hit_f and (not hit_b or gdf >= gdb)
            g, gd = (gf, gdf) if front else (gb, gdb)
            return min(max(t + newton_polish(g, gd, M, delta, SCALAR), 0.0), horizon), (1 if front else -1)
        if m.third:
            # tau = min over ends of max(plain, curvature step): the other end's curvature step only
            # matters when the first end's step exceeds the other's plain step (same tau as events.py)
            rem = horizon - t
            if step_f <= step_b:
                s1 = with_curvature1(ef, c, sn, W, w, 1.0, acc1, acc2, m, M, K, V2, rem)
                s2 = step_b
                if s1 > s2:
                    s2 = with_curvature1(eb, c, sn, W, w, -1.0, acc1, acc2, m, M, K, V2, rem)
            else:
                s1 = with_curvature1(eb, c, sn, W, w, -1.0, acc1, acc2, m, M, K, V2, rem)
                s2 = step_f
                if s1 > s2:
                    s2 = with_curvature1(ef, c, sn, W, w, 1.0, acc1, acc2, m, M, K, V2, rem)
            step_f, step_b = s1, s2
        t = t + min(step_f, step_b)
        if not t < horizon:
            return math.inf, 0
    return t, 2


# -- impacts -------------------------------------------------------------------------------------
def relocate1(s, m):
    """Move the contact point so that neither end is outside the wall (round-off repairs)."""
    x, y = s[0], s[1]
    for sigma in (1.0, -1.0):
        px, py, _, _ = end_point(x, y, s[3], s[4], s[5], sigma, m.R, SCALAR)
        g, hx, hy = wall_terms(m, px, py)
        if g > 0.0:
            k = g / (hx * hx + hy * hy)
            x -= k * hx
            y -= k * hy
    return (x, y, s[2], s[3], s[4], s[5])


def law1(s, sigma, m):
    """Post-impact state of end sigma (see laws.apply_law)."""
    R = m.R
    px, py, _, _ = end_point(s[0], s[1], s[3], s[4], s[5], sigma, R, SCALAR)
    _, hx, hy = wall_terms(m, px, py)
    c, sn = math.cos(s[3]), math.sin(s[3])
    a = R * (hx * c + hy * sn)
    b = sigma * R * (hy * c - hx * sn)
    W, w = law_update(s[4], s[5], a, b, hx * hx + hy * hy, m.e, m.plastic, m.Itot, m.J, m.m, SCALAR)
    return (s[0], s[1], s[2], s[3], W, w)


def pushes_out1(s, acc1, acc2, m, delta):
    """At rest, would the controls drive an end that touches the wall outward?"""
    R = m.R
    c, sn = math.cos(s[3]), math.sin(s[3])
    for sigma in (1.0, -1.0):
        px, py, _, _ = end_point(s[0], s[1], s[3], s[4], s[5], sigma, R, SCALAR)
        g, hx, hy = wall_terms(m, px, py)
        ax = R * (acc2 * c - sigma * acc1 * sn)
        ay = R * (acc2 * sn + sigma * acc1 * c)
        if g >= -delta and hx * ax + hy * ay > 0.0:
            return True
    return False


def advance_m(s, acc1, acc2, dt, m, stop_after):
    """One penny over one control interval (see advance.advance); stop_after <= 0: no limit.

    Returns (state, impacts, rests, elapsed): impacts is a list of (time, end, post_state),
    rests a list of (time, pinned). The call stops early, right after an impact, with elapsed < dt
    and the state reached (speeds untouched), after stop_after impacts or after m.max_events impacts
    (SolverSettings.max_events_per_interval: it bounds the work and the impact list of one call,
    never the physics); the caller resumes from there (:func:`advance_through_m`).

    Only an accumulation brings a penny to rest: m.zeno_impacts consecutive impacts each closer
    than the time-resolution window to the previous one, under a dissipative law. An elastic
    penny is never stopped (it keeps its energy; tables too narrow for the search to resolve its
    impacts are refused up front, validation.check_table)."""
    R = m.R
    impacts = [(0.0, 0, s)]  # typed by example (numba); removed below
    rests = [(0.0, False)]
    impacts.pop()
    rests.pop()
    if not dt > 0.0:
        return s, impacts, rests, 0.0
    elapsed = 0.0
    n_events = 0
    streak = 0
    delta = m.delta
    elastic = m.e == 1.0 and not m.plastic
    while True:
        rem = dt - elapsed
        t_hit, end = first_impact_m(s, acc1, acc2, rem, m)
        if end == 0:
            return flow1(s, acc1, acc2, rem, R), impacts, rests, dt
        pre = relocate1(flow1(s, acc1, acc2, t_hit, R), m)
        if end == 2 or wall1(pre, float(end), m)[1] <= 0.0:
            # search budget spent on a tangency, or a grazing touch that turned inward: go on from there
            s = pre
            elapsed += t_hit
            continue
        post = law1(pre, float(end), m)
        elapsed += t_hit
        t_impact = elapsed
        n_events += 1
        left = dt - elapsed
        M = acceleration_bound(pre[4], pre[4] + acc2 * left, pre[5], pre[5] + acc1 * left, acc1, acc2, R,
                               m.G, m.L, SCALAR)
        window = max(m.zeno_window, 8.0 * time_resolution(delta, M, SCALAR))
        streak = streak + 1 if t_hit < window else 0
        done = False
        if streak >= m.zeno_impacts and not elastic:
            post = (post[0], post[1], post[2], post[3], 0.0, 0.0)
            streak = 0
            pinned = pushes_out1(post, acc1, acc2, m, 64 * delta)
            rests.append((t_impact, pinned))
            if pinned:
                done = True
                elapsed = dt
        impacts.append((t_impact, end, post))
        if (stop_after > 0 and n_events >= stop_after) or n_events >= m.max_events:
            done = True
        s = post
        if done:
            return s, impacts, rests, elapsed


def advance_through_m(s, acc1, acc2, dt, m):
    """:func:`advance_m` over the whole interval: resumes after each call that the per-call event cap
    stopped early. Returns (state, impacts, rests, dt) with the times counted from the interval's start."""
    s, impacts, rests, elapsed = advance_m(s, acc1, acc2, dt, m, 0)
    while elapsed < dt:
        rem = dt - elapsed
        s, more, more_rests, step = advance_m(s, acc1, acc2, rem, m, 0)
        for k in range(len(more)):
            t_k, end_k, post_k = more[k]
            impacts.append((elapsed + t_k, end_k, post_k))
        for k in range(len(more_rests)):
            t_k, pinned_k = more_rests[k]
            rests.append((elapsed + t_k, pinned_k))
        if not step < rem:  # reached the interval's end
            break
        elapsed += step
    return s, impacts, rests, dt


# -- the physics-object API (simulate, tests, analysis) ------------------------------------------------
def advance1(s, acc1, acc2, dt, params, table, law, settings, stop_after=None):
    """One penny over one control interval (see advance.advance).

    Returns (state, impacts, rests, elapsed): impacts is a list of (time, end, post_state),
    rests a list of (time, pinned). Without stop_after the whole interval is run (elapsed = dt,
    resumed past the per-call event cap, :func:`advance_through_m`); with it the call stops right
    after stop_after impacts or at the cap (elapsed < dt), and the caller resumes."""
    if table is None:
        return flow1(s, acc1, acc2, dt, params.R), [], [], dt
    model = scalar_model(params, table, law, settings)
    if stop_after is None:
        return advance_through_m(tuple(s), acc1, acc2, dt, model)
    return advance_m(tuple(s), acc1, acc2, dt, model, int(stop_after))
