"""Stable-Baselines3 adapter: PennyVectorEnv as an SB3 ``VecEnv`` (SB3 is imported only here).

>>> from stable_baselines3 import PPO
>>> from stable_baselines3.common.vec_env import VecMonitor
>>> from penny_env.sb3 import PennySB3VecEnv
>>> venv = VecMonitor(PennySB3VecEnv("PennyReach-Ellipse-v0", num_envs=16))
>>> model = PPO("MlpPolicy", venv, n_steps=64).learn(2048)   # doctest: +SKIP

SB3 semantics: episodes reset automatically in the step that ends them (the vector env runs in
SAME_STEP autoreset mode); ``infos[i]["terminal_observation"]`` holds the last observation and
``infos[i]["TimeLimit.truncated"]`` is True when the episode was cut by the time limit (not a
success). ``infos[i]["is_success"]`` is set at episode ends. Wrap in ``VecMonitor`` for the
``infos[i]["episode"]`` statistics ({"r", "l", "t"}) that SB3 logs.

Goal-conditioned variant for HER (``goal_env=True``, reach tasks on tables): observations are
dicts ``{"observation": obs, "achieved_goal": (x, y) / L, "desired_goal": (tx, ty) / L}`` read from
the float32 observation (achieved = obs[0:2], desired = obs[0:2] + obs[8:10]), and the reward is the
sparse ``compute_reward(achieved, desired, info) = -(L |achieved - desired| >= tolerance)`` (0 at
the target, -1 elsewhere; vectorised), which SB3's ``HerReplayBuffer`` recomputes for relabelled
goals. Episodes still terminate on the task's success.

Sub-env access (SB3's VecEnv contract, one entry per selected index): the sub-envs of the native
vector env share its scene, task and spaces, so ``get_attr`` answers the shared value for each
index (``observation_space`` / ``action_space``: the single-env spaces; ``states`` / ``targets``:
each env's row); ``set_attr`` on a shared attribute needs every index (a subset raises
ValueError); ``env_method`` calls ``compute_reward`` (goal env) per index, ``render`` gives each
index's frame, other methods act on every sub-env and need every index.
"""
from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env.base_vec_env import VecEnv

from .envs.registration import env_presets
from .envs.vector_env import PennyVectorEnv

__all__ = ["PennySB3VecEnv"]

PER_ENV_ATTRS = ("states", "targets")  # (num_envs, k) arrays: row i belongs to sub-env i


