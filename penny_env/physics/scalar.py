"""The event loop of the penny, once: one penny in plain floats, numba-compatible.

States are 6-tuples (x, y, theta, phi, theta_dot, phi_dot). Everything a penny needs travels in a
:class:`Model` of plain numbers (the table's formula index and constants, the law's index and
coefficient included), so backends/physics.py compiles these very functions (and runs them in
parallel over the pennies of a batch, backends/pennies.py); in plain Python they run as they are,
the readable reference the tests compare the compiled loop with, bitwise.

Impact search (:func:`first_impact_search`). For an end p(t), g(t) = h(p(t)) is the wall function along
the flow. While the end is on the table, |p'| <= V and |p''| <= A (bounds from the linear-in-time
angular velocities), so g'' <= M = L V^2 + G A (L, G: the table's Hessian and gradient bounds).
From a time t the quadratic g(t) + g'(t) tau + M tau^2 / 2 bounds g from above, and it stays
<= delta up to its positive root tau* (delta = contact_tol * table size, a few ulps of the table).
Stepping by tau* therefore never passes over an impact deeper than delta, however grazing.
Shallower "impacts" are below the round-off of the positions themselves. Near a transversal
crossing the steps are Newton steps from below and converge quadratically; near a tangency they
shrink geometrically, so the step count stays small and is capped by settings.max_search_steps
(end 2: resumed by the caller from the certified time). An impact is declared where g >= -delta
with g' > 0, then polished by one Newton step limited to sqrt(2 delta / M). Tables that offer a
Hessian add a third-order certificate: g''(s) <= g''(t) + jump V^2 + K (s - t) with
K >= |d^3 g / dt^3| (kernels.curvature_step); near a tangency that step crosses it at once; each
step taken is the larger of the two certified ones.

Degenerate cases end in a defined state (:func:`advance_listing`; docs/physics.md):
* an end on the wall still moving outward after the law (plastic with I > m R^2): the normal
  velocity is removed (kernels.law_update);
* accumulation (Zeno), including both ends wedged against the wall: zeno_impacts consecutive
  impacts each within max(zeno_window, 8 sqrt(2 delta / M)) of the previous one, or
  max_events_per_interval impacts in one interval, bring the penny to rest (theta_dot = phi_dot
  = 0). If the controls then push an end that touches the wall outward, the penny stays pinned
  until the interval ends.
"""
from __future__ import annotations

import math
import weakref
from typing import NamedTuple

from .flows import (CIS_MEDIUM, CIS_SMALL, MAX_PHASE_PER_PANEL, RULE_CIS, RULE_COUNTS, RULE_LIMITS, RULE_NODES,
                   RULE_WEIGHTS, phase_sweep)
from .faults import FAULT_ENERGY, FAULT_NONE, FAULT_NONFINITE, FAULT_OUTSIDE, FAULT_OUTWARD, OUTSIDE_TOL, fault_error
from .law_checks import ENERGY_RTOL, OUTWARD_RTOL
from .laws import BUILTIN_LAW_UPDATES, COMPILED_LAWS, PLASTIC_LAW, law_index
from .tables.base import COMPILED_FORMULAS, N_CONSTANTS, compiled_kind
from .kernels import (SCALAR, acceleration_bound, angles_at, cis_medium, cis_small, curvature_bounds, curvature_step,
                      displacement_closed, end_point, law_update, local_curvature, motion_bounds, newton_polish,
                      search_step, time_resolution)


OTHER = -1  # Model.kind of a table called through its methods (plain Python only); else an index
# into tables.COMPILED_FORMULAS (the registered tables' compiled formulas)


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
    outside_tol: float   # an end found farther outside the wall at an impact: FAULT_OUTSIDE [m]
    e: float             # the law's coefficient (restitution e)
    law: int             # index of the law's update function in laws.COMPILED_LAWS
    elastic: bool        # the law keeps the kinetic energy: an accumulation never brings the penny to rest
    max_search_steps: int
    zeno_impacts: int
    zeno_window: float
    max_events: int
    kind: int            # index of the table's formulas in tables.COMPILED_FORMULAS, or OTHER
    other: int           # OTHER: the key of the table in _OTHER_TABLES
    table_c0: float      # table_c0..table_c4: the table's constants (Table.constants(), zero-padded)
    table_c1: float
    table_c2: float
    table_c3: float
    table_c4: float


