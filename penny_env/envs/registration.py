"""Registration of the env ids listed in penny_env/presets/envs.yaml (done by ``import penny_env``).

``gymnasium.make(id)`` wraps the env in gymnasium's TimeLimit (the id's max_episode_steps, or the
``max_episode_steps=N`` given to make): the registered entry point builds PennyEnv with
``truncate=False`` so that TimeLimit alone ends episodes by time, and N is honoured both ways.
``gymnasium.make_vec(id, num_envs, max_episode_steps=N)`` passes N to PennyVectorEnv.

In worker processes started with "spawn" or "forkserver" (SB3's SubprocVecEnv, gymnasium's
AsyncVectorEnv with ``context="spawn"``), ``gymnasium.make("PennyReach-Ellipse-v0")`` finds no id
unless penny_env was imported there: gymnasium 1.x loads no plugins. Use the module-prefixed id
``"penny_env:PennyReach-Ellipse-v0"``, which makes gymnasium import penny_env first.
"""
from __future__ import annotations

from .scene import _preset, env_presets

ENTRY_POINT = "penny_env.envs.registration:make_registered_env"
VECTOR_ENTRY_POINT = "penny_env.envs.vector_env:PennyVectorEnv"


def make_registered_env(**kwargs):
    """The entry point of the registered ids: PennyEnv(**kwargs) without its own time limit
    (gymnasium's TimeLimit, applied by make, truncates)."""
    from .penny_env import PennyEnv
    return PennyEnv(truncate=False, **kwargs)


def env_ids() -> list[str]:
    """The registered ids, in penny_env/presets/envs.yaml order."""
    return list(env_presets())


def register_envs() -> list[str]:
    """Register every id of penny_env/presets/envs.yaml with gymnasium (idempotent)."""
    from gymnasium.envs.registration import register, registry

    ids = []
    for env_id, kwargs in env_presets().items():
        kwargs = dict(kwargs)
        task = _preset("task", kwargs.get("task", "reach"))
        steps = kwargs.get("max_episode_steps", task.get("max_episode_steps", 400))
        if env_id not in registry:
            register(id=env_id, entry_point=ENTRY_POINT, vector_entry_point=VECTOR_ENTRY_POINT,
                     max_episode_steps=steps, kwargs=kwargs)
        ids.append(env_id)
    return ids
