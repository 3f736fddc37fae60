"""Evaluation episodes of a policy on an env id, with what training.evaluate measures per episode."""
from __future__ import annotations

import numpy as np


def make_vector_env(env_id: str, num_envs: int, **overrides):
    """A PennyVectorEnv of a registered id (its preset, with scene/task field overrides)."""
    import penny_env  # noqa: F401
    from penny_env.envs import PennyVectorEnv
    from penny_env.envs.scene import env_presets
    presets = env_presets()
    if env_id not in presets:
        raise ValueError(f"unknown env id {env_id!r}; registered: {sorted(presets)}")
    return PennyVectorEnv(num_envs, **{**presets[env_id], **overrides})


def run_episodes(env_id: str, policy, episodes: int, seed: int, options=None, **overrides) -> dict:
    """One episode in each of `episodes` sub-envs seeded seed, seed + 1, ...: per episode
    success (info["is_success"]), steps, time [s], return and impacts (all impacts, any wall).
    options: reset options ({"state": (episodes, 6), "target": (episodes, 2)}: given start/target pairs);
    overrides: scene/task fields (e.g. spin_tolerance=None)."""
    venv = make_vector_env(env_id, episodes, **overrides)
    obs, _ = venv.reset(seed=seed, options=options)
    n = episodes
    alive = np.ones(n, bool)
    success = np.zeros(n, bool)
    steps = np.zeros(n, int)
    ret = np.zeros(n)
    impacts = np.zeros(n, int)
    while alive.any():
        obs, rew, term, trunc, info = venv.step(policy(obs))
        ret += np.where(alive, rew, 0.0)
        steps += alive
        impacts += np.where(alive, info["impacts"], 0)
        ended = alive & (term | trunc)
        if ended.any():
            success[ended] = np.asarray(info["is_success"])[ended]
            alive &= ~ended
    dt = venv.scene.control_dt
    venv.close()
    return {"success": success.tolist(), "steps": steps.tolist(), "time": (steps * dt).tolist(),
            "return": ret.tolist(), "impacts": impacts.tolist()}
