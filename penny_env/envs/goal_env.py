"""PennyGoalEnv: a goal task (reach; any task whose record says goal=True) as a goal-conditioned env
(Gymnasium-Robotics' GoalEnv convention), what ``gymnasium.make(id, goal_env=True)`` builds; the vector counterpart
is ``penny_env.sb3.PennySB3VecEnv(id, goal_env=True)``, with the same observations and rewards."""
from __future__ import annotations

import numpy as np
from gymnasium import spaces

from .penny_env import PennyEnv


def goal_setup(core, obs_space):
    """(L, tolerance, the dict observation space) of a goal env on ``core``'s task (TaskRecord.goal) and table, the
    single env's and the SB3 adapter's; ValueError naming the task otherwise."""
    if not core.task_record.goal or core.plane:
        raise ValueError(f"goal_env=True needs a goal task (a reach task on a table, or a task registered with "
                         f"goal=True on one), got task {core.task.kind!r} on "
                         f"{'the open plane' if core.plane else 'a table'}")
    goal = spaces.Box(-2.0, 2.0, (2,), np.float32)
    return float(core.L), float(core.task.tolerance), spaces.Dict({"observation": obs_space, "achieved_goal": goal,
                                                                    "desired_goal": goal})


class PennyGoalEnv(PennyEnv):
    """PennyEnv (a goal task on a table: TaskRecord.goal, the reach task's) with dict observations ``{"observation": obs,
    "achieved_goal": (x, y) / L, "desired_goal": (tx, ty) / L}`` (read from the float32 observation:
    achieved = obs[0:2], desired = obs[0:2] + obs[8:10]) and the sparse reward
    ``compute_reward(achieved_goal, desired_goal, info) = -(L |achieved - desired| >= tolerance)``
    (0 at the target, -1 elsewhere), vectorised over leading axes, which SB3's HerReplayBuffer (through
    ``env_method``) and Gymnasium-Robotics-style code (``env.unwrapped.compute_reward``) recompute for
    relabelled goals. Episodes still terminate on the task's success; everything else is PennyEnv's."""

    def _setup(self):
        super()._setup()
        self._L, self._tol, self.observation_space = goal_setup(self._core, self.observation_space)

    @staticmethod
    def _goal_obs(obs):
        achieved = obs[0:2].copy()
        return {"observation": obs, "achieved_goal": achieved, "desired_goal": achieved + obs[8:10]}

    def compute_reward(self, achieved_goal, desired_goal, info) -> np.ndarray:
        """0 where the goals are within the task's tolerance, -1 elsewhere (float32; leading axes kept)."""
        d = np.linalg.norm(np.asarray(achieved_goal, np.float64) - np.asarray(desired_goal, np.float64), axis=-1)
        return -(d * self._L >= self._tol).astype(np.float32)

    def reset(self, *, seed=None, options=None):
        obs, info = super().reset(seed=seed, options=options)
        return self._goal_obs(obs), info

    def step(self, action):
        obs, _, terminated, truncated, info = super().step(action)
        g = self._goal_obs(obs)
        return g, float(self.compute_reward(g["achieved_goal"], g["desired_goal"], info)), terminated, truncated, info
