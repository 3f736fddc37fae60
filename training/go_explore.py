"""go_explore (PRIVILEGED): Go-Explore (Ecoffet et al., "First return, then explore", Nature 590, 2021) over
penny_env's native vector env: an archive of cells per start/target pair, return to a cell by resetting the env to
its stored state, explore from it, then robustify a policy from the archive's successful trajectories with the
backward start-state curriculum of training/start_curriculum.py.

    python -m training.go_explore --env-id PennyProbeSteer-Stadium-Elastic-v0 [--total-timesteps 5e6] [--seed 0]
                                  [--set FIELD=VALUE ...] [--hp NAME=VALUE ...] [--quick] [--eval] [--out DIR]

**Privileged, in training only.** The exploration phase reads the env's state and target (the cells are made of
them) and resets envs to stored states (``PennyVectorEnv.reset(options={"state", "target", "reset_mask"})``): the
env is deterministic and can start anywhere, so "return" is free. The robustified policy sees only the observation,
``info["impacts"]`` and its own clock (start_curriculum's policy), and is evaluated from the task's own starts.
Every table labels it PRIVILEGED. The pairs are the task's own start/target draws of training seeds from
20,000,000 (never the evaluation's 0..199 or the validation's 50,000..).

**Phase 1, explore** (``explore_steps`` env steps, counted in the budget). Per pair an archive of cells keyed by
(the target's offset from the contact point in bins of ``pos_bin`` [m], the heading in 8 bins, the rolling speed
and the turning rate in a few bins: park |R theta_dot| / speed_tolerance in [0, 0.5, 1, 2, 4, inf) and |phi_dot| /
spin_tolerance in [0, 1, inf); reach |R theta_dot| in [0, 0.02, 0.1, inf) m/s and |phi_dot| in [0, 0.1, 1, 3, inf)
rad/s); a cell keeps the earliest (lowest clock) state that reached it, with the trajectory to it (parent node and
the segment's actions). Each env: pick an unsolved pair uniformly, a cell of its archive with weight 1 /
sqrt(1 + times chosen), reset to the cell's state, then explore for ``segment`` steps (or to the time limit) with
random commands through the agent's action head (a heading, or a rolling speed, uniform, held for a geometric
number of steps of mean 1 / p_switch). A success closes its pair: the trajectory from the pair's start is replayed
(certified: the replay must end in success at the same step) and kept.

**Phase 2, robustify** (the rest of the budget): start_curriculum.train with the kept trajectories as its
demonstrations (the 20 % rule, moving each start back to the pair's real start, then the task's own starts).

**Recommended.** 5e6 env steps per seed: 1e6 to explore (400 pairs, 1024 envs, segments of 20 steps), 4e6 to
robustify with start_curriculum's defaults.
"""
from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass

import numpy as np
import torch

from . import agent_side as A
from . import start_curriculum as SC
from .protocol import no_demos

GO_SEED_MIN = 20_000_000


@dataclass
class Args:
    env_id: str = "PennyProbeSteer-Stadium-Elastic-v0"
    env_kwargs: dict = dataclasses.field(default_factory=dict)
    seed: int = 0
    total_timesteps: int = 5_000_000
    torch_threads: int = 1
    out: str | None = None
    explore_steps: int = 1_000_000
    pairs: int = 400
    num_envs: int = 1024
    segment: int = 20
    p_switch: float = 0.1
    pos_bin: float = 0.02
    go_seed: int = GO_SEED_MIN
    head: str = "pd"
    curriculum: dict = dataclasses.field(default_factory=dict)  # start_curriculum.Args fields for phase 2
    val_every: int = 0
    val_episodes: int = 200
    val_seed: int = 50_000


