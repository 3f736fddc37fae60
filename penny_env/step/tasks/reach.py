"""The reach task: bring the contact point within ``tolerance`` of a target drawn each episode.

reward per step: progress_weight (d_prev - d) / L - ctrl_cost ctrl + success_bonus [success];
success (terminates): d < tolerance. d: distance from the contact point to the target, L: the scene's
length scale, ctrl: mean squared action. The target is uniform in target_fraction (1 - R / inradius)
times the spawn ellipse, at least heading_offset from the initial heading line (by rejection)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

from ..draws import N_DRAWS, draw_uniform
from ..config import ConfigError
from .base import Task, TaskRecord, add_task

OFFSET_TRIES = 64  # target candidates per episode when heading_offset > 0 (draws 8, 9, ... of the episode)


@dataclass(frozen=True)
class ReachTask(Task):
    """reach (and park, which extends it).

    tolerance:        [m] success radius around the target
    target_fraction:  targets are uniform in this fraction of the reachable part of the spawn ellipse
    progress_weight:  weight of the progress term (d_prev - d) / L
    heading_offset:   [m] minimum distance of the target from the initial heading line (the line
                      through the start contact point along phi); 0 = no constraint. Drawn by rejection
                      (up to 64 candidates, then the farthest).
    """

    kind: str = "reach"
    tolerance: float = 0.02
    target_fraction: float = 0.6
    progress_weight: float = 10.0
    heading_offset: float = 0.0

    def __post_init__(self):
        super().__post_init__()
        self.set_number("tolerance", positive=True)
        self.set_number("target_fraction", nonneg=True, hi=1.0)
        self.set_number("progress_weight", nonneg=True)
        self.set_number("heading_offset", nonneg=True)


class ReachConstants(NamedTuple):
    length_scale: float
    tolerance: float
    progress_weight: float
    ctrl_cost: float
    success_bonus: float
    target_scale: float      # target_fraction (1 - R / inradius) (1 on the open plane)
    heading_offset: float


def reachable_fraction(scene) -> float:
    """1 - R / inradius: the part of the spawn ellipse where the whole penny fits (1 on the open plane)."""
    table = scene.make_table()
    return 1.0 if table is None else 1.0 - scene.params["R"] / table.inradius


def constants(scene, task, L) -> ReachConstants:
    if not task.tolerance < L:
        # a success radius as large as the region itself: most episodes succeed at their first step
        field = "scene.arena (the open plane's length scale)" if scene.make_table() is None else "the table's size"
        raise ConfigError(f"task.tolerance = {task.tolerance!r} m must be below {field} = {L!r} m; lower the "
                          "tolerance or enlarge the region")
    scale = task.target_fraction * reachable_fraction(scene)
    ax, ay = scene.spawn_axes()
    if task.heading_offset > 0 and not task.heading_offset < scale * min(ax, ay):
        # any line through the spawn point leaves target points farther than the target ellipse's
        # semi-minor axis, so below it the accepted region has positive area
        raise ConfigError(f"task.heading_offset must be < target_fraction (1 - R / inradius) x the spawn ellipse's "
                          f"semi-minor axis = {scale * min(ax, ay):.6g} m, got {task.heading_offset!r}")
    return ReachConstants(float(L), task.tolerance, task.progress_weight, task.ctrl_cost, task.success_bonus, scale,
                          task.heading_offset)


def progress(k, before, after):
    return k.progress_weight * (before.dist - after.dist) / k.length_scale


def reward(k, before, after, ctrl, n_arc, xp):
    success = after.dist < k.tolerance
    return progress(k, before, after) - k.ctrl_cost * ctrl + k.success_bonus * success, success


def heading_offset(tx, ty, s, trig):
    """Distance of the point (tx, ty) from the heading line of state s (trig: its angles' cos and sin)."""
    return abs((tx - s[0]) * trig[3] - (ty - s[1]) * trig[2])


def target(k, p, m, s, trig, base, xp):
    """Uniform in the target ellipse (draws 6, 7), redrawn (draws 8, 9, ...) while closer than
    heading_offset to the initial heading line: the first candidate far enough, else the farthest."""
    b = 2.0 * xp.pi * draw_uniform(base, 7, xp) - xp.pi
    cb, sb = xp.cos(b), xp.sin(b)
    rt = k.target_scale * xp.sqrt(draw_uniform(base, 6, xp))
    tx, ty = rt * p.spawn_ax * cb, rt * p.spawn_ay * sb
    if k.heading_offset > 0.0:
        best = heading_offset(tx, ty, s, trig)
        for j in range(OFFSET_TRIES):
            if not best < k.heading_offset:
                break
            r2 = k.target_scale * xp.sqrt(draw_uniform(base, N_DRAWS + 2 * j, xp))
            b2 = 2.0 * xp.pi * draw_uniform(base, N_DRAWS + 1 + 2 * j, xp) - xp.pi
            x2, y2 = r2 * p.spawn_ax * xp.cos(b2), r2 * p.spawn_ay * xp.sin(b2)
            d = heading_offset(x2, y2, s, trig)
            if d > best:
                tx, ty, best = x2, y2, d
    return tx, ty, cb, sb


RECORD = TaskRecord("reach", ReachTask, constants, reward, target, goal=True)
add_task(RECORD)
