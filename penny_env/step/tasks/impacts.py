"""The impacts task: hit a marked arc of the wall (centred on a direction drawn each episode) impacts_goal
times.

reward per step: impact_reward n_arc - ctrl_cost ctrl + success_bonus [count >= impacts_goal]; n_arc: the
step's impacts whose impact point p satisfies p . (cos b, sin b) >= cos(arc_half_width) |p| (b: the arc's
centre direction); with arc_half_width >= pi every impact counts. Observation entry 10: min(count / goal, 1).
The "target" is the wall point at the arc's centre."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

from ...physics.scalar import WHOLE_WALL, wall_distance
from ..config import count
from ..draws import draw_uniform
from .base import Task, TaskRecord, add_task


@dataclass(frozen=True)
class ImpactsTask(Task):
    """impacts.

    impact_reward:   reward per impact on the marked arc
    arc_half_width:  [rad] half-width of the marked arc (polar angle of the impact point about the
                     table's centre); >= pi marks the whole wall
    impacts_goal:    success after this many impacts on the arc
    """

    kind: str = "impacts"
    impact_reward: float = 1.0
    arc_half_width: float = 0.5
    impacts_goal: int = 10

    def __post_init__(self):
        super().__post_init__()
        self.set_number("impact_reward", nonneg=True)
        self.set_number("arc_half_width", positive=True)
        object.__setattr__(self, "impacts_goal", count("task", "impacts_goal", self.impacts_goal))


class ImpactsConstants(NamedTuple):
    impact_reward: float
    ctrl_cost: float
    success_bonus: float
    goal: int
    whole_wall: bool         # arc_half_width >= pi: every impact counts
    cos_half_width: float


def constants(scene, task, L) -> ImpactsConstants:
    return ImpactsConstants(task.impact_reward, task.ctrl_cost, task.success_bonus, task.impacts_goal,
                            bool(task.arc_half_width >= math.pi), math.cos(min(task.arc_half_width, math.pi)))


def reward(k, before, after, ctrl, n_arc, xp):
    success = after.count >= k.goal
    return k.impact_reward * n_arc - k.ctrl_cost * ctrl + k.success_bonus * success, success


def target(k, p, m, s, trig, base, xp):
    """The wall point in the arc's direction (draw 7)."""
    b = 2.0 * xp.pi * draw_uniform(base, 7, xp) - xp.pi
    cb, sb = xp.cos(b), xp.sin(b)
    rho = wall_distance(m, cb, sb)
    return rho * cb, rho * sb, cb, sb


def observation(k, st, obs, i):
    obs[i, 10] = min(st.count / k.goal, 1.0)


def marked_arc(k, st):
    if k.whole_wall:
        return (st.arc[0], st.arc[1], WHOLE_WALL[1])
    return (st.arc[0], st.arc[1], k.cos_half_width)


RECORD = TaskRecord("impacts", ImpactsTask, constants, reward, target, observation, ((0.0, 1.0),), marked_arc,
                    needs_walls=True)
add_task(RECORD)