class Archive:
    """Nodes (state, target, clock, impacts, parent, the actions from the parent) and per pair the cells' nodes."""

    def __init__(self, n_pairs):
        self.state, self.clock, self.imp, self.parent, self.actions, self.pair = [], [], [], [], [], []
        self.cells = [dict() for _ in range(n_pairs)]   # per pair: cell key -> node
        self.keys = [[] for _ in range(n_pairs)]        # per pair: cell keys in order of discovery
        self.chosen = [dict() for _ in range(n_pairs)]  # per pair: cell key -> times chosen

    def node(self, state, clock, imp, parent, actions, pair) -> int:
        self.state.append(np.array(state))
        self.clock.append(int(clock))
        self.imp.append(int(imp))
        self.parent.append(int(parent))
        self.actions.append(np.array(actions))
        self.pair.append(int(pair))
        return len(self.state) - 1

    def offer(self, pair, key, state, clock, imp, parent, actions) -> bool:
        """Keep the state as the cell's if the cell is new or reached earlier than before."""
        cell = self.cells[pair]
        old = cell.get(key)
        if old is not None and self.clock[old] <= clock:
            return False
        cell[key] = self.node(state, clock, imp, parent, actions, pair)
        if old is None:
            self.keys[pair].append(key)
            self.chosen[pair][key] = 0
        return True

    def choose(self, pair, rng) -> int:
        keys = self.keys[pair]
        w = 1.0 / np.sqrt(1.0 + np.array([self.chosen[pair][c] for c in keys]))
        c = keys[rng.choice(len(keys), p=w / w.sum())]
        self.chosen[pair][c] += 1
        return self.cells[pair][c]

    def actions_to(self, node) -> np.ndarray:
        """The actions from the pair's start to the node."""
        parts = []
        while node >= 0:
            parts.append(self.actions[node])
            node = self.parent[node]
        return np.concatenate(parts[::-1]) if parts else np.zeros((0, 1))

    def size(self) -> int:
        return sum(len(c) for c in self.cells)


def cell_keys(S, targets, k: A.TaskConsts, pos_bin):
    """(N, 5) int cell coordinates of states S (N, 6) and targets (N, 2) (module docstring)."""
    dx = np.floor((targets[:, 0] - S[:, 0]) / pos_bin)
    dy = np.floor((targets[:, 1] - S[:, 1]) / pos_bin)
    head = np.floor((np.mod(S[:, 3], 2 * np.pi)) / (np.pi / 4)) % 8
    v, w = np.abs(k.R * S[:, 4]), np.abs(S[:, 5])
    if k.park:
        vb = np.searchsorted(np.array([0.5, 1, 2, 4]) * k.vtol, v, side="right")
        wb = np.searchsorted(np.array([1.0]) * (k.wtol if math.isfinite(k.wtol) else 0.5), w, side="right")
    else:
        vb = np.searchsorted(np.array([0.02, 0.1]), v, side="right")
        wb = np.searchsorted(np.array([0.1, 1.0, 3.0]), w, side="right")
    return np.stack([dx, dy, head, vb, wb], 1).astype(np.int64)


