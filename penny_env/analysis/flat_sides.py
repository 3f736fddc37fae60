"""Theorems T8 of docs/controllability_theory.md: steer only on a table with two parallel flat sides (the stadium, the
rounded rectangle), approximately, given enough time; and the aiming lemma T6.1 with turns up to 2 pi.

A pair of parallel flat sides (:class:`FlatPair`) in its coordinates s = p . t (along the sides) and y = p . n
(across): the sides lie on y = +-b, their flat pieces cover |s| <= X on both sides, and the rectangle |s| <= X,
|y| <= b lies in the table. Every segment s = c, |c| <= X, is a double normal (it meets the wall head-on at both
ends), and a line at incidence beta to n meets both sides at incidence beta (the sides are parallel).

* T6.1 (:func:`aim_through`): a steer-only penny rolling with phi_dot = 0 turns rest to rest by some delta with
  |delta| <= 2 pi after which it rolls straight through a given point (the degree argument needs more than a half
  turn: a point straight behind is aimed at only by turns beyond pi).
* T8.1 (:func:`ladder_park`, dissipative walls, 0 < e0 < 1): turn the heading along n; every impact is head-on and
  multiplies theta_dot by -e0; once slower than v_slow, creep to the mid-line and aim at the target (T6.1).
* T8.2 (:func:`stop_release_park`, elastic walls): roll at incidence beta* into a flat side (the impact turns all the
  rolling into spin), brake over the flat free angle pi - 2 beta*, and the other end, at incidence beta* again,
  releases all the spin into rolling along the mirror line; re-aim at the mid-line toward the centre; the last stop
  is braked so that the release leaves a chosen slow speed; then T6.1.

The constructions run a control row at a time on an :class:`Episode` (the probe's environment in the tests), with
piecewise-constant steering over rows of length dt, and use the table's simulator (penny_env.simulate) only to find
T6.1's turn and the row of a release. Their hypotheses ("room") are :func:`ladder_room` and :func:`zigzag_room`;
:func:`zigzag_constants` holds the table-level inequalities of T8.2.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..physics.laws import make_law
from ..physics.simulation import simulate
from .impact_geometry import full_conversion_angle
from .one_input import head_on_coefficient

FULL_TURN = 2.0 * math.pi      # T6.1's largest turn
ROOM_MARGIN = 1e-9             # [m] a room inequality counts when it holds by this much (far above float64 rounding)
AIM_SCAN = 129                 # turns scanned by aim_through over [-max_turn, max_turn]


# -- geometry -----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class FlatPair:
    """Two parallel flat pieces of a table's wall: on y = p . normal = +-b, covering |p . along| <= X on both sides,
    with the rectangle |s| <= X, |y| <= b inside the table."""

    normal: tuple
    along: tuple
    b: float
    X: float

    def coords(self, p):
        """(s, y) of the point p."""
        return (float(p[0] * self.along[0] + p[1] * self.along[1]),
                float(p[0] * self.normal[0] + p[1] * self.normal[1]))

    def vector(self, s, y):
        """The plane vector with coordinates (s, y)."""
        return np.array([s * self.along[0] + y * self.normal[0], s * self.along[1] + y * self.normal[1]])


def flat_pairs(table) -> tuple:
    """The pairs of parallel flat sides of a built-in table: the stadium's (its straight sides), the rounded
    rectangle's two (its long and its short sides); () for the other tables (the ellipse and the circle have none)."""
    from ..physics.tables.rounded_rectangle import RoundedRectangle
    from ..physics.tables.stadium import Stadium

    if isinstance(table, Stadium) and table.length > 0:
        return (FlatPair((0.0, 1.0), (1.0, 0.0), table.radius, 0.5 * table.length),)
    if isinstance(table, RoundedRectangle):
        ax, ay = 0.5 * table.width - table.radius, 0.5 * table.height - table.radius
        out = []
        if ax > 0:
            out.append(FlatPair((0.0, 1.0), (1.0, 0.0), 0.5 * table.height, ax))
        if ay > 0:
            out.append(FlatPair((1.0, 0.0), (0.0, 1.0), 0.5 * table.width, ay))
        return tuple(out)
    return ()