def table_constants_of(m):
    """The table's constants of Model m as the tuple its formulas take."""
    return (m.table_c0, m.table_c1, m.table_c2, m.table_c3, m.table_c4)


# -- the tables' formulas: wall_terms(m, x, y) -> (h, hx, hy), wall_hess(m, x, y) -> (hxx, hxy, hyy) ------
# A registered table's static terms/hess (one module per shape, physics/tables/) receive its constants;
# any other table is called through its methods (plain Python only). Compiled, these two functions
# are replaced by a dispatch over the registered kinds generated by backends/physics.py.
_OTHER_TABLES = weakref.WeakValueDictionary()


def other_terms(m, x, y):
    table = _OTHER_TABLES[m.other]
    hx, hy = table.grad(x, y)
    return table.h(x, y), hx, hy


def other_hess(m, x, y):
    return _OTHER_TABLES[m.other].hessian(x, y)


def wall_terms(m, x, y):
    if m.kind == OTHER:
        return other_terms(m, x, y)
    return COMPILED_FORMULAS[m.kind][0](table_constants_of(m), x, y)


def wall_hess(m, x, y):
    if m.kind == OTHER:
        return other_hess(m, x, y)
    return COMPILED_FORMULAS[m.kind][1](table_constants_of(m), x, y)


RAY_BISECTIONS = 64  # halvings of the bracket [0, 2 size] of wall_distance's bisection


def wall_distance(m, c, s):
    """Distance from the table's centre to its wall along the unit direction (c, s): the table's ``ray``
    formula, else a bisection on h along the ray (Table.wall_distance's generic version, for one ray)."""
    if m.kind == OTHER:
        return float(_OTHER_TABLES[m.other].wall_distance(c, s))
    ray = COMPILED_FORMULAS[m.kind][2]
    if ray is not None:
        return ray(table_constants_of(m), c, s)
    return wall_distance_bisection(m, c, s)


def wall_distance_bisection(m, c, s):
    """wall_distance by bisection on h (the table's terms): the bracket [0, 2 size] (2 size exceeds the
    extent's half-diagonal) halved RAY_BISECTIONS times; size = delta / contact_tol is not in the Model,
    so the bracket grows from 1 m until its end is outside."""
    lo, hi = 0.0, 1.0
    while wall_terms(m, hi * c, hi * s)[0] < 0.0:
        lo, hi = hi, 2.0 * hi
    for _ in range(RAY_BISECTIONS):
        mid = 0.5 * (lo + hi)
        if wall_terms(m, mid * c, mid * s)[0] < 0.0:
            lo = mid
        else:
            hi = mid
    return lo


def law_terms(m, W, w, a, b, grad2):
    """The law's post-impact (theta_dot, phi_dot) for the normal form n = a W + b w (laws.py): penny_env's own
    laws are the formula kernels.law_update itself (restitution, or the plastic law), a user's law its function.
    (The compiled builds replace this by a generated dispatch: backends/physics.py.)"""
    if m.law < len(BUILTIN_LAW_UPDATES):
        return law_update(W, w, a, b, grad2, m.e, m.law == PLASTIC_LAW, m.Itot, m.J, m.m, SCALAR)
    return COMPILED_LAWS[m.law](W, w, a, b, grad2, m.e, m.Itot, m.J, m.m)


def third_order(table):
    """(use it, third-derivative bound, Hessian jump) for tables that offer a Hessian."""
    if getattr(table, "hessian", None) is None:
        return False, 0.0, 0.0
    return True, float(getattr(table, "third_derivative_bound", 0.0)), float(getattr(table, "hessian_jump", 0.0))


def table_constants(table):
    """(kind, constants for table_c0..table_c4) of a table: OTHER for a table without registered compiled formulas."""
    kind = compiled_kind(type(table))
    if kind == OTHER:
        return OTHER, (0.0,) * N_CONSTANTS
    c = tuple(float(v) for v in table.constants())
    if len(c) > N_CONSTANTS:
        raise ValueError(f"table {type(table).__name__}: constants() gives {len(c)} numbers, at most {N_CONSTANTS}")
    return kind, c + (0.0,) * (N_CONSTANTS - len(c))


