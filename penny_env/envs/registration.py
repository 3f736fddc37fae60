"""Registration of the env ids listed in penny_env/presets/envs.yaml (done by ``import penny_env``)."""
from __future__ import annotations

from .scene import _preset, env_presets

ENTRY_POINT = "penny_env.envs.penny_env:PennyEnv"
VECTOR_ENTRY_POINT = "penny_env.envs.vector_env:PennyVectorEnv"


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