def clearance(table, p) -> float:
    """The distance from the point p to the wall (negative outside), exact for the stadium and the rounded rectangle:
    each is the set of points within `radius` of a convex set K (a segment, a rectangle), so the distance is
    radius - dist(p, K) outside K and radius + dist(p, boundary of K) inside it."""
    from ..physics.tables.rounded_rectangle import RoundedRectangle
    from ..physics.tables.stadium import Stadium

    x, y = float(p[0]), float(p[1])
    if isinstance(table, Stadium):
        half = 0.5 * table.length
        return table.radius - math.hypot(x - min(max(x, -half), half), y)
    if isinstance(table, RoundedRectangle):
        ax, ay = 0.5 * table.width - table.radius, 0.5 * table.height - table.radius
        dx, dy = abs(x) - ax, abs(y) - ay
        if dx <= 0 and dy <= 0:
            return table.radius + min(-dx, -dy)
        return table.radius - math.hypot(max(dx, 0.0), max(dy, 0.0))
    raise TypeError(f"clearance: a Stadium or a RoundedRectangle, got {type(table).__name__}")


# -- rows of steering ---------------------------------------------------------------------------------------
def wrap(angle, period=2.0 * math.pi) -> float:
    """The angle modulo period, in [-period / 2, period / 2)."""
    return float((angle + 0.5 * period) % period - 0.5 * period)


def heading_for(direction, theta_dot) -> float:
    """The heading whose motion (sign(theta_dot) e(phi)) points along the plane vector `direction`."""
    a = math.atan2(direction[1], direction[0])
    return a if theta_dot >= 0 else a + math.pi


SPIN_ROUND_OFF = 1e-12  # [rad/s] a spin this small is the simulator's round-off (a release leaves ~1e-15): not braked


def brake_rows(phi_dot, a1, dt) -> list:
    """Scaled steering torques (phi'' = action a1) that bring phi_dot to 0 in the fewest rows, at a constant torque
    (none for a spin at round-off level, so that a turn that follows starts at once)."""
    if abs(phi_dot) <= SPIN_ROUND_OFF:
        return []
    n = max(1, int(math.ceil(abs(phi_dot) / (a1 * dt) - 1e-12)))
    return [-phi_dot / (a1 * dt * n)] * n


def brake_turn(phi_dot, a1, dt) -> float:
    """The heading change during :func:`brake_rows`: phi_dot n dt / 2."""
    return 0.5 * phi_dot * dt * len(brake_rows(phi_dot, a1, dt))


def turn_rows_needed(delta, a1, dt) -> int:
    """Rows (even, >= 2) of a rest-to-rest turn by delta within the torque limit: (k/2)^2 a1 dt^2 >= |delta|."""
    return 2 * max(1, int(math.ceil(math.sqrt(abs(delta) / (a1 * dt * dt)) - 1e-12)))


