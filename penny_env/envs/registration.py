"""Registration of the env ids listed in penny_env/presets/envs.yaml (done by ``import penny_env``).

``gymnasium.make(id)`` wraps the env in gymnasium's TimeLimit (the id's max_episode_steps, or the
``max_episode_steps=N`` given to make): the registered entry point builds PennyEnv with
``truncate=False`` so that TimeLimit alone ends episodes by time, and N is honoured both ways.
``gymnasium.make_vec(id, num_envs, max_episode_steps=N)`` passes N to PennyVectorEnv.

In worker processes started with "spawn" or "forkserver" (SB3's SubprocVecEnv, gymnasium's
AsyncVectorEnv with ``context="spawn"``), ``gymnasium.make("PennyReach-Ellipse-v0")`` finds no id
unless penny_env was imported there: gymnasium 1.x loads no plugins. Use :func:`make_env` (a
picklable factory whose unpickling imports penny_env) or the module-prefixed id
``"penny_env:PennyReach-Ellipse-v0"``, which makes gymnasium import penny_env first.
"""
from __future__ import annotations

from .scene import env_presets, preset_dict

ENTRY_POINT = "penny_env.envs.registration:make_registered_env"
VECTOR_ENTRY_POINT = "penny_env.envs.vector_env:PennyVectorEnv"


def make_registered_env(goal_env: bool = False, **kwargs):
    """The entry point of the registered ids: PennyEnv(**kwargs) without its own time limit
    (gymnasium's TimeLimit, applied by make, truncates). goal_env=True: PennyGoalEnv, the reach task
    with dict observations and compute_reward (Gymnasium-Robotics' GoalEnv convention, for HER)."""
    if not isinstance(goal_env, bool):
        raise TypeError(f"goal_env must be a bool, got {type(goal_env).__name__}")
    if goal_env:
        from .goal_env import PennyGoalEnv
        return PennyGoalEnv(truncate=False, **kwargs)
    from .penny_env import PennyEnv
    return PennyEnv(truncate=False, **kwargs)


def make_env(env_id: str, wrapper=None, **kwargs):
    """A picklable factory of the env `env_id` (``gymnasium.make(env_id, **kwargs)``, then
    ``wrapper(env)`` if given) for worker processes: calling it in a process started by spawn or
    forkserver imports penny_env there first (the factory's function lives in this package), so
    plain ids work where gymnasium alone would raise NameNotFound. For example
    ``SubprocVecEnv([penny_env.make_env(id) for _ in range(4)])``,
    ``make_vec_env(penny_env.make_env(id), n_envs=4, vec_env_cls=SubprocVecEnv)``,
    ``AsyncVectorEnv([penny_env.make_env(id)] * 4, context="spawn")`` or TorchRL's
    ``ParallelEnv(2, penny_env.make_env(id, wrapper=GymWrapper))``. wrapper: a picklable callable
    (a class or a module-level function). An id that is not registered raises here, in the caller's
    process, naming it."""
    import functools
    from gymnasium.envs.registration import registry
    if not isinstance(env_id, str):
        raise TypeError(f"env_id must be a str, got {type(env_id).__name__}")
    name = env_id.split(":", 1)[-1]
    if name not in registry:
        raise ValueError(f"env_id {env_id!r} is not registered; penny_env's ids: {env_ids()}")
    if wrapper is not None and not callable(wrapper):
        raise TypeError(f"wrapper must be callable, got {type(wrapper).__name__}")
    return functools.partial(_make_in_this_process, name, wrapper, kwargs)


def _make_in_this_process(env_id, wrapper, kwargs):
    """make_env's factory body (module level, so that it pickles by reference and its unpickling
    imports penny_env, which registers the ids)."""
    import gymnasium as gym
    env = gym.make(env_id, **kwargs)
    return env if wrapper is None else wrapper(env)


def env_ids() -> list[str]:
    """The registered ids, in penny_env/presets/envs.yaml order."""
    return list(env_presets())


def register_envs() -> list[str]:
    """Register every id of penny_env/presets/envs.yaml with gymnasium (idempotent)."""
    from gymnasium.envs.registration import register, registry

    ids = []
    for env_id, kwargs in env_presets().items():
        kwargs = dict(kwargs)
        task = preset_dict("task", kwargs.get("task", "reach"))
        steps = kwargs.get("max_episode_steps", task.get("max_episode_steps", 400))
        if env_id not in registry:
            register(id=env_id, entry_point=ENTRY_POINT, vector_entry_point=VECTOR_ENTRY_POINT,
                     max_episode_steps=steps, kwargs=kwargs)
        ids.append(env_id)
    return ids
