"""Side-by-side timing of the compiled batch (CompiledBatch) of two checkouts of penny_env.

    python -m devtools.compare_compiled_batch OTHER_CHECKOUT [--n 4096] [--steps 40] [--rounds 5] [--clock cpu]

Runs the same workload (the 4 built-in scenes' tables and laws, N pennies with random inside states
and random torques in the scene's limits, `steps` control periods of the scene's control_dt) with
this checkout's penny_env and with OTHER_CHECKOUT's, each in a fresh subprocess (machine code from
numba's disk cache, warm-up excluded), alternating the two `rounds` times, and prints the best
time of each and the ratio (this / other; < 1: this checkout is faster). Both must have compiled
once (their numba caches warm) for the timings to exclude compilation.
"""
import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parents[2]  # the checkout holding this penny_env

WORKER = r'''
import json, sys, time
import numpy as np
import penny_env as pe
from penny_env.envs import resolve
from penny_env.backends.batch import CompiledBatch
n, steps, speed = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[4])
out = {}
for name in ("ellipse", "circle", "stadium", "plane"):
    sc, _ = resolve(scene=name, task="reach")
    table, law, params = sc.make_table(), sc.make_law(), sc.make_params()
    cb = CompiledBatch(params, table, law, pe.SolverSettings())
    run = getattr(cb, "states_and_impacts", None) or cb.advance
    rng = np.random.default_rng(0)
    ax, ay = (0.1, 0.1) if table is None else sc.spawn_axes()
    r = 0.7 * np.sqrt(rng.uniform(size=n)); a = rng.uniform(0, 2 * np.pi, n)
    S = np.stack([r * ax * np.cos(a), r * ay * np.sin(a), rng.uniform(-3, 3, n), rng.uniform(-3, 3, n),
                  rng.uniform(-20, 20, n) * speed, rng.uniform(-5, 5, n)])
    lim = sc.torque_limits
    acc = [(rng.uniform(-1, 1, n) * lim["u1"] / params.J, rng.uniform(-1, 1, n) * lim["u2"] / params.rolling_inertia)
           for _ in range(steps)]
    run(S, acc[0][0], acc[0][1], sc.control_dt)  # warm
    clock = time.process_time if sys.argv[3] == "cpu" else time.perf_counter
    t0 = clock()
    for a1, a2 in acc:
        S, _ = run(S, a1, a2, sc.control_dt)
    out[name] = clock() - t0
print(json.dumps(out))
'''


def run(checkout, n, steps, clock, speed):
    env = dict(os.environ, PYTHONPATH=str(checkout))
    res = subprocess.run([sys.executable, "-c", WORKER, str(n), str(steps), clock, str(speed)], env=env, cwd=str(checkout),
                         capture_output=True, text=True, check=True)
    return json.loads(res.stdout.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("other")
    ap.add_argument("--n", type=int, default=4096)
    ap.add_argument("--steps", type=int, default=40)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--speed", type=float, default=1.0,
                    help="scale of the initial rolling rates (theta_dot in +-20 rad/s times this): fewer impacts below 1")
    ap.add_argument("--clock", choices=("wall", "cpu"), default="wall",
                    help="wall time, or the process's CPU time (less sensitive to a loaded machine)")
    args = ap.parse_args()
    best = {"this": {}, "other": {}}
    for k in range(args.rounds):
        for who, path in (("other", Path(args.other).resolve()), ("this", HERE)):
            for scene, t in run(path, args.n, args.steps, args.clock, args.speed).items():
                best[who][scene] = min(best[who].get(scene, float("inf")), t)
        print(f"round {k + 1}: " + ", ".join(f"{s} {best['this'][s] / best['other'][s]:.3f}" for s in best["this"]),
              flush=True)
    print(f"N = {args.n}, {args.steps} control periods, best of {args.rounds} alternated runs, {args.clock} time, "
          f"speed {args.speed}, "
          f"NUMBA_NUM_THREADS={os.environ.get('NUMBA_NUM_THREADS', 'default')}")
    print("| scene | this [s] | other [s] | this / other |")
    print("|---|---|---|---|")
    for s in best["this"]:
        print(f"| {s} | {best['this'][s]:.4f} | {best['other'][s]:.4f} | {best['this'][s] / best['other'][s]:.3f} |")


if __name__ == "__main__":
    main()
