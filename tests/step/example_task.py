"""A task defined outside the package (tests/step/test_tasks.py registers and trains it; docs/extending.md shows it):
reach in a hurry. Reach's reward with a cost per step, and the episode's clock as an observation entry of its
own; targets drawn as reach draws them."""
from dataclasses import dataclass
from typing import NamedTuple

from penny_env import register_task
from penny_env.step.tasks import ReachTask, TaskRecord
from penny_env.step.tasks.reach import ReachConstants
from penny_env.step.tasks.reach import constants as reach_constants
from penny_env.step.tasks.reach import progress
from penny_env.step.tasks.reach import target as reach_target


@dataclass(frozen=True)
class HurryTask(ReachTask):
    """reach's fields, and time_cost: the reward lost per step."""

    kind: str = "hurry"
    time_cost: float = 0.05

    def __post_init__(self):
        super().__post_init__()
        self.set_number("time_cost", nonneg=True)


# what the stages read: reach's constants, then the task's own (ints, floats, bools: they travel packed)
HurryConstants = NamedTuple("HurryConstants", [*ReachConstants.__annotations__.items(), ("time_cost", float),
                                               ("max_steps", int)])


def constants(scene, task, L):
    return HurryConstants(*reach_constants(scene, task, L), task.time_cost, task.max_episode_steps)


def reward(k, before, after, ctrl, n_arc, xp):
    success = after.dist < k.tolerance
    return progress(k, before, after) - k.time_cost - k.ctrl_cost * ctrl + k.success_bonus * success, success


def observation(k, st, obs, i):
    obs[i, 10] = st.steps / k.max_steps  # the episode's clock, in [0, 1]


register_task(TaskRecord("hurry", HurryTask, constants, reward, reach_target, observation, ((0.0, 1.0),)))
