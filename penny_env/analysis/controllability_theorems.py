"""Which cells and start/target pairs the theory decides: docs/controllability_theory.md as code.

The impossibility theorems, each applied to every cell (registered ids, field overrides, user tables): they
read the table's size and shape, the spawn and target regions, the time limit (max_episode_steps x control_dt),
the start speeds and the torque limits.

* T2.3, steer only, open plane: theta_dot never changes, so a park needs |R theta_dot0| < speed_tolerance and
  the target within tolerance + |R theta_dot0| T of the start;
* T2.5, steer only, a table: a park either happens with no impact (as on the plane) or after a first impact at
  t1 >= (d0 - R) / |R theta_dot0| (d0: the start's distance to the wall; theta_dot is constant until then), and
  then at the end the contact point is within R + tolerance + speed_tolerance (T - t1) of the wall;
* T3.2, drive only, open plane from phi_dot = 0: the contact point stays on its heading line;
* T3.4, drive only from phi_dot = 0 on a circle, the heading line through the centre: a diameter, invariant;
* T5.2, every actuation, built-in laws: the contact point travels at most R (rho0 T + c T^2 / 2) / sqrt(I + m R^2)
  in time T (rho0 the metric speed at the start, c the torques' bound on its growth; impacts never add energy).

:func:`cell_theorem` says whether every start/target pair a (Scene, Task) can draw falls under one of them (from
the regions' and ranges' extremes, with lower bounds of distances that are proved); :func:`pair_theorem` decides
one pair. Each verdict names the success conditions it rules out (position, speed, time). Distances to the wall
are lower bounds (:func:`wall_distance_lower`): the distance to an inscribed polygon, less a margin; every bound
leans toward "not decided".
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..step.tasks.park import rest_speed

DOC = "controllability_theory.md"
POLYGON = 8192        # vertices of the inscribed polygon of the wall (wall_distance_lower)
SLACK = 1e-5          # [table sizes] subtracted from every distance to the wall (the polygon's sagitta, round-off)
BUILT_IN_LAWS = ("elastic", "plastic", "restitution")  # laws that never add energy (T1.5): T5 needs it

ANCHORS = {"T2": "t2-steer-only", "T3": "t3-drive-only", "T4": "t4-both-controls",
           "T5": "t5-every-actuation-a-travel-bound"}


@dataclass(frozen=True)
class TheoremVerdict:
    """A cell or pair that a theorem of docs/controllability_theory.md makes impossible."""

    id: str          # the statement, e.g. "T2.5"
    anchor: str      # its section's anchor in DOC, e.g. "t2-steer-only"
    reason: str      # one sentence: why, with the numbers of the configuration
    conditions: tuple = ()  # the success conditions it rules out: "position", "speed", "time"

    @property
    def label(self) -> str:
        return f"impossible (theorem {self.id})"

    def link(self, base: str = "docs/") -> str:
        """The Markdown target of the statement's section (base: the folder of DOC as seen from the caller)."""
        return f"{base}{DOC}#{self.anchor}"


def _verdict(tid, reason, *conditions):
    return TheoremVerdict(tid, ANCHORS[tid.split(".")[0]], reason, tuple(conditions))


# -- geometry -----------------------------------------------------------------------------------------------
def _polygon(table):
    """(vertices (n, 2), next vertices) of an inscribed polygon: rays from the centre to the wall (convex and
    star-shaped about the origin, which every table's spawn region is centred on)."""
    key = id(table)
    if _POLY_CACHE.get(key, (None,))[0] is not table:
        ang = np.linspace(0.0, 2.0 * np.pi, POLYGON, endpoint=False)
        rho = np.asarray(table.wall_distance(np.cos(ang), np.sin(ang)), float)
        v = np.stack([rho * np.cos(ang), rho * np.sin(ang)], axis=1)
        _POLY_CACHE.clear()
        _POLY_CACHE[key] = (table, v, np.roll(v, -1, axis=0))
    return _POLY_CACHE[key][1:]


_POLY_CACHE: dict = {}


def wall_distance_lower(table, points) -> np.ndarray:
    """A lower bound of the distance from each point (n, 2) (inside the table) to the wall: the distance to the
    boundary of an inscribed polygon (vertices on the wall; the polygon lies inside the convex table, so for a point
    inside it the segment to the nearest wall point crosses the polygon's boundary), less SLACK x the table size.
    Points outside the table get 0."""
    p = np.ascontiguousarray(np.atleast_2d(np.asarray(points, float)))
    if _is_circle(table):  # exact: r - |p|
        out = table.a - np.hypot(p[:, 0], p[:, 1])
    else:
        a, _ = _polygon(table)
        out = _polygon_distance(p, np.ascontiguousarray(a))
    inside = np.asarray(table.h(p[:, 0], p[:, 1]), float) < 0
    return np.where(inside, np.maximum(out - SLACK * table.size, 0.0), 0.0)


