"""The park task: reach the target and come to rest there.

reward per step: progress_weight (d_prev - d) / L - speed_cost v / v_ref [d < 2 tolerance]
- ctrl_cost ctrl + success_bonus [success], with v = |R theta_dot| and v_ref = R obs_scale.theta_dot;
success (terminates): d < tolerance and v < speed_tolerance (and |phi_dot| < spin_tolerance where set).
Targets are drawn as the reach task's."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

from .reach import ReachTask, progress, target as reach_target
from .reach import constants as reach_constants
from .base import TaskRecord, add_task


DEFAULT_SPEED_TOLERANCE = 0.01  # [m/s] park's rest speed; controllers of other tasks use it as their rest speed too


def rest_speed(task) -> float:
    """[m/s] The rolling speed under which the penny counts as at rest for a task: park's speed_tolerance, else
    DEFAULT_SPEED_TOLERANCE (the witnesses' controllers switch modes on it whatever the task)."""
    return float(getattr(task, "speed_tolerance", DEFAULT_SPEED_TOLERANCE))


@dataclass(frozen=True)
class ParkTask(ReachTask):
    """park: reach's fields and

    speed_tolerance:  [m/s] rolling speed |R theta_dot| below this counts as at rest
    spin_tolerance:   [rad/s] and the turning rate |phi_dot| below this (None: not checked)
    speed_cost:       weight of the speed penalty |R theta_dot| / (R obs_scale.theta_dot) near the target
    """

    kind: str = "park"
    speed_tolerance: float = DEFAULT_SPEED_TOLERANCE
    spin_tolerance: float | None = None
    speed_cost: float = 0.1

    def __post_init__(self):
        super().__post_init__()
        self.set_number("speed_tolerance", positive=True)
        if self.spin_tolerance is not None:
            self.set_number("spin_tolerance", positive=True)
        self.set_number("speed_cost", nonneg=True)


class ParkConstants(NamedTuple):
    length_scale: float
    tolerance: float
    progress_weight: float
    ctrl_cost: float
    success_bonus: float
    target_scale: float
    heading_offset: float
    near: float              # 2 tolerance: the speed penalty applies within it
    speed_tolerance: float
    spin_tolerance: float    # inf: not checked
    speed_cost: float
    R: float
    reference_speed: float   # R obs_scale.theta_dot


def constants(scene, task, L) -> ParkConstants:
    R = scene.params["R"]
    return ParkConstants(*reach_constants(scene, task, L), 2.0 * task.tolerance, task.speed_tolerance,
                         math.inf if task.spin_tolerance is None else task.spin_tolerance, task.speed_cost, float(R),
                         R * scene.obs_scale["theta_dot"])


def reward(k, before, after, ctrl, n_arc, xp):
    d = after.dist
    v = xp.abs(k.R * after.s[4])
    success = (d < k.tolerance) & (v < k.speed_tolerance) & (xp.abs(after.s[5]) < k.spin_tolerance)
    r = (progress(k, before, after) - k.speed_cost * (v / k.reference_speed) * (d < k.near)
         - k.ctrl_cost * ctrl + k.success_bonus * success)
    return r, success


RECORD = TaskRecord("park", ParkTask, constants, reward, reach_target)
add_task(RECORD)
