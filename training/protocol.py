"""What every agent of the ladder (studies/ladder.py) provides, and the one evaluation they are all measured by.

An agent is one file in training/ (CleanRL's style: hyperparameters at the top in an ``Args`` dataclass, a
docstring that says what the agent may use) with:

* ``Args``: a dataclass with at least ``env_id: str``, ``env_kwargs: dict`` (field overrides of the id, as
  ``gymnasium.make(env_id, **env_kwargs)``), ``seed: int``, ``total_timesteps: int``, ``torch_threads: int`` and
  ``out: str | None`` (a folder for its files);
* ``train(args, checkpoints=(), on_checkpoint=None, log=print) -> dict``: trains for ``args.total_timesteps`` env
  steps; the first time its env-step count reaches each value of ``checkpoints`` (ascending) and at the end, it
  calls ``on_checkpoint(env_steps, policy)`` with its current deterministic :class:`Policy`; returns a dict of
  results (at least ``env_steps``, ``wall_time_s``, ``steps_per_s``);
* its policies follow :class:`Policy` (below).

Privileged agents (start-state curricula, Go-Explore) also take demonstrations (``Args.demos``: an .npz written by
:func:`save_demos`) or reset their training envs to chosen states (``PennyVectorEnv.reset(options={"state": ...,
"target": ..., "reset_mask": ...})``); they say so in their docstring, and every table labels them.

:func:`evaluate` is the ladder's measure: one deterministic episode per seed of ``seeds`` (the witness study's
pair seeds: env i of a PennyVectorEnv seeded ``seeds[0] + i`` draws what ``gymnasium.make(env_id)`` reset with that
seed draws), success read from the env's own test (``info["is_success"]``), and the impacts of each successful
episode counted up to its success.
"""
from __future__ import annotations

from typing import Protocol

import numpy as np


FAIR_REWARD = {"progress_weight": 0.0, "speed_cost": 0.0, "ctrl_cost": 0.0, "success_bonus": 10.0}


def fair_reward_kwargs(env_id: str, env_kwargs: dict | None = None) -> dict:
    """The fields of FAIR_REWARD (the success bonus only: no progress term, no speed or control cost) that the task of
    ``env_id`` with ``env_kwargs`` has (reach has no speed cost), so every agent trains on the same reward."""
    from penny_env.envs.scene import env_presets, resolve
    fields = {**env_presets()[env_id], **(env_kwargs or {})}  # (a cell's overrides may replace the scene itself)
    _, task = resolve(fields.pop("scene"), fields.pop("task"), **fields)
    return {k: v for k, v in FAIR_REWARD.items() if hasattr(task, k)}


class Policy(Protocol):
    """A deterministic policy for the vector env, possibly with state of its own (an agent's clock, its count of
    impacts, a previous action): ``reset(num_envs)`` before the first step of every env's episode (the evaluation
    runs one episode per env, all starting together), then ``__call__(obs, info) -> actions``: obs (N, obs_dim)
    float32 and the step's info (numpy arrays: ``info["impacts"]`` the impacts of the last step per env; after the
    reset, the reset's info), actions (N, n_act) in [-1, 1]. Envs whose episode has ended keep being called (their
    actions are ignored)."""

    def reset(self, num_envs: int) -> None: ...

    def __call__(self, obs: np.ndarray, info: dict) -> np.ndarray: ...


def evaluate(policy: Policy, env_id: str, env_kwargs: dict | None = None, seeds=range(200),
             backend: str = "auto") -> dict:
    """One deterministic episode of ``policy`` per seed (consecutive seeds: seeds[0] + i), in a PennyVectorEnv with
    autoreset disabled. Returns {"successes", "episodes", "success" (per seed, bool), "impacts_to_success" (per
    seed: impacts up to and including the successful step, -1 where it did not succeed), "steps" (per seed)}."""
    import gymnasium as gym
    from gymnasium.vector import AutoresetMode

    import penny_env  # noqa: F401
    seeds = list(seeds)
    if seeds != list(range(seeds[0], seeds[0] + len(seeds))):
        raise ValueError("seeds must be consecutive (env i is seeded seeds[0] + i)")
    n = len(seeds)
    env = gym.make_vec(env_id, n, vectorization_mode="vector_entry_point", autoreset_mode=AutoresetMode.DISABLED,
                       backend=backend, **dict(env_kwargs or {}))
    obs, info = env.reset(seed=seeds[0])
    policy.reset(n)
    done = np.zeros(n, dtype=bool)
    success = np.zeros(n, dtype=bool)
    impacts = np.zeros(n, dtype=np.int64)
    steps = np.zeros(n, dtype=np.int64)
    to_success = np.full(n, -1, dtype=np.int64)
    while not done.all():
        actions = np.asarray(policy(obs, info), dtype=np.float64).reshape(n, -1)
        obs, reward, terminated, truncated, info = env.step(actions)
        live = ~done
        impacts[live] += np.asarray(info["impacts"])[live]
        steps[live] += 1
        won = live & np.asarray(info["is_success"], dtype=bool)
        success |= won
        to_success[won] = impacts[won]
        done |= live & (np.asarray(terminated) | np.asarray(truncated))
    env.close()
    return {"successes": int(success.sum()), "episodes": n, "success": success.tolist(),
            "impacts_to_success": to_success.tolist(), "steps": steps.tolist()}


def save_demos(path, episodes) -> None:
    """Demonstrations for privileged agents as one .npz: ``episodes`` a list of (states (T+1, 6), target (2,), actions
    (T, n_act)) of successful episodes (state t is the one before action t); stored as ``states`` (M, 6),
    ``targets`` (M, 2), ``episode`` (M,), ``step`` (M,), ``length`` (E,) and ``actions`` (M - E, n_act).
    No episodes (a cell with no witness, such as the plane) is stored as empty arrays: :func:`no_demos`."""
    if not episodes:
        np.savez(path, **no_demos())
        return
    states = np.concatenate([np.asarray(s, float) for s, _, _ in episodes])
    targets = np.concatenate([np.repeat(np.asarray(t, float)[None], len(s), 0) for s, t, _ in episodes])
    episode = np.concatenate([np.full(len(s), j) for j, (s, _, _) in enumerate(episodes)])
    step = np.concatenate([np.arange(len(s)) for s, _, _ in episodes])
    length = np.array([len(s) - 1 for s, _, _ in episodes])
    actions = np.concatenate([np.asarray(a, float).reshape(len(s) - 1, -1) for s, _, a in episodes])
    np.savez(path, states=states, targets=targets, episode=episode, step=step, length=length, actions=actions)


def no_demos() -> dict:
    """The arrays of :func:`save_demos` for no episode (a privileged agent then starts from the task's own draws)."""
    return {"states": np.zeros((0, 6)), "targets": np.zeros((0, 2)), "episode": np.zeros(0, np.int64),
            "step": np.zeros(0, np.int64), "length": np.zeros(0, np.int64), "actions": np.zeros((0, 1))}


def load_demos(path) -> dict:
    """The arrays of :func:`save_demos`."""
    with np.load(path) as z:
        return {k: z[k] for k in z.files}