SEARCH_SPEED2_FLOOR = 1e-290  # [m^2/s^2] below this squared end speed the certificate's squares leave float64's
# normal range (a plastic penny wedged in a table 1.0001 R wide decays to 1e-159 rad/s): the search's penetrations
# are then underflow, not false bounds, and the guard does not judge them (relocate_inside repairs them, as before)


def scalar_model(params, table, law, settings) -> Model:
    """The Model of the physics objects (table None: the open plane). Built anew on every call (a few
    microseconds): a cache keyed on the objects would hand one user table, or a law re-registered under
    the same name, another's constants."""
    if table is None:
        kind, consts, G, L, third, D3, jump, delta = OTHER, (0.0,) * N_CONSTANTS, 0.0, 0.0, False, 0.0, 0.0, 0.0
        other = 0
        outside = math.inf
    else:
        kind, consts = table_constants(table)
        other = 0
        if kind == OTHER:
            other = id(table)
            _OTHER_TABLES[other] = table
        third, D3, jump = third_order(table)
        G, L, delta = float(table.grad_bound), float(table.hessian_bound), settings.contact_tol * table.size
        outside = max(OUTSIDE_TOL * table.size, 64.0 * delta)
    return Model(params.R, params.m, params.rolling_inertia, params.J, G, L, bool(third), D3, jump, delta, outside,
                 float(law.e), law_index(law.update), law.conserves_energy, int(settings.max_search_steps),
                 int(settings.zeno_impacts),
                 float(settings.zeno_window), int(settings.max_events_per_interval), kind, other, *consts)



# -- flow ------------------------------------------------------------------------------------------
def displacement_penny(W, w, ph, acc1, acc2, t, R):
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


def flow_penny(s, acc1, acc2, t, R):
    """State after time t with constant angular accelerations (see flow.flow)."""
    x, y, th, ph, W, w = s
    th1, ph1, W1, w1 = angles_at(th, ph, W, w, acc1, acc2, t)
    if acc1 == 0.0:
        dx, dy = displacement_closed(W, w, ph, acc2, t, R, SCALAR)
    else:
        dx, dy = displacement_penny(W, w, ph, acc1, acc2, t, R)
    return (x + dx, y + dy, th1, ph1, W1, w1)


# -- impact search -----------------------------------------------------------------------------------
def end_wall_gap(s, sigma, m):
    """(h(end), d/dt h(end)) for end sigma."""
    px, py, vx, vy = end_point(s[0], s[1], s[3], s[4], s[5], sigma, m.R, SCALAR)
    g, hx, hy = wall_terms(m, px, py)
    return g, hx * vx + hy * vy


def end_search_step(x, y, c, sn, W, w, sigma, m, M):
    """(g, g', plain certified step, end position, gradient) of one end;
    c, sn = cos, sin of the heading."""
    R = m.R
    sR = sigma * R
    px, py = x + sR * c, y + sR * sn
    g, hx, hy = wall_terms(m, px, py)
    gd = hx * (R * W * c - sR * w * sn) + hy * (R * W * sn + sR * w * c)
    return g, gd, search_step(g, gd, M, m.delta, SCALAR), px, py, hx, hy


def end_search_step_curved(end, c, sn, W, w, sigma, acc1, acc2, m, M, K, V2, rem):
    """The end's step, improved by the curvature step where that can help: moving away, or near a
    tangency (curvature dominates the approach speed)."""
    g, gd, step, px, py, hx, hy = end
    if step < rem and (gd <= 0.0 or gd * gd < 2.0 * M * abs(g)):
        hxx, hxy, hyy = wall_hess(m, px, py)
        A = local_curvature(c, sn, W, w, acc1, acc2, sigma, m.R, hx, hy, hxx, hxy, hyy, SCALAR)
        step = max(step, curvature_step(g, gd, A + m.jump * V2, M, K, m.delta, SCALAR))
    return step