def explore(args: Args, log=print):
    """Phase 1. Returns (archive, solved {pair: node}, pairs' (states, targets), env steps, stats)."""
    rng = np.random.default_rng(args.seed)
    N = args.num_envs
    vec = A.make_vec(args.env_id, max(args.pairs, 1), args.env_kwargs)
    vec.reset(seed=args.go_seed + 1_000_000 * args.seed)
    S0, G0 = vec.states, vec.targets
    vec.close()
    vec = A.make_vec(args.env_id, N, args.env_kwargs)
    k = A.TaskConsts.of(vec)
    n_out = A.head_dim(k, args.head)
    arch = Archive(args.pairs)
    keys0 = cell_keys(S0, G0, k, args.pos_bin)
    for p in range(args.pairs):
        arch.offer(p, tuple(keys0[p]), S0[p], 0, 0, -1, np.zeros((0, vec.single_action_space.shape[0])))
    solved = {}
    n_act = vec.single_action_space.shape[0]
    seg = np.zeros((N, args.segment, n_act))
    seg_len = np.zeros(N, np.int64)
    start_node = np.zeros(N, np.int64)
    pair_of = np.zeros(N, np.int64)
    clock = np.zeros(N, np.int64)
    imp = np.zeros(N, np.int64)
    cmd = torch.zeros(N, n_out)
    fresh = np.ones(N, bool)  # envs just returned to a cell: a new command
    vec.reset(seed=args.go_seed + 1_000_000 * args.seed + 500_000)

    def go(rows):
        """Return: each env of `rows` picks an unsolved pair and a cell and is reset to the cell's state; the reset's
        observation of every env, or None when every pair is solved."""
        open_ = np.array([p for p in range(args.pairs) if p not in solved])
        if not len(open_):
            return None
        S = np.tile(S0[open_[0]], (N, 1))
        G = np.tile(G0[open_[0]], (N, 1))
        for i in rows:
            p = int(open_[rng.integers(len(open_))])
            node = arch.choose(p, rng)
            pair_of[i], start_node[i] = p, node
            S[i], G[i] = arch.state[node], G0[p]
            clock[i], imp[i] = arch.clock[node], arch.imp[node]
        seg_len[rows] = 0
        fresh[rows] = True
        mask = np.zeros(N, bool)
        mask[rows] = True
        return vec.reset(options={"state": S, "target": G, "reset_mask": mask})[0]

    obs = go(np.arange(N))
    steps = 0
    t0 = time.perf_counter()
    last_log = 0
    while obs is not None and steps < args.explore_steps:
        switch = torch.as_tensor((rng.random(N) < args.p_switch) | fresh)
        fresh[:] = False
        cmd[switch] = torch.rand(int(switch.sum()), n_out) * 2 - 1
        act = A.to_env(torch.tensor(obs), cmd, k, args.head).numpy().astype(np.float64)
        obs, _, term, trunc, info = vec.step(act)
        steps += N
        seg[np.arange(N), seg_len] = act
        seg_len += 1
        clock += 1
        imp += np.asarray(info["impacts"])
        S, G = vec.states, vec.targets
        term = np.asarray(term, bool)
        won = term & np.asarray(info["is_success"], bool)
        keys = cell_keys(S, G, k, args.pos_bin)
        ended = term | np.asarray(trunc, bool) | (clock >= k.max_steps) | (seg_len >= args.segment)
        for i in range(N):
            p = int(pair_of[i])
            if p in solved:
                continue
            if won[i]:
                solved[p] = arch.node(S[i], clock[i], imp[i], start_node[i], seg[i, :seg_len[i]], p)
                continue
            if not term[i] and clock[i] < k.max_steps:
                node_key = tuple(keys[i])
                if arch.offer(p, node_key, S[i], clock[i], imp[i], start_node[i], seg[i, :seg_len[i]]):
                    # the env goes on from the new node: its segment restarts there
                    start_node[i] = arch.cells[p][node_key]
                    seg_len[i] = 0
        ended |= np.array([int(p) in solved for p in pair_of])
        rows = np.flatnonzero(ended)
        if len(rows):
            obs = go(rows)
        if steps - last_log >= 200_000:
            last_log = steps
            log(f"go_explore {args.env_id} seed {args.seed}: explore {steps:,} steps, {time.perf_counter() - t0:.0f} s, "
                f"cells {arch.size():,}, solved {len(solved)}/{args.pairs}")
    vec.close()
    stats = {"explore_steps": steps, "explore_wall_s": time.perf_counter() - t0, "cells": arch.size(),
             "solved": len(solved), "pairs": args.pairs}
    return arch, solved, (S0, G0), steps, stats


