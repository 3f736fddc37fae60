"""Demonstrations for the ladder's privileged agents: certified witness episodes (studies/witness.py) of
training seeds, written with training.protocol.save_demos.

``python -m studies.witness_demos ENV_ID OUT.npz [--pairs N] [--seed S] [field=value ...]``

Pair seeds S .. S + N - 1 (S >= 100,000: never the evaluation's pair seeds 0..199 nor the validation seeds from
50,000); each witnessed pair's certified actions are replayed in the real episode (gymnasium.make of the id, reset
with the pair's seed) and its states recorded (state t before action t, the last state the successful one).
"""
from __future__ import annotations

import argparse
import sys

import numpy as np

from studies.witness import Witness, parse_overrides, positive_int
from training.protocol import save_demos

DEMO_SEED_MIN = 100_000


def witness_demos(env_id: str, overrides: dict | None, seeds) -> list:
    """[(states (T+1, 6), target (2,), actions (T, n_act))] of the witnessed pairs among ``seeds`` (all >= 100,000)."""
    seeds = list(seeds)
    if seeds and min(seeds) < DEMO_SEED_MIN:
        raise ValueError(f"demonstration seeds start at {DEMO_SEED_MIN:,} (never the evaluation's 0..199 or the "
                         f"validation's 50,000..), got {min(seeds)}")
    w = Witness(env_id, overrides)
    out = []
    try:
        for seed in seeds:
            r = w.pair(seed)
            if not r.witnessed:
                continue
            env, u = w.env, w.env.unwrapped
            env.reset(seed=seed)
            states, target = [u.state.copy()], u.target.copy()
            info = {}
            for a in r.actions:
                _, _, term, trunc, info = env.step(a)
                states.append(u.state.copy())
            if not info.get("is_success"):
                raise AssertionError(f"{env_id} seed {seed}: the certified actions did not succeed on replay")
            out.append((np.array(states), target, np.array(r.actions, float).reshape(len(r.actions), -1)))
    finally:
        w.close()
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m studies.witness_demos", description=__doc__.split("\n\n")[0])
    ap.add_argument("env_id", metavar="ENV_ID")
    ap.add_argument("out", metavar="OUT.npz")
    ap.add_argument("overrides", nargs="*", metavar="field=value")
    ap.add_argument("--pairs", type=positive_int("--pairs"), default=200)
    ap.add_argument("--seed", type=positive_int("--seed", DEMO_SEED_MIN), default=DEMO_SEED_MIN)
    args = ap.parse_intermixed_args(argv)
    episodes = witness_demos(args.env_id, parse_overrides(args.overrides), range(args.seed, args.seed + args.pairs))
    save_demos(args.out, episodes)
    print(f"{args.env_id}: {len(episodes)}/{args.pairs} pairs witnessed, {sum(len(s) for s, _, _ in episodes)} states "
          f"-> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