def period_is_free(s, c, sn, acc1, acc2, dt, m):
    """The certificate of an impact-free period: the first step of the impact search (:func:`first_impact_search`)
    from t = 0 finds no end touching the wall and certifies the whole period [0, dt], so the period has no impact
    and its motion is one flow. It is that first step itself, curvature refinement included (the same bounds and
    formulas, so the same decision): where it fails the search does not finish at its first step either, and
    where it passes the event loop would have found no impact and flowed over [0, dt] (the same flow, bitwise).
    The refinement (a Hessian at the end, :func:`end_search_step_curved`) is evaluated only for an end whose
    plain step falls short of dt, and only where the search refines it. c, sn = math.cos, math.sin of the
    heading s[3] (which the envs keep from the previous step)."""
    R = m.R
    delta = m.delta
    x, y, _, _, W, w = s
    V2, A, J = motion_bounds(W, W + acc2 * dt, w, w + acc1 * dt, acc1, acc2, R, SCALAR)
    M, K = curvature_bounds(V2, A, J, m.G, m.L, m.D3, SCALAR)
    ef = end_search_step(x, y, c, sn, W, w, 1.0, m, M)
    if ef[0] >= -delta and ef[1] > 0.0:
        return False
    eb = end_search_step(x, y, c, sn, W, w, -1.0, m, M)
    if eb[0] >= -delta and eb[1] > 0.0:
        return False
    # (each end's best step >= dt  <=>  the search's first step, min over ends of the best steps, reaches dt)
    free = not ef[2] < dt and not eb[2] < dt
    if not free and m.third:
        free = not (ef[2] < dt and end_search_step_curved(ef, c, sn, W, w, 1.0, acc1, acc2, m, M, K, V2, dt) < dt)
        if free:
            free = not (eb[2] < dt and end_search_step_curved(eb, c, sn, W, w, -1.0, acc1, acc2, m, M, K, V2, dt) < dt)
    return free


def first_impact_search(s0, acc1, acc2, horizon, m):
    """(t_hit, end) of the first impact within horizon (module docstring): end +1 front, -1 back,
    0 none (t_hit inf), 2 step budget spent (t_hit: the time certified free so far)."""
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
        x, y, _, ph, W, w = flow_penny(s0, acc1, acc2, t, R) if t != 0.0 else s0
        c, sn = math.cos(ph), math.sin(ph)
        if not free and t != 0.0:
            V2, A, J = motion_bounds(W, W_end, w, w_end, acc1, acc2, R, SCALAR)
            M, K = curvature_bounds(V2, A, J, G, L, D3, SCALAR)
        ef = end_search_step(x, y, c, sn, W, w, 1.0, m, M)
        eb = end_search_step(x, y, c, sn, W, w, -1.0, m, M)
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
            # matters when the first end's step exceeds the other's plain step (the same tau as taking both ends' best steps)
            rem = horizon - t
            if step_f <= step_b:
                s1 = end_search_step_curved(ef, c, sn, W, w, 1.0, acc1, acc2, m, M, K, V2, rem)
                s2 = step_b
                if s1 > s2:
                    s2 = end_search_step_curved(eb, c, sn, W, w, -1.0, acc1, acc2, m, M, K, V2, rem)
            else:
                s1 = end_search_step_curved(eb, c, sn, W, w, -1.0, acc1, acc2, m, M, K, V2, rem)
                s2 = step_f
                if s1 > s2:
                    s2 = end_search_step_curved(ef, c, sn, W, w, 1.0, acc1, acc2, m, M, K, V2, rem)
            step_f, step_b = s1, s2
        t = t + min(step_f, step_b)
        if not t < horizon:
            return math.inf, 0
    return t, 2


def first_impact_resumed(s0, acc1, acc2, horizon, m, rounds):
    """(t_hit, end) as first_impact_search, resumed from the certified time (at most ``rounds`` times) when
    the search spends its step budget: end +1 front, -1 back, 0 none (t_hit inf, also when the budget
    of every round is spent)."""
    start = 0.0
    t, end = first_impact_search(s0, acc1, acc2, horizon, m)
    for _ in range(rounds):
        if end != 2:
            break
        start += t
        t, end = first_impact_search(flow_penny(s0, acc1, acc2, start, m.R), acc1, acc2, horizon - start, m)
    if end == 0 or end == 2:
        return math.inf, 0
    return start + t, end


# -- impacts -------------------------------------------------------------------------------------
def relocate_inside(s, m):
    """Move the contact point so that neither end is outside the wall (round-off repairs)."""
    return relocate_measured(s, m)[0]


