"""Side-by-side speed of two checkouts of penny_env (say main and a branch) in one run.

    python scripts/compare_throughput.py --old /path/to/main --new . [--rounds 3]

Each round measures every case once per checkout, alternating old and new, each in a fresh
subprocess whose PYTHONPATH is that checkout (the two cannot share a process: same package name);
the best of the rounds is kept per case and checkout (on a loaded machine the fastest run is the
least disturbed). Cases: the single env (gymnasium.make, resets
included) and the vector env (gymnasium.make_vec) at N = 1, 16, 256, 4096, on a few presets, random
actions drawn beforehand. Rates are env-steps per second of CPU time (time.process_time, all the
process's threads): on a machine loaded by other work, wall-clock rates swing by several times
from run to run, CPU time much less. Prints a table of ratios new / old (> 1: the new is faster)."""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

PRESETS = ("PennyReach-Ellipse-v0", "PennyImpacts-Stadium-v0", "PennyPark-Stadium-v0", "PennyReach-Plane-v0")
SIZES = (1, 16, 256, 4096)

_MEASURE = r"""
import json, sys, time, gymnasium as gym, numpy as np, penny_env
presets, sizes, budget = json.loads(sys.argv[1]), json.loads(sys.argv[2]), int(sys.argv[3])

def rate(env, steps, n):
    env.reset(seed=0)
    env.action_space.seed(0)
    acts = [env.action_space.sample() for _ in range(steps)]
    for a in acts[:3]:
        env.step(a)
    t0 = time.process_time()  # CPU time of this process (all its threads): what other load cannot inflate
    for a in acts:
        out = env.step(a)
        if n == 0 and (out[2] or out[3]):
            env.reset()
    return max(n, 1) * steps / (time.process_time() - t0)

out = {}
for env_id in presets:
    out[env_id + " single"] = rate(gym.make(env_id), budget // 10, 0)
    for n in sizes:
        out[f"{env_id} N={n}"] = rate(gym.make_vec(env_id, num_envs=n), max(10, min(2000, budget // n)), n)
print(json.dumps(out))
"""


def measure(checkout, presets, sizes, budget):
    env = dict(os.environ, PYTHONPATH=os.path.abspath(checkout))
    res = subprocess.run([sys.executable, "-c", _MEASURE, json.dumps(presets), json.dumps(sizes), str(budget)],
                         env=env, capture_output=True, text=True, check=True, cwd=os.path.abspath(checkout))
    return json.loads(res.stdout.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--old", required=True)
    ap.add_argument("--new", required=True)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--budget", type=int, default=250_000, help="env-steps per vector measurement")
    ap.add_argument("--presets", nargs="*", default=list(PRESETS))
    ap.add_argument("--sizes", nargs="*", type=int, default=list(SIZES))
    args = ap.parse_args(argv)
    best = {"old": {}, "new": {}}
    for r in range(args.rounds):
        for name in ("old", "new") if r % 2 == 0 else ("new", "old"):
            got = measure(getattr(args, name), args.presets, args.sizes, args.budget)
            for k, v in got.items():
                best[name][k] = max(best[name].get(k, 0.0), v)
            print(f"round {r + 1} {name} done", file=sys.stderr, flush=True)
    print("| case | old steps/s | new steps/s | new / old |\n| --- | ---: | ---: | ---: |")
    for k in best["old"]:
        o, n = best["old"][k], best["new"][k]
        print(f"| {k} | {o:,.0f} | {n:,.0f} | {n / o:.2f} |")


if __name__ == "__main__":
    main()