def _polygon_distance_py(p, v):
    """Distance from each point of p (n, 2) to the closed polygon with vertices v (m, 2)."""
    b = np.roll(v, -1, axis=0)
    ab = b - v
    out = np.empty(len(p))
    for i, q in enumerate(p):
        t = np.clip(((q - v) * ab).sum(1) / (ab * ab).sum(1), 0.0, 1.0)
        out[i] = np.hypot(*(q - (v + t[:, None] * ab)).T).min()
    return out


try:  # numba is a core dependency; the plain version is the same arithmetic (and the reference in the tests)
    import numba

    @numba.njit(cache=True)
    def _polygon_distance(p, v):  # pragma: no cover - compiled
        n, m = p.shape[0], v.shape[0]
        out = np.empty(n)
        for i in range(n):
            best = np.inf
            for j in range(m):
                k = j + 1 if j + 1 < m else 0
                ex, ey = v[k, 0] - v[j, 0], v[k, 1] - v[j, 1]
                qx, qy = p[i, 0] - v[j, 0], p[i, 1] - v[j, 1]
                t = (qx * ex + qy * ey) / (ex * ex + ey * ey)
                t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
                dx, dy = qx - t * ex, qy - t * ey
                d = dx * dx + dy * dy
                if d < best:
                    best = d
            out[i] = np.sqrt(best)
        return out
except ImportError:  # pragma: no cover
    _polygon_distance = _polygon_distance_py


def region_wall_distance_lower(table, axes, n: int = 256, tol: float = 1e-4) -> float:
    """A lower bound of min over the filled ellipse E with semi-axes `axes` (centred on the origin) of the distance
    to the wall. The distance to the boundary of a convex set is concave inside it, so its minimum over E is on E's
    boundary; it is 1-Lipschitz, so over an arc of E's boundary between two points it is at least the smaller of
    their values less half the arc's length. Branch and bound on n arcs, splitting the arcs whose bound is below the
    best value found, until the bound is within tol x the table's size of it."""
    ax, ay = float(axes[0]), float(axes[1])
    if ax == 0.0 and ay == 0.0:
        return float(wall_distance_lower(table, [[0.0, 0.0]])[0])
    if _is_circle(table):  # exact: the region's farthest point from the centre
        return max(table.a - max(ax, ay) - SLACK * table.size, 0.0)

    def at(t):
        return wall_distance_lower(table, np.stack([ax * np.cos(t), ay * np.sin(t)], axis=1))

    def arc(t0, t1):  # an upper bound of the arc length of E between parameters t0 < t1
        return (t1 - t0) * max(ax, ay)
    t = np.linspace(0.0, 2.0 * np.pi, n + 1)
    d = at(t)
    lo, hi, dlo, dhi = t[:-1], t[1:], d[:-1], d[1:]
    best = float(d.min())
    for _ in range(60):
        bound = np.minimum(dlo, dhi) - 0.5 * arc(lo, hi)
        open_ = bound < best - tol * table.size
        if not open_.any():
            break
        lo, hi, dlo, dhi = lo[open_], hi[open_], dlo[open_], dhi[open_]
        mid = 0.5 * (lo + hi)
        dm = at(mid)
        best = min(best, float(dm.min()))
        lo, hi = np.concatenate([lo, mid]), np.concatenate([mid, hi])
        dlo, dhi = np.concatenate([dlo, dm]), np.concatenate([dm, dhi])
    bound = np.minimum(dlo, dhi) - 0.5 * arc(lo, hi)
    return max(min(best, float(bound.min())), 0.0)


# -- the cell's numbers ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CellNumbers:
    """What the theorems read from a (Scene, Task): the same formulas as the environment's sampler
    (penny_env/envs/core.py: Core.sample)."""

    table: object            # the Table, or None on the open plane
    R: float
    rolling_inertia: float   # I + m R^2
    J: float
    a1: float                # |phi''| bound of the actuated steering torque [rad/s^2] (0 if not actuated)
    a2: float                # |theta''| bound of the actuated rolling torque (0 if not actuated)
    horizon: float           # T = max_episode_steps x control_dt [s]
    spawn_axes: tuple        # semi-axes of the start region (contact points)
    target_axes: tuple       # semi-axes of the target region
    law_kind: str


def cell_numbers(scene, task) -> CellNumbers:
    p = scene.make_params()
    table = scene.make_table()
    ax, ay = scene.spawn_axes()
    fmax = 1.0 if table is None else 1.0 - p.R / table.inradius
    fs, ft = scene.init["spawn_fraction"], task.target_fraction * fmax
    a1 = scene.torque_limits["u1"] / p.J if 0 in scene.controls else 0.0
    a2 = scene.torque_limits["u2"] / p.rolling_inertia if 1 in scene.controls else 0.0
    return CellNumbers(table, p.R, p.rolling_inertia, p.J, a1, a2, task.max_episode_steps * scene.control_dt,
                       (fs * ax, fs * ay), (ft * ax, ft * ay), scene.make_law().kind)