def relocate_measured(s, m):
    """(relocate_inside's state, the larger wall function h of the two ends of s itself): h > 0 is how far outside
    the wall an end was found, which the run-time guard compares with m.outside_tol. (The back end is
    measured before the front end's repair moves it: in a table barely wider than the penny that repair
    pushes the other end out by more than the search ever lets an end in.)"""
    x, y = s[0], s[1]
    depth = -math.inf
    for sigma in (1.0, -1.0):
        px, py, _, _ = end_point(x, y, s[3], s[4], s[5], sigma, m.R, SCALAR)
        g, hx, hy = wall_terms(m, px, py)
        if x == s[0] and y == s[1]:
            depth = max(depth, g)
        else:  # (moved by the front end's repair: the back end of s itself)
            qx, qy, _, _ = end_point(s[0], s[1], s[3], s[4], s[5], sigma, m.R, SCALAR)
            depth = max(depth, wall_terms(m, qx, qy)[0])
        if g > 0.0:
            k = g / (hx * hx + hy * hy)
            x -= k * hx
            y -= k * hy
    return (x, y, s[2], s[3], s[4], s[5]), depth


# -- the run-time guard: faults the event loop records (ImpactBuffers.fault) rather than raising in compiled code


def law_fault(pre, post, n_scale, n_post, m):
    """FAULT_NONFINITE if the law gave a non-finite velocity, FAULT_ENERGY if it added kinetic energy beyond
    round-off (laws.ENERGY_RTOL; no law may add any), FAULT_OUTWARD if it left the end moving outward (its normal
    speed n_post beyond OUTWARD_RTOL of n_scale = |a W| + |b w| before: the search would find the same impact at
    once, the call spinning through its event cap), else FAULT_NONE. Only at impacts: the hot path of impact-free
    steps never pays for it."""
    W, w = post[4], post[5]
    if not (math.isfinite(W) and math.isfinite(w)):
        return FAULT_NONFINITE
    before = m.Itot * (pre[4] * pre[4]) + m.J * (pre[5] * pre[5])
    if m.Itot * (W * W) + m.J * (w * w) > before * (1.0 + ENERGY_RTOL):
        return FAULT_ENERGY
    if n_post > OUTWARD_RTOL * n_scale:
        return FAULT_OUTWARD
    return FAULT_NONE


def record_fault(buf, row, code):
    """Fault ``code`` of penny ``row`` into buf (its caller raises, or ends the episode: physics/faults.py)."""
    buf.fault[row] = code


def law_at_end(s, sigma, m):
    """(post-impact state of end sigma (see laws.apply_law), the scale |a W| + |b w| of the end's normal speed
    before, the end's normal speed a W + b w after)."""
    R = m.R
    px, py, _, _ = end_point(s[0], s[1], s[3], s[4], s[5], sigma, R, SCALAR)
    _, hx, hy = wall_terms(m, px, py)
    c, sn = math.cos(s[3]), math.sin(s[3])
    a = R * (hx * c + hy * sn)
    b = sigma * R * (hy * c - hx * sn)
    W, w = law_terms(m, s[4], s[5], a, b, hx * hx + hy * hy)
    # (the scale of n: |a W| + |b w| before, so that round-off of a near-grazing impact's cancellation is not a fault)
    return (s[0], s[1], s[2], s[3], W, w), abs(a * s[4]) + abs(b * s[5]), a * W + b * w


def controls_push_out(s, acc1, acc2, m, delta):
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


# -- the impact buffers: caller-owned, fixed capacity (no lists, so that GPU code can run the loop) ------
REST, PINNED = 1, 2  # ImpactBuffers.rest: the impact brought the penny to rest (PINNED: held by the controls)
NO_ARC = (0.0, 0.0, 2.0)   # record_impact's arc (cos b, sin b, cos half-width): no marked arc, nothing counted
WHOLE_WALL = 2.0, -2.0      # cos half-width values: none of the wall / all of it (p.b >= -2 |p| for any p)