class PennySB3VecEnv(VecEnv):
    """SB3 VecEnv over a native :class:`PennyVectorEnv`.

    ``PennySB3VecEnv(env_id_or_none, num_envs=8, *, goal_env=False, **kwargs)``: a registered id (its
    preset) or None with scene/task/overrides in kwargs, or ``venv=`` an existing PennyVectorEnv in
    SAME_STEP mode (possibly inside gymnasium vector wrappers).
    """

    def __init__(self, env_id: str | None = None, num_envs: int = 8, *, venv: PennyVectorEnv | None = None,
                 goal_env: bool = False, **kwargs):
        if venv is None:
            cfg = dict(env_presets()[env_id]) if env_id is not None else {}
            cfg.update(kwargs)
            venv = PennyVectorEnv(num_envs, autoreset_mode=AutoresetMode.SAME_STEP, **cfg)
        elif venv.unwrapped.autoreset_mode != AutoresetMode.SAME_STEP:
            raise ValueError("PennySB3VecEnv needs a PennyVectorEnv with autoreset_mode=SAME_STEP")
        if not isinstance(goal_env, bool):
            raise TypeError(f"goal_env must be a bool, got {type(goal_env).__name__}")
        self.venv = venv
        core = venv.unwrapped._core
        self.goal_env = goal_env
        obs_space = venv.single_observation_space
        if goal_env:
            from .envs.goal_env import goal_setup
            self._L, self._tol, obs_space = goal_setup(core, obs_space)
        self.render_mode = venv.render_mode
        super().__init__(venv.num_envs, obs_space, venv.single_action_space)
        self._actions = None
        self._seeded = False

    # -- goal env (HER) ------------------------------------------------------------------
    def _goal_obs(self, obs):
        if not self.goal_env:
            return obs
        obs = np.asarray(obs, dtype=np.float32)
        achieved = obs[..., 0:2].copy()
        return {"observation": obs, "achieved_goal": achieved, "desired_goal": achieved + obs[..., 8:10]}

    def compute_reward(self, achieved_goal, desired_goal, info) -> np.ndarray:
        """The goal env's sparse reward, vectorised over leading axes: 0 where the goals are within
        the task's tolerance, -1 elsewhere (float32)."""
        d = np.linalg.norm(np.asarray(achieved_goal, np.float64) - np.asarray(desired_goal, np.float64), axis=-1)
        return -(d * self._L >= self._tol).astype(np.float32)

    # -- SB3 API -------------------------------------------------------------------------
    def reset(self):
        seeds = self._seeds
        if any(s is not None for s in seeds) or not self._seeded:
            obs, _ = self.venv.reset(seed=list(seeds) if any(s is not None for s in seeds) else None)
            self._seeded = True
        else:
            obs, _ = self.venv.reset()
        self._reset_seeds()
        self._reset_options()
        return self._goal_obs(obs)

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self):
        obs, rew, term, trunc, info = self.venv.step(self._actions)
        n = self.num_envs
        dones = term | trunc
        infos: list[dict[str, Any]] = [{} for _ in range(n)]  # SB3's list of dicts (one per env)
        final = info["final_obs"] if dones.any() else None
        if self.goal_env:  # the reward of the observation reached (the final one where an episode ended)
            last = obs.copy()
            for i in np.flatnonzero(dones):
                last[i] = final[i]
            g = self._goal_obs(last)
            rew = self.compute_reward(g["achieved_goal"], g["desired_goal"], infos)
        for i in np.flatnonzero(dones):
            infos[i]["terminal_observation"] = self._goal_obs(final[i])
            infos[i]["TimeLimit.truncated"] = bool(trunc[i] and not term[i])
            infos[i]["is_success"] = bool(term[i])
        return self._goal_obs(obs), rew.astype(np.float32), dones, infos

    def close(self) -> None:
        self.venv.close()

    def _indices(self, indices) -> list[int]:
        return [int(i) for i in self._get_indices(indices)]

    def _needs_every_index(self, idx, what):
        if sorted(set(idx)) != list(range(self.num_envs)):
            raise ValueError(f"PennySB3VecEnv.{what}: the sub-envs of the native vector env share it; "
                             f"select every index (indices=None), got {idx}")

    def get_attr(self, attr_name: str, indices=None) -> list[Any]:
        idx = self._indices(indices)
        if attr_name in ("observation_space", "action_space"):
            return [getattr(self, attr_name) for _ in idx]
        if attr_name == "render_mode":
            return [self.render_mode for _ in idx]
        value = getattr(self.venv.unwrapped, attr_name)
        if attr_name in PER_ENV_ATTRS:
            return [value[i] for i in idx]
        return [value for _ in idx]

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        idx = self._indices(indices)
        if attr_name in PER_ENV_ATTRS:
            raise ValueError(f"PennySB3VecEnv.set_attr: {attr_name!r} cannot be set (use reset options)")
        self._needs_every_index(idx, f"set_attr({attr_name!r})")
        setattr(self.venv.unwrapped, attr_name, value)

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs) -> list[Any]:
        idx = self._indices(indices)
        if method_name == "compute_reward" and self.goal_env:  # a pure function: one answer per index
            return [self.compute_reward(*method_args, **method_kwargs) for _ in idx]
        if method_name == "render":
            frames = self.venv.render(*method_args, **method_kwargs)
            return [None if frames is None else frames[i] for i in idx]
        self._needs_every_index(idx, f"env_method({method_name!r})")
        result = getattr(self.venv.unwrapped, method_name)(*method_args, **method_kwargs)
        return [result for _ in idx]

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        """Whether the vector env is wrapped in (or is) wrapper_class, for each index: the sub-envs
        of the native vector env are not gymnasium Envs and carry no wrappers of their own."""
        env, wrapped = self.venv, False
        while True:
            wrapped = wrapped or isinstance(env, wrapper_class)
            inner = getattr(env, "env", None)
            if inner is None or inner is env:
                break
            env = inner
        return [wrapped for _ in self._indices(indices)]

    def get_images(self):
        frames = self.venv.render()
        return list(frames) if frames is not None else [None] * self.num_envs