def travel_bound(c: CellNumbers, theta_dot, phi_dot, T) -> float:
    """T5.2: the longest path of the contact point in time T from a start with speeds (theta_dot, phi_dot):
    R (rho0 T + k T^2 / 2) / sqrt(I + m R^2), rho0 the start's metric speed, k = sqrt((I + m R^2) a2^2 + J a1^2)."""
    rho0 = math.sqrt(c.rolling_inertia * theta_dot * theta_dot + c.J * phi_dot * phi_dot)
    k = math.sqrt(c.rolling_inertia * c.a2 * c.a2 + c.J * c.a1 * c.a1)
    return c.R * (rho0 * T + 0.5 * k * T * T) / math.sqrt(c.rolling_inertia)


def first_impact_time(d0: float, R: float, v: float) -> float:
    """T2.5: a lower bound of the first impact's time of a steer-only penny rolling at v = |R theta_dot| [m/s]
    whose contact point starts d0 from the wall: it must first come within R of it (inf when it cannot move)."""
    if d0 <= R:
        return 0.0
    return math.inf if v == 0.0 else (d0 - R) / v


def _slowest(lo, hi):
    return 0.0 if lo <= 0.0 <= hi else min(abs(lo), abs(hi))


# -- cells ----------------------------------------------------------------------------------------------------
def cell_theorem(scene, task) -> TheoremVerdict | None:
    """The theorem that makes every pair this (Scene, Task) can draw impossible, or None (the theory leaves the
    cell to witnesses; single pairs may still be decided by :func:`pair_theorem`). Drive only: the env draws
    targets at least `heading_offset` off the heading line (by rejection, with a fallback of probability below
    1e-10 per episode, see docs/study_probes.md); :func:`pair_theorem` decides each drawn pair exactly."""
    if task.kind not in ("park", "reach"):
        return None
    c = cell_numbers(scene, task)
    R, T = c.R, c.horizon
    tol, vtol = task.tolerance, rest_speed(task)  # (reach: the rest speed its witnesses brake to)
    W_lo, W_hi = scene.init["theta_dot"]
    if scene.actuation == "steer" and task.kind == "park":
        v_min, v_max = R * _slowest(W_lo, W_hi), R * max(abs(W_lo), abs(W_hi))
        if v_min < vtol:
            return None  # some starts may creep to a target without an impact (route A of T2.5)
        if c.table is None:
            return _verdict("T2.3", f"open plane, steering only: |R theta_dot| stays at its start value, at least "
                                    f"{v_min:g} m/s >= speed_tolerance {vtol:g} m/s", "speed")
        d0 = region_wall_distance_lower(c.table, c.spawn_axes)
        t1 = first_impact_time(d0, R, v_max)
        dg = region_wall_distance_lower(c.table, c.target_axes)
        reach = R + tol + vtol * max(T - t1, 0.0)
        if dg >= reach:
            return _verdict("T2.5", f"steering only: every start rolls at >= {v_min:g} m/s >= speed_tolerance, so a park "
                                    f"follows an impact, the first after >= {t1:.3g} s (starts >= {d0:.4g} m from the "
                                    f"wall, <= {v_max:g} m/s); by T = {T:g} s the contact point is then within "
                                    f"R + tolerance + speed_tolerance (T - t1) = {reach:.4g} m of the wall, and every "
                                    f"target is >= {dg:.4g} m from it", "speed", "time")
    if scene.actuation == "drive" and task.kind in ("reach", "park"):
        still = tuple(scene.init["phi_dot"]) == (0.0, 0.0)
        if still and task.heading_offset >= task.tolerance:
            if c.table is None:
                return _verdict("T3.2", f"open plane, rolling only, phi_dot = 0: the contact point stays on its heading "
                                        f"line, targets are {task.heading_offset:g} m off it >= tolerance "
                                        f"{task.tolerance:g} m", "position")
            if _is_circle(c.table) and c.spawn_axes == (0.0, 0.0):
                return _verdict("T3.4", f"rolling only, phi_dot = 0, every start at the centre of a circle: the heading "
                                        f"line is a diameter, invariant; targets are {task.heading_offset:g} m off it "
                                        f">= tolerance {task.tolerance:g} m", "position")
    return None


def _is_circle(table) -> bool:
    from ..physics.tables.ellipse import Ellipse
    return isinstance(table, Ellipse) and table.a == table.b