class ImpactBuffers(NamedTuple):
    """Where the event loop writes the impacts of N pennies over one call: fixed capacity per penny, owned by
    the caller (:func:`impact_buffers`). Column i belongs to penny i; the slots are the first axis, so that
    neighbouring pennies (a GPU's neighbouring threads) write neighbouring addresses.

    count (N,) int64      the impacts of the call, all of them (also those past the capacity)
    time (K, N)           their times since the interval's start [s]
    end (K, N) int8       +1 front, -1 back
    post (Kp, 6, N)       the state right after each impact (Kp = K, or 0 where the caller does not read
                          them: the vector env's step)
    rest (Kp, N) int8     0, REST (the impact ended an accumulation: the penny is at rest) or PINNED (at
                          rest and held against the wall by the controls until the interval ends)
    arc_count (N,) int64  impacts whose contact point lies on the marked arc (record_impact's ``arc``)
    fault (N,) int8       FAULT_NONE, or the run-time guard's FAULT_* that stopped the penny's call at an
                          impact (a law or a table that breaks its contract). Written by advance_into
                          only (cleared when it starts), so that steps without an impact search never
                          touch it: read it after a call on fresh buffers (impact_buffers), or where
                          the call stopped early (elapsed < dt, as a fault stops it at its impact)

    The slots hold the first K impacts; the overflow flag of penny i is ``count[i] > K``
    (:func:`overflowed`): its caller reruns that penny with a larger buffer (the loop is a pure
    function of its inputs) or reports the count alone."""

    count: object
    time: object
    end: object
    post: object
    rest: object
    arc_count: object
    fault: object


def impact_buffers(n, capacity, empty=False, states=True) -> ImpactBuffers:
    """ImpactBuffers (numpy) for n pennies with ``capacity`` slots each, zeroed (empty: uninitialised, for a
    caller that clears what it reads); states False: no slots for the post-impact states and rest flags."""
    import numpy as np
    new = np.empty if empty else np.zeros
    kp = capacity if states else 0
    return ImpactBuffers(np.zeros(n, dtype=np.int64), new((capacity, n)), new((capacity, n), dtype=np.int8),
                         new((kp, 6, n)), new((kp, n), dtype=np.int8), np.zeros(n, dtype=np.int64),
                         np.zeros(n, dtype=np.int8))


def overflowed(buf):
    """The overflow flags of ImpactBuffers (N,): more impacts than the slots hold."""
    return buf.count > buf.time.shape[0]


def clear_row(buf, row):
    """Penny ``row``'s count and arc count set to 0 before a call writes its impacts. (By position: it is
    inlined into parallel loops, where numba loses writes made through a NamedTuple's attribute. The fault
    is cleared by advance_into, which only impact searches reach.)"""
    count = buf[0]
    arc_count = buf[5]
    count[row] = 0
    arc_count[row] = 0


def record_impact(buf, row, t, end, post, rest, arc, m):
    """Impact (t, end, post, rest flag) appended to penny ``row``'s slots of buf (stored while a slot is free,
    counted always). arc = (cos b, sin b, cos h): the impact counts in buf.arc_count when its contact
    point p (the end on the wall) satisfies p . (cos b, sin b) >= cos h |p| (cos h = 2: no arc marked)."""
    j = buf.count[row]
    if j < buf.time.shape[0]:
        buf.time[j, row] = t
        buf.end[j, row] = end
    if j < buf.post.shape[0]:
        buf.rest[j, row] = rest
        for r in range(6):
            buf.post[j, r, row] = post[r]
    buf.count[row] = j + 1
    if arc[2] < 1.5:
        sR = end * m.R
        px = post[0] + sR * math.cos(post[3])
        py = post[1] + sR * math.sin(post[3])
        if px * arc[0] + py * arc[1] >= arc[2] * math.sqrt(px * px + py * py):
            buf.arc_count[row] += 1


