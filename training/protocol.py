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
    """The fields of FAIR_REWARD (the success bonus only: studies/fair_pure_rl.py's reward) that the task of
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


def cli(prog: str, args_class, train, argv=None, quick_args=None) -> dict:
    """The command line every ladder agent shares (``python -m training.<agent>``):

        --env-id ID  --total-timesteps N  --seed K  --set FIELD=VALUE ...  --hp NAME=VALUE ...  [--demos NPZ]
        [--quick] [--eval] [--out DIR]

    ``--set``: the env's fields (YAML values, as ``gymnasium.make(id, **fields)``); ``--hp``: fields of the agent's
    ``Args`` (YAML values, an unknown name refused); ``--quick``: the agent's ``quick_args`` (seconds; learns
    nothing); ``--eval``: :func:`evaluate` of the final policy on the pair seeds 0..199. The env's numba threads
    default to 1 (NUMBA_NUM_THREADS; ``--hp torch_threads=N`` sets torch's). With ``--out`` the results (and the
    agent's state, where ``train`` returns it as ``agent``, ``actor`` or ``state``) are written there, in
    ``results.json`` beside what ``train`` wrote itself. Returns ``train``'s dict, with ``eval`` after --eval."""
    import argparse
    import dataclasses
    import json
    import os
    import sys
    from pathlib import Path

    import yaml
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")
    fields = {f.name for f in dataclasses.fields(args_class)}
    ap = argparse.ArgumentParser(prog=f"python -m {prog}")
    ap.add_argument("--env-id", default=args_class.env_id)
    ap.add_argument("--total-timesteps", type=float, default=None, help="env steps (default: the agent's)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--set", nargs="*", default=[], metavar="FIELD=VALUE", help="env field overrides (YAML values)")
    ap.add_argument("--hp", nargs="*", default=[], metavar="NAME=VALUE", help="fields of the agent's Args (YAML values)")
    if "demos" in fields:
        ap.add_argument("--demos", default=None, help="demonstrations (.npz of training.protocol.save_demos)")
    ap.add_argument("--quick", action="store_true", help="a few seconds: checks the pipeline, learns nothing")
    ap.add_argument("--eval", action="store_true", help="evaluate the final policy on the pair seeds 0..199")
    ap.add_argument("--out", default=None)
    a = ap.parse_args(list(sys.argv[1:] if argv is None else argv))

    def pairs(items, flag):
        out = {}
        for item in items:
            if "=" not in item:
                ap.error(f"{flag}: expected NAME=VALUE, got {item!r}")
            name, value = item.split("=", 1)
            out[name] = yaml.safe_load(value)
        return out
    hp = pairs(a.hp, "--hp")
    unknown = sorted(set(hp) - fields)
    if unknown:
        ap.error(f"--hp: {unknown} are not fields of {prog}.Args; fields: {sorted(fields)}")
    given = {"env_id": a.env_id, "env_kwargs": pairs(a.set, "--set"), "seed": a.seed, "out": a.out}
    if a.total_timesteps is not None:
        given["total_timesteps"] = int(a.total_timesteps)
    if getattr(a, "demos", None) is not None:
        given["demos"] = a.demos
    args = dataclasses.replace(args_class(), **given, **hp)
    if a.quick:
        if quick_args is None:
            ap.error(f"{prog} has no --quick mode")
        args = quick_args(args)
    final = []
    res = train(args, on_checkpoint=lambda steps, policy: final.append(policy), log=lambda s: print(s, flush=True))
    res = dict(res or {})
    if a.eval:
        ev = evaluate(final[-1], args.env_id, args.env_kwargs)
        res["eval"] = {"successes": ev["successes"], "episodes": ev["episodes"]}
        print(f"[{prog}] evaluation (seeds 0..199, deterministic): {ev['successes']}/{ev['episodes']}", flush=True)
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        state = next((res.pop(k) for k in ("agent", "actor", "state") if k in res), None)
        if state is not None:
            import torch
            torch.save(state, out / "agent.pt")
        path = out / "results.json"
        before = json.loads(path.read_text()) if path.is_file() else {}
        plain = {k: v for k, v in res.items() if k != "policy"}
        path.write_text(json.dumps({**before, **plain, "args": dataclasses.asdict(args)}, default=str, indent=1))
    return res