def turn_rows(delta, a1, dt, rows=None) -> list:
    """A rest-to-rest turn by delta in `rows` rows (default the fewest): c for rows/2 rows, then -c (symmetric in
    time, so a turn from +alpha to -alpha about a direction moves the contact point only along it)."""
    k = turn_rows_needed(delta, a1, dt) if rows is None else int(rows)
    c = delta / (a1 * dt * dt * (k // 2) ** 2)
    if abs(c) > 1.0 + 1e-12:
        raise ValueError(f"a turn by {delta!r} rad needs more than {k} rows at the torque limit")
    return [c] * (k // 2) + [-c] * (k // 2)


def aim_heading(state, phi_target, a1, dt, period=2.0 * math.pi) -> list:
    """Rows that brake phi_dot and then turn rest to rest onto phi_target (modulo period): the heading after them is
    exact, whatever the contact point does (phi'' is the steering torque alone)."""
    brake = brake_rows(state[5], a1, dt)
    delta = wrap(phi_target - (state[3] + brake_turn(state[5], a1, dt)), period)
    return brake + turn_rows(delta, a1, dt)


def aim_duration(phi_dot, delta, a1, dt) -> float:
    """How long :func:`aim_heading` runs (dt > 0: whole rows) or the shortest braking plus rest-to-rest turn (dt = 0:
    |phi_dot| / a1 + 2 sqrt(|delta| / a1)). The contact point moves at most |R theta_dot| times this."""
    if dt == 0:
        return abs(phi_dot) / a1 + 2.0 * math.sqrt(abs(delta) / a1)
    return dt * (len(brake_rows(phi_dot, a1, dt)) + turn_rows_needed(delta, a1, dt))


def aim_time(a1, max_turn=FULL_TURN, dt=0.0) -> float:
    """T6.1's tau: the duration of its turn, rest to rest by at most max_turn (2 sqrt(max_turn / a1) = 1.59 s at
    a1 = 10 rad/s^2 and 2 pi; 32 rows of 0.05 s)."""
    return 2.0 * math.sqrt(max_turn / a1) if dt == 0 else dt * turn_rows_needed(max_turn, a1, dt)


@dataclass(frozen=True)
class Steering:
    """A steer-only penny's world: the table, the law, the penny, the steering limit a1 = u1 / J and the row length."""

    table: object
    law: object
    params: object
    a1: float
    dt: float

    @classmethod
    def of_scene(cls, scene) -> "Steering":
        """The world of an environment's scene (env.unwrapped.scene)."""
        params = scene.make_params()
        return cls(scene.make_table(), scene.law, params, scene.torque_limits["u1"] / params.J, scene.control_dt)

    def run(self, state, actions):
        """The simulator's trajectory of the rows of scaled steering torques from state."""
        u = [[float(a) * self.a1 * self.params.J, 0.0] for a in actions]
        return simulate(np.asarray(state, float), params=self.params, table=self.table, law=self.law, controls=u,
                        control_dt=self.dt)


# -- T6.1 -------------------------------------------------------------------------------------------------------
def aim_through(state, target, steering: Steering, max_turn=FULL_TURN, scan=AIM_SCAN):
    """T6.1's turn: rows (brake phi_dot, then a rest-to-rest turn by delta in a fixed number of rows, |delta| <=
    max_turn) after which the penny's motion points at `target`: a zero of f(delta) = angle(target - z(delta)) -
    motion(delta) (mod 2 pi), found by a scan and bisection on the simulator. None where the scan finds no zero (the
    proof's 2 pi always has one; pi misses targets straight behind). Returns (rows, delta) or None."""
    st = steering
    brake = brake_rows(state[5], st.a1, st.dt)
    k = turn_rows_needed(max_turn, st.a1, st.dt)
    g = np.asarray(target, float)

    def plan(delta):
        return brake + turn_rows(delta, st.a1, st.dt, rows=k)

    def f(delta):
        s = st.run(state, plan(delta)).final_state
        motion = s[3] + (math.pi if s[4] < 0 else 0.0)
        return wrap(math.atan2(g[1] - s[1], g[0] - s[0]) - motion)
    grid = np.linspace(-max_turn, max_turn, scan)
    vals = [f(d) for d in grid]
    brackets = [(lo, hi, flo) for lo, hi, flo, fhi in zip(grid[:-1], grid[1:], vals[:-1], vals[1:])
                if flo * fhi <= 0 and abs(flo - fhi) < math.pi]  # (a jump of 2 pi is the wrap, not a zero)
    if not brackets:
        return None
    lo, hi, flo = min(brackets, key=lambda b: min(abs(b[0]), abs(b[1])))  # the shortest turn
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        fm = f(mid)
        lo, hi, flo = (mid, hi, fm) if fm * flo > 0 else (lo, mid, flo)
    return plan(0.5 * (lo + hi)), 0.5 * (lo + hi)


# -- an episode, one row at a time ----------------------------------------------------------------------------
class EpisodeEnded(Exception):
    """The episode ended (success or time limit) during a construction's row."""


@dataclass
class Episode:
    """What a construction needs of an episode: one row of scaled steering torque (True when the episode ended), the
    state after it, the impacts so far and whether the episode succeeded."""

    step: Callable[[float], bool]
    state: Callable[[], np.ndarray]
    impacts: Callable[[], int]
    success: Callable[[], bool]
    rows_run: int = 0

    def row(self, action):
        if not abs(action) <= 1.0 + 1e-9:
            raise ValueError(f"a steering row beyond the torque limit: {action!r}")
        self.rows_run += 1
        if self.step(float(min(max(action, -1.0), 1.0))):
            raise EpisodeEnded

    def rows(self, actions):
        for a in actions:
            self.row(a)

    def coast_until(self, done, limit=10 ** 6):
        """Rows without torque until done() (checked before each row)."""
        for _ in range(limit):
            if done():
                return
            self.row(0.0)
        raise RuntimeError("coast_until: the condition never came")


@dataclass
class ParkRecord:
    """What a construction did, for the tests: where the episode ended and the formulas' checks on the way."""

    success: bool = False
    phase: str = "aim"
    ladder: list = field(default_factory=list)    # T8.1: (k, theta_dot after the k-th impact, theta_dot0 (-e0)^k)
    stops: list = field(default_factory=list)     # T8.2: (theta_dot before, theta_dot after, phi_dot after, s at stop)
    releases: list = field(default_factory=list)  # T8.2: (predicted |theta_dot|, |theta_dot| after, turned, final)
    impacts_at: list = field(default_factory=list)  # (s, y) of the contact point after each impact row
    crossings: list = field(default_factory=list)   # T8.2: s of the contact point at the row after each mid-line crossing
    aim_turn: float = math.nan                    # T6.1's turn delta (rad)


def _crossed_mid_line(ep, pair, side):
    """A predicate: the contact point is on the other side of the mid-line y = 0 than `side` (+1 or -1)."""
    return lambda: pair.coords(ep.state()[:2])[1] * side <= 0.0


def _park_from_mid_line(ep, st, pair, target, rec, v_slow):
    """The common end of T8.1 and T8.2, for a penny creeping at |R theta_dot| <= v_slow just after an impact (or a
    release) on one side: brake its spin, coast across the mid-line (the clearance there is large) and on until the
    target lies outside T6.1's disk, then T6.1's turn and the creep through the target."""
    rec.phase = "creep"
    ep.rows(brake_rows(ep.state()[5], st.a1, st.dt))
    side = math.copysign(1.0, pair.coords(ep.state()[:2])[1])  # (just after an impact on that side)
    ep.coast_until(_crossed_mid_line(ep, pair, side))
    rho1 = abs(st.params.R * ep.state()[4]) * aim_time(st.a1, FULL_TURN, st.dt)
    g = np.asarray(target, float)
    ep.coast_until(lambda: np.hypot(*(g - ep.state()[:2])) > 2.0 * rho1)
    rec.phase = "aim"
    found = aim_through(ep.state(), g, st)
    if found is None:
        rec.phase = "no aim"
        return
    acts, rec.aim_turn = found
    ep.rows(acts)
    rec.phase = "park"
    ep.coast_until(lambda: False)


# -- T8.1: dissipative walls, the head-on ladder ------------------------------------------------------------------
def ladder_room(table, pair: FlatPair, state, a1, R, dt=0.0):
    """T8.1's hypothesis: (holds, (clearance margin, along-side margin)). The aim (brake phi_dot, turn the heading
    along the pair's normal, modulo pi) lasts tau; the contact point stays in the disk of radius |R theta_dot| tau
    about its start, which must have clearance > R (no impact during the aim) and lie within |s| <= X (the line
    after the aim is a double normal)."""
    phi_n = math.atan2(pair.normal[1], pair.normal[0])
    braked = state[3] + (brake_turn(state[5], a1, dt) if dt else state[5] * abs(state[5]) / (2.0 * a1))
    delta = wrap(phi_n - braked, math.pi)
    rho = abs(R * state[4]) * aim_duration(state[5], delta, a1, dt)
    s0, _ = pair.coords(state[:2])
    m_clear = clearance(table, state[:2]) - R - rho
    m_side = pair.X - abs(s0) - rho
    return bool(m_clear > ROOM_MARGIN and m_side > ROOM_MARGIN), (m_clear, m_side)


def ladder_park(ep: Episode, st: Steering, pair: FlatPair, target, e0, v_slow=0.004) -> ParkRecord:
    """T8.1's construction on an episode: aim along the pair's normal; bounce head-on (after each impact a turn onto
    the exact normal heading: in exact arithmetic a turn by 0, on the simulator it removes the round-off that the
    unstable head-on line would grow, T3.5) until |R theta_dot| < v_slow; creep to the mid-line; T6.1."""
    rec = ParkRecord()
    phi_n = math.atan2(pair.normal[1], pair.normal[0])
    v_slow = min(v_slow, 0.5 * abs(st.params.R * ep.state()[4]))  # (at least one impact: the creep starts at a wall)
    try:
        ep.rows(aim_heading(ep.state(), phi_n, st.a1, st.dt, math.pi))
        rec.phase = "ladder"
        td0, k = ep.state()[4], 0
        while abs(st.params.R * ep.state()[4]) >= v_slow:
            before = ep.impacts()
            ep.row(0.0)
            if ep.impacts() > before:
                k += ep.impacts() - before
                s = ep.state()
                rec.ladder.append((k, float(s[4]), float(td0 * (-e0) ** k)))
                rec.impacts_at.append(pair.coords(s[:2]))
                ep.rows(aim_heading(s, phi_n, st.a1, st.dt, math.pi))
        _park_from_mid_line(ep, st, pair, target, rec, v_slow)
    except EpisodeEnded:
        pass
    rec.success = bool(ep.success())
    return rec


# -- T8.2: elastic walls, stop and release --------------------------------------------------------------------------
@dataclass(frozen=True)
class ZigzagConstants:
    """The table-level numbers of T8.2 for a pair, a penny, a1, the fastest speed v_max and the row length dt."""

    beta: float        # beta*, the full-conversion incidence
    free_angle: float  # pi - 2 beta*: the heading's turn between a stop and its release on a flat side
    L: float           # b - R cos beta*: |y| of the contact point at a stop
    D: float           # L tan beta*: the along-side travel between the mid-line and a stop
    d1: float          # v_max (T_turn tan beta* + 2 dt sin beta*): how much a re-aim shortens that travel, at most
    xi: float          # the mid-line crossings stay within |s| <= xi
    margins: tuple     # (X - R - D, 2 D - d1, xi - 2 D): all > 0 is the hypothesis on the table

    @property
    def holds(self) -> bool:
        return all(m > ROOM_MARGIN for m in self.margins)


def zigzag_constants(table, pair: FlatPair, params, a1, v_max, dt=0.0) -> ZigzagConstants:
    """T8.2's invariant: a mid-line crossing at |s0| <= xi, re-aimed toward s = 0, stops at |s| <= max(D, xi - D + d1)
    <= X - R and crosses the mid-line next at |s| <= max(2 D, xi - 2 D + d1) <= xi. xi is the smaller of X - R + D - d1
    (the stops stay on the flat pieces with the spin circle in the rectangle) and the largest |s| of a mid-line crossing
    after which the re-aim turn (lasting T_turn, starting within v_max dt of the crossing) has room."""
    beta = full_conversion_angle(params)
    R = params.R
    L = pair.b - R * math.cos(beta)
    D = L * math.tan(beta)
    t_turn = aim_duration(0.0, 2.0 * beta, a1, dt)
    d1 = v_max * (t_turn * math.tan(beta) + 2.0 * dt * math.sin(beta))
    need = R + v_max * t_turn + ROOM_MARGIN

    def room(s):  # the turn starts in the box |s'| <= s + v_max dt, |y| <= v_max dt (the lag after the crossing);
        # clearance is concave, so its least over the box is at a corner
        lag = v_max * dt
        return min(clearance(table, pair.vector(sg * (s + lag), sy * lag)) for sg in (1, -1) for sy in (1, -1)) > need
    lo, hi = 0.0, pair.X + pair.b
    if not room(lo):
        xi_room = -math.inf
    else:
        for _ in range(80):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if room(mid) else (lo, mid)
        xi_room = lo
    xi = min(pair.X - R + D - d1, xi_room)
    return ZigzagConstants(beta, math.pi - 2.0 * beta, L, D, d1, xi, (pair.X - R - D, 2.0 * D - d1, xi - 2.0 * D))


def zigzag_room(table, pair: FlatPair, state, params, a1, dt=0.0, v_max=None):
    """T8.2's hypothesis on a start: (holds, (s_x, s_n), margins). The aim (brake phi_dot, turn onto the motion
    s_x sin beta* t + s_n cos beta* n, s_x = -sign(s0): toward the centre) keeps the contact point in the disk of
    radius rho = |R theta_dot| tau about z0, which must have clearance > R; from every point of that disk the first
    stop must land at |s| <= X - R and the first release cross the mid-line at |s| <= xi; and the table's constants
    must hold for v_max (default the start's speed: the speed never grows). The side s_n with the larger margin."""
    R = params.R
    v0 = abs(R * state[4])
    c = zigzag_constants(table, pair, params, a1, v0 if v_max is None else v_max, dt)
    s0, y0 = pair.coords(state[:2])
    sx = -1.0 if s0 > 0 else 1.0
    tb = math.tan(c.beta)
    best = (False, (sx, 1.0), (-math.inf,))
    for sn in (1.0, -1.0):
        phi_t = heading_for(pair.vector(sx * math.sin(c.beta), sn * math.cos(c.beta)), state[4])
        braked = state[3] + (brake_turn(state[5], a1, dt) if dt else state[5] * abs(state[5]) / (2.0 * a1))
        rho = v0 * aim_duration(state[5], wrap(phi_t - braked), a1, dt)
        travel = (c.L - sn * y0 - rho, c.L - sn * y0 + rho)  # the contact point's |y| distance to the stop line
        stop = (s0 - rho + sx * tb * (travel[0] if sx > 0 else travel[1]),
                s0 + rho + sx * tb * (travel[1] if sx > 0 else travel[0]))
        mid = (stop[0] + sx * c.D, stop[1] + sx * c.D)
        margins = (clearance(table, state[:2]) - R - rho, travel[0],
                   pair.X - R - max(abs(stop[0]), abs(stop[1])), c.xi - max(abs(mid[0]), abs(mid[1])), *c.margins)
        ok = all(m > ROOM_MARGIN for m in margins)
        if (ok, min(margins)) > (best[0], min(best[2])):
            best = (ok, (sx, sn), margins)
    return best


def stop_release_park(ep: Episode, st: Steering, pair: FlatPair, target, choice, v_slow=0.004, beta=None,
                      free_angle=None) -> ParkRecord:
    """T8.2's construction on an episode (elastic walls). choice = (s_x, s_n) of :func:`zigzag_room`. beta and
    free_angle default to the theorem's beta* and pi - 2 beta* (the tests pass wrong ones: the checks must fail)."""
    rec = ParkRecord()
    p = st.params
    beta = full_conversion_angle(p) if beta is None else beta
    delta_free = math.pi - 2.0 * full_conversion_angle(p) if free_angle is None else free_angle
    ratio = math.sqrt(p.rolling_inertia / p.J)  # a full stop: |phi_dot| after = ratio |theta_dot| before
    w1 = ratio * v_slow / p.R                   # the spin that a release turns into |R theta_dot| = v_slow
    sx, sn = choice

    def aim(sx, sn):
        s = ep.state()
        phi_t = heading_for(pair.vector(sx * math.sin(beta), sn * math.cos(beta)), s[4])
        ep.rows(aim_heading(s, phi_t, st.a1, st.dt))
    try:
        aim(sx, sn)
        while True:
            rec.phase = "stop"
            before = ep.state().copy()
            n0 = ep.impacts()
            ep.coast_until(lambda: ep.impacts() > n0)
            s = ep.state()
            rec.stops.append((float(before[4]), float(s[4]), float(s[5]), pair.coords(s[:2])[0]))
            rec.impacts_at.append(pair.coords(s[:2]))
            side = math.copysign(1.0, pair.coords(s[:2])[1])
            turned = abs(wrap(s[3] - before[3]))  # the spin turned the heading, unbraked, over the rest of the row
            rem = delta_free - turned
            spin = s[5]
            final = spin * spin < 2.0 * st.a1 * rem + w1 * w1
            rec.phase = "release"
            n0 = ep.impacts()
            if final:  # brake at the constant rate that leaves the spin w1 at the release
                a = max((spin * spin - w1 * w1) / (2.0 * rem), 0.0)
                while ep.impacts() == n0:
                    ep.row(-math.copysign(a / st.a1, spin))
                predicted = math.sqrt(max(spin * spin - 2.0 * a * rem, 0.0)) / ratio
                rec.releases.append((predicted, abs(float(ep.state()[4])), math.nan, True))
                rec.impacts_at.append(pair.coords(ep.state()[:2]))
                break
            while ep.impacts() == n0:  # full braking; the row of the release (the simulator's) coasts: no spin left
                cur = ep.state()
                full = -math.copysign(1.0, cur[5])
                ep.row(0.0 if st.run(cur, [full]).n_impacts else full)
            s2 = ep.state()
            rec.releases.append((abs(float(cur[5])) / ratio, abs(float(s2[4])),
                                 abs(wrap(s2[3] - before[3])), False))
            rec.impacts_at.append(pair.coords(s2[:2]))
            rec.phase = "cross"
            ep.coast_until(_crossed_mid_line(ep, pair, side))
            s_mid = pair.coords(ep.state()[:2])[0]
            rec.crossings.append(s_mid)
            aim(-1.0 if s_mid > 0 else 1.0, -side)
        _park_from_mid_line(ep, st, pair, target, rec, v_slow)
    except EpisodeEnded:
        pass
    rec.success = bool(ep.success())
    return rec


# -- which start/target pairs T8 decides -------------------------------------------------------------------------
def steer_park_theorem(table, law, params, a1, dt, state, target):
    """('T8.1' or 'T8.2', the pair, the choice) where T8 proves the steer-only park of this start and target possible
    given enough time (with rows of length dt): a table with parallel flat sides, a law with 0 < e0 < 1 (T8.1) or
    elastic walls (T8.2), a start that rolls with room and a target with clearance > R; else None."""
    pairs = flat_pairs(table)
    if not pairs or state[4] == 0 or clearance(table, target) <= params.R + ROOM_MARGIN:
        return None
    parsed = make_law(law)
    if parsed.kind == "elastic":
        for pair in pairs:
            ok, choice, _ = zigzag_room(table, pair, state, params, a1, dt)
            if ok:
                return "T8.2", pair, choice
        return None
    e0 = head_on_coefficient(law, params)
    if not 0.0 < e0 < 1.0:
        return None
    for pair in pairs:
        if ladder_room(table, pair, state, a1, params.R, dt)[0]:
            return "T8.1", pair, None
    return None