def advance_into(s, acc1, acc2, dt, m, stop_after, buf, row, base, arc):
    """One penny over one control interval with walls (module docstring); stop_after <= 0: no limit.
    The impacts go into row ``row`` of the ImpactBuffers buf (:func:`record_impact`), at times
    base + (time since this call's start); the row is not cleared.

    Returns (state, elapsed). The call stops early, right after an impact, with elapsed < dt and the
    state reached (speeds untouched), after stop_after impacts or after m.max_events impacts
    (SolverSettings.max_events_per_interval: it bounds the work of one call, never the physics); the
    caller resumes from there (:func:`advance_through_into`).

    The run-time guard (the impacts only) stops the call at an impact, recording a FAULT_* in buf.fault:
    FAULT_OUTSIDE with the state where an end was found more than m.outside_tol outside the wall (the
    table's bounds or formulas are false), FAULT_NONFINITE / FAULT_ENERGY / FAULT_OUTWARD with the state right
    before the impact whose law gave a non-finite velocity, added energy or left the end moving outward
    (:func:`law_fault`). elapsed is then the
    impact's time. The motion up to there is the one without the guard.

    Only an accumulation brings a penny to rest: m.zeno_impacts consecutive impacts each closer
    than the time-resolution window to the previous one, under a dissipative law. An elastic
    penny is never stopped (it keeps its energy; tables too narrow for the search to resolve its
    impacts are refused up front, validation.check_table)."""
    R = m.R
    record_fault(buf, row, FAULT_NONE)
    if not dt > 0.0:
        return s, 0.0
    elapsed = 0.0
    n_events = 0
    streak = 0
    delta = m.delta
    while True:
        rem = dt - elapsed
        t_hit, end = first_impact_search(s, acc1, acc2, rem, m)
        if end == 0:
            return flow_penny(s, acc1, acc2, rem, R), dt
        reached = flow_penny(s, acc1, acc2, t_hit, R)
        pre, depth = relocate_measured(reached, m)
        if depth > m.outside_tol and R * R * (pre[4] * pre[4] + pre[5] * pre[5]) > SEARCH_SPEED2_FLOOR:
            # the search stepped past the wall: the table's bounds or formulas are false
            record_fault(buf, row, FAULT_OUTSIDE)
            return reached, elapsed + t_hit
        if end == 2 or end_wall_gap(pre, float(end), m)[1] <= 0.0:
            # search budget spent on a tangency, or a grazing touch that turned inward: go on from there
            s = pre
            elapsed += t_hit
            continue
        post, n_scale, n_post = law_at_end(pre, float(end), m)
        fault = law_fault(pre, post, n_scale, n_post, m)
        if fault != FAULT_NONE:  # the law broke its contract: stop at the impact, before it (the caller reports it)
            record_fault(buf, row, fault)
            return pre, elapsed + t_hit
        elapsed += t_hit
        t_impact = elapsed
        n_events += 1
        left = dt - elapsed
        M = acceleration_bound(pre[4], pre[4] + acc2 * left, pre[5], pre[5] + acc1 * left, acc1, acc2, R,
                               m.G, m.L, SCALAR)
        window = max(m.zeno_window, 8.0 * time_resolution(delta, M, SCALAR))
        streak = streak + 1 if t_hit < window else 0
        done = False
        rest = 0
        if streak >= m.zeno_impacts and not m.elastic:
            post = (post[0], post[1], post[2], post[3], 0.0, 0.0)
            streak = 0
            rest = REST
            if controls_push_out(post, acc1, acc2, m, 64 * delta):
                rest = PINNED
                done = True
                elapsed = dt
        record_impact(buf, row, base + t_impact, end, post, rest, arc, m)
        if (stop_after > 0 and n_events >= stop_after) or n_events >= m.max_events:
            done = True
        s = post
        if done:
            return s, elapsed


def advance_through_into(s, acc1, acc2, dt, m, stop_after, buf, row, arc):
    """:func:`advance_into` over the whole interval: resumed after each call that the per-call event cap
    stopped early, so the motion is that of one uninterrupted call (the one resumption loop of the
    package). Returns (state, elapsed); the impacts go into row ``row`` of buf (not cleared), their
    times counted from the interval's start; elapsed is dt, or less when stop_after > 0 impacts were
    reached (the state is then the one right after that impact) or when the guard recorded a fault
    (buf.fault, :func:`advance_into`)."""
    first = buf.count[row]
    s, elapsed = advance_into(s, acc1, acc2, dt, m, stop_after, buf, row, 0.0, arc)
    while elapsed < dt and buf.fault[row] == FAULT_NONE and not (stop_after > 0 and buf.count[row] - first >= stop_after):
        rem = dt - elapsed
        left = stop_after - (buf.count[row] - first) if stop_after > 0 else 0
        s, step = advance_into(s, acc1, acc2, rem, m, left, buf, row, elapsed, arc)
        if not step < rem:  # reached the interval's end
            elapsed = dt
            break
        elapsed += step
    return s, elapsed