def certify(env_id, env_kwargs, arch: Archive, solved: dict, starts, seed):
    """Replay every solved pair's actions from its start (a reset to it); keep the trajectories that end in success
    at their last action. [(states (T+1, 6), target, actions (T, n_act))]."""
    S0, G0 = starts
    pairs = sorted(solved)
    if not pairs:
        return []
    acts = [arch.actions_to(solved[p]) for p in pairs]
    D = len(pairs)
    vec = A.make_vec(env_id, D, env_kwargs)
    vec.reset(seed=seed, options={"state": S0[pairs], "target": G0[pairs]})
    n_act = vec.single_action_space.shape[0]
    states = [[S0[p].copy()] for p in pairs]
    ok = np.zeros(D, bool)
    alive = np.ones(D, bool)
    for t in range(max(len(a) for a in acts)):
        a = np.zeros((D, n_act))
        for j in range(D):
            if t < len(acts[j]):
                a[j] = acts[j][t]
        _, _, term, trunc, info = vec.step(a)
        S = vec.states
        for j in np.flatnonzero(alive):
            if t < len(acts[j]):
                states[j].append(S[j].copy())
                if term[j] or trunc[j]:
                    ok[j] = bool(info["is_success"][j]) and t + 1 == len(acts[j])
                    alive[j] = False
        alive &= ~(np.asarray(term) | np.asarray(trunc))
    vec.close()
    return [(np.array(states[j]), G0[p], acts[j]) for j, p in enumerate(pairs) if ok[j]]


def to_demos(episodes) -> dict:
    """save_demos' arrays in memory (as load_demos returns them)."""
    import io

    from .protocol import load_demos, save_demos
    buf = io.BytesIO()
    save_demos(buf, episodes)
    buf.seek(0)
    return load_demos(buf)


def train(args: Args, checkpoints=(), on_checkpoint=None, log=print) -> dict:
    """Explore, then robustify (training/protocol.py): on_checkpoint(env_steps, policy) at each checkpoint (the
    exploration's steps counted; a checkpoint the exploration passed gets phase 2's initial, untrained policy: the
    agent had no other then) and at the end."""
    torch.set_num_threads(args.torch_threads)
    if args.go_seed < GO_SEED_MIN:
        raise ValueError(f"go_seed must be >= {GO_SEED_MIN:,} (training seeds), got {args.go_seed}")
    t0 = time.perf_counter()
    arch, solved, starts, steps, stats = explore(args, log)
    episodes = certify(args.env_id, args.env_kwargs, arch, solved, starts, args.go_seed)
    stats["certified"] = len(episodes)
    log(f"go_explore {args.env_id} seed {args.seed}: explored {steps:,} steps, {stats['cells']:,} cells, solved "
        f"{stats['solved']}/{args.pairs} pairs, {len(episodes)} certified trajectories")
    # phase 2's own fields (args.curriculum) first; those of this run (env, seed, budget, head) win
    cargs = SC.Args(**{**args.curriculum, "env_id": args.env_id, "env_kwargs": args.env_kwargs, "seed": args.seed,
                       "total_timesteps": max(args.total_timesteps - steps, 1), "torch_threads": args.torch_threads,
                       "head": args.head, "val_every": args.val_every, "val_episodes": args.val_episodes,
                       "val_seed": args.val_seed})
    res = SC.train(cargs, checkpoints, on_checkpoint, log, demos=to_demos(episodes) if episodes else no_demos(),
                   step_offset=steps)
    res.update(stats)
    res["wall_time_s"] = time.perf_counter() - t0
    res["steps_per_s"] = res["env_steps"] / res["wall_time_s"]
    return res


def quick_args(args: Args) -> Args:
    """--quick: seconds on a few envs (checks the pipeline, learns nothing)."""
    return dataclasses.replace(args, num_envs=16, pairs=4, explore_steps=2048, total_timesteps=4096)


def main(argv=None):
    """The command line every ladder agent shares (training.protocol.cli)."""
    from training.protocol import cli
    return cli("training.go_explore", Args, train, argv, quick_args)


if __name__ == "__main__":
    main()