# -- pairs ----------------------------------------------------------------------------------------------------
def pair_theorem(scene, task, state, target) -> TheoremVerdict | None:
    """The theorem that makes this start (x, y, theta, phi, theta_dot, phi_dot) and target (x, y) impossible
    under (Scene, Task), or None."""
    s = np.asarray(state, dtype=float)
    g = np.asarray(target, dtype=float)
    if s.shape != (6,) or not np.all(np.isfinite(s)):
        raise ValueError(f"state must be 6 finite numbers (x, y, theta, phi, theta_dot, phi_dot), got shape {s.shape}")
    if g.shape != (2,) or not np.all(np.isfinite(g)):
        raise ValueError(f"target must be 2 finite numbers (x, y), got shape {g.shape}")
    if task.kind not in ("park", "reach"):
        return None
    c = cell_numbers(scene, task)
    R, T = c.R, c.horizon
    tol, vtol = task.tolerance, rest_speed(task)  # (reach: the rest speed its witnesses brake to)
    v = abs(R * s[4])
    gap = float(np.hypot(*(g - s[:2])))
    if scene.actuation == "steer" and task.kind == "park":
        found = _steer_park(c, s, g, v, gap, tol, vtol, T)
        if found:
            return found
    if scene.actuation == "drive" and s[5] == 0.0:
        off_line = abs(-(g[0] - s[0]) * math.sin(s[3]) + (g[1] - s[1]) * math.cos(s[3]))
        if off_line >= tol:
            if c.table is None:
                return _verdict("T3.2", f"the target is {off_line:g} m off the heading line >= tolerance {tol:g} m",
                                "position")
            if _is_circle(c.table) and s[0] * math.sin(s[3]) - s[1] * math.cos(s[3]) == 0.0:
                return _verdict("T3.4", f"the heading line is a diameter of the circle (invariant), the target "
                                        f"{off_line:g} m off it >= tolerance {tol:g} m", "position")
    if c.law_kind in BUILT_IN_LAWS:
        reach = travel_bound(c, s[4], s[5], T)
        if gap >= tol + reach:
            return _verdict("T5.2", f"the target is {gap:.4g} m from the start; in T = {T:g} s the contact point travels "
                                    f"at most {reach:.4g} m (start speeds and torque limits)", "position", "time")
    return None


def _steer_park(c, s, g, v, gap, tol, vtol, T):
    """T2.3 / T2.5 for one pair (the routes of docs/controllability_theory.md#t2-steer-only)."""
    no_impact = v < vtol and gap < tol + v * T  # route A: the penny creeps there at its start speed
    if c.table is None:
        if no_impact:
            return None
        why = (f"|R theta_dot| = {v:g} m/s >= speed_tolerance {vtol:g} m/s forever" if v >= vtol else
               f"|R theta_dot| = {v:g} m/s forever: in T = {T:g} s the contact point gets {v * T:.4g} m from the start, "
               f"the target is {gap:.4g} m away (tolerance {tol:g} m)")
        return _verdict("T2.3", why, "speed" if v >= vtol else "position", *(() if v >= vtol else ("time",)))
    if no_impact:
        return None
    d0, dg = wall_distance_lower(c.table, np.array([s[:2], g]))
    t1 = first_impact_time(float(d0), c.R, v)
    reach = c.R + tol + vtol * max(T - t1, 0.0)
    if t1 <= T and dg < reach:
        return None  # route B is open
    start = (f"|R theta_dot| = {v:g} m/s >= speed_tolerance {vtol:g} m/s until an impact" if v >= vtol else
             f"at {v:g} m/s the start cannot creep the {gap:.4g} m to the target in T = {T:g} s")
    after = (f"the first impact comes after T = {T:g} s" if t1 > T else
             f"the first impact comes after >= {t1:.3g} s (start {float(d0):.4g} m from the wall), so by T = {T:g} s the "
             f"contact point is within R + tolerance + speed_tolerance (T - t1) = {reach:.4g} m of the wall; the target "
             f"is {float(dg):.4g} m from it")
    return _verdict("T2.5", f"{start}; {after}", "speed", "time")


# -- registered ids -------------------------------------------------------------------------------------------
def resolve_id(env_id: str, **overrides):
    """(Scene, Task) of a registered id with field overrides (the way gymnasium.make(env_id, **overrides) builds it)."""
    from ..envs.scene import env_presets, resolve

    if not isinstance(env_id, str):
        raise TypeError(f"env_id must be a string, got {type(env_id).__name__}")
    presets = env_presets()
    if env_id not in presets:
        raise ValueError(f"env_id {env_id!r} is not a registered penny_env id (penny_env/presets/envs.yaml)")
    return resolve(**{**presets[env_id], **overrides})


def theorem_for(env_id: str, **overrides) -> TheoremVerdict | None:
    """:func:`cell_theorem` of a registered id with field overrides (table=..., law=...)."""
    return cell_theorem(*resolve_id(env_id, **overrides))