def run_interval(s, c_ph, s_ph, acc1, acc2, dt, m, plane, resume, stop_after, buf, row, arc):
    """The penny over one interval, the one driver of the event loop (the env step, simulate, the batch
    API and the renderer's impacts all come from it): row ``row`` of buf is cleared, then the interval
    is one flow where there is no wall (plane) or where the certificate (:func:`period_is_free`,
    given c_ph, s_ph = cos, sin of the heading s[3]) shows it free of impacts; otherwise the event loop
    runs, resumed after the per-call event cap when ``resume`` (:func:`advance_through_into`), else one
    call (:func:`advance_into`: the env step, which ends the episode where the cap stopped it).
    Returns (state, elapsed)."""
    clear_row(buf, row)
    # (one return, at the end: the CPU builder may paste this body into its caller, builder.inline_source)
    if plane or period_is_free(s, c_ph, s_ph, acc1, acc2, dt, m):
        out = flow_penny(s, acc1, acc2, dt, m.R), dt
    elif resume:
        out = advance_through_into(s, acc1, acc2, dt, m, stop_after, buf, row, arc)
    else:
        out = advance_into(s, acc1, acc2, dt, m, stop_after, buf, row, 0.0, arc)
    return out


# -- lists of impacts, in plain Python (tests, analysis): the loop above with a buffer ---------------------
def impacts_of(buf, row):
    """(impacts, rests) of penny ``row`` of buf as lists: (time, end, post_state) and (time, pinned)."""
    n = min(int(buf.count[row]), buf.time.shape[0])
    impacts = [(float(buf.time[j, row]), int(buf.end[j, row]), tuple(float(v) for v in buf.post[j, :, row]))
               for j in range(n)]
    rests = [(float(buf.time[j, row]), bool(buf.rest[j, row] == PINNED)) for j in range(n) if buf.rest[j, row]]
    return impacts, rests


def _with_lists(run, capacity, law=None, table=None):
    buf = impact_buffers(1, capacity)
    s, elapsed = run(buf)
    if buf.count[0] > capacity:  # the loop is pure: run it again with room for every impact
        buf = impact_buffers(1, int(buf.count[0]))
        s, elapsed = run(buf)
    if buf.fault[0] != FAULT_NONE:  # the run-time guard stopped the call (physics/faults.py)
        raise fault_error(buf.fault[0], law, table, where=f"t = {elapsed:.6g} s")
    impacts, rests = impacts_of(buf, 0)
    return s, impacts, rests, elapsed


def advance_listing(s, acc1, acc2, dt, m, stop_after):
    """:func:`advance_into` with lists (plain Python): (state, impacts, rests, elapsed), impacts a list of
    (time, end, post_state), rests of (time, pinned)."""
    return _with_lists(lambda buf: advance_into(s, acc1, acc2, dt, m, stop_after, buf, 0, 0.0, NO_ARC), 64)


def advance_through_listing(s, acc1, acc2, dt, m, stop_after=0):
    """:func:`advance_through_into` with lists (plain Python), as :func:`advance_listing`."""
    return _with_lists(lambda buf: advance_through_into(s, acc1, acc2, dt, m, stop_after, buf, 0, NO_ARC), 64)


# -- the physics-object API (simulate, tests, analysis) ------------------------------------------------
def advance_interval(s, acc1, acc2, dt, params, table, law, settings, stop_after=None):
    """One penny over one control interval, from the physics objects (builds the Model).

    Returns (state, impacts, rests, elapsed): impacts is a list of (time, end, post_state),
    rests a list of (time, pinned). Without stop_after the whole interval is run (elapsed = dt,
    resumed past the per-call event cap, :func:`advance_through_listing`); with it the call stops right
    after stop_after impacts or at the cap (elapsed < dt), and the caller resumes."""
    if table is None:
        return flow_penny(s, acc1, acc2, dt, params.R), [], [], dt
    model = scalar_model(params, table, law, settings)
    if stop_after is None:
        return advance_through_listing(tuple(s), acc1, acc2, dt, model)
    return advance_listing(tuple(s), acc1, acc2, dt, model, int(stop_after))
