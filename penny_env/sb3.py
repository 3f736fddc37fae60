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
"""
from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env.base_vec_env import VecEnv

from .envs.registration import env_presets
from .envs.vector_env import PennyVectorEnv

__all__ = ["PennySB3VecEnv"]


class PennySB3VecEnv(VecEnv):
    """SB3 VecEnv over a native :class:`PennyVectorEnv`.

    ``PennySB3VecEnv(env_id_or_none, num_envs=8, **kwargs)``: a registered id (its preset) or None
    with scene/task/overrides in kwargs, or ``venv=`` an existing PennyVectorEnv in SAME_STEP mode.
    """

    def __init__(self, env_id: str | None = None, num_envs: int = 8, *, venv: PennyVectorEnv | None = None, **kwargs):
        if venv is None:
            cfg = dict(env_presets()[env_id]) if env_id is not None else {}
            cfg.update(kwargs)
            venv = PennyVectorEnv(num_envs, autoreset_mode=AutoresetMode.SAME_STEP, **cfg)
        elif venv.autoreset_mode != AutoresetMode.SAME_STEP:
            raise ValueError("PennySB3VecEnv needs a PennyVectorEnv with autoreset_mode=SAME_STEP")
        self.venv = venv
        self.render_mode = venv.render_mode
        super().__init__(venv.num_envs, venv.single_observation_space, venv.single_action_space)
        self._actions = None
        self._seeded = False

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
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self):
        obs, rew, term, trunc, info = self.venv.step(self._actions)
        n = self.num_envs
        dones = term | trunc
        infos: list[dict[str, Any]] = [{} for _ in range(n)]  # SB3's list of dicts (one per env)
        if dones.any():
            final = info["final_obs"]
            for i in np.flatnonzero(dones):
                infos[i]["terminal_observation"] = final[i]
                infos[i]["TimeLimit.truncated"] = bool(trunc[i] and not term[i])
                infos[i]["is_success"] = bool(term[i])
        return obs, rew.astype(np.float32), dones, infos

    def close(self) -> None:
        self.venv.close()

    def get_attr(self, attr_name: str, indices=None) -> list[Any]:
        idx = list(self._get_indices(indices))
        if attr_name == "render_mode":
            return [self.venv.render_mode for _ in idx]
        value = getattr(self.venv, attr_name)
        return [value for _ in idx]

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        setattr(self.venv, attr_name, value)

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs) -> list[Any]:
        idx = list(self._get_indices(indices))
        result = getattr(self.venv, method_name)(*method_args, **method_kwargs)
        return [result for _ in idx]

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]

    def get_images(self):
        frames = self.venv.render()
        return list(frames) if frames is not None else [None] * self.num_envs
