"""Side-by-side speed of two checkouts of penny_env (say main and a branch) in one run.

    python scripts/compare_throughput.py --old /path/to/main --new . [--rounds 3]

Each round measures every case once per checkout, alternating old and new, each in a fresh
subprocess whose PYTHONPATH is that checkout (the two cannot share a process: same package name);
the best of the rounds is kept per case and checkout (on a loaded machine the fastest run is the
least disturbed). Cases: the single env (gymnasium.make, us per step) and the vector env
(gymnasium.make_vec, env-steps per second) at N = 1, 16, 256, 4096, on a few presets, with
penny_env.analysis.throughput's functions (random actions drawn beforehand). Prints a table of
ratios new / old (speed: > 1 is faster)."""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

PRESETS = ("PennyReach-Ellipse-v0", "PennyImpacts-Stadium-v0", "PennyPark-Stadium-v0", "PennyReach-Plane-v0")
SIZES = (1, 16, 256, 4096)

_MEASURE = r"""
import json, sys, gymnasium as gym, penny_env
from penny_env.analysis.throughput import single_step_us, vector_rate
presets, sizes, budget = json.loads(sys.argv[1]), json.loads(sys.argv[2]), int(sys.argv[3])
out = {}
for env_id in presets:
    us, _ = single_step_us(env_id, budget // 10)
    out[env_id + " single"] = 1e6 / us
    for n in sizes:
        steps = max(10, min(1000, budget // n))
        out[f"{env_id} N={n}"] = vector_rate(lambda k: gym.make_vec(env_id, num_envs=k), n, steps)
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
