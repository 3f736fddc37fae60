"""Throughput of two source trees of penny_env, side by side in one run (before / after a change).

    python -m devtools.throughput_compare --before OLD_TREE --after NEW_TREE [--rounds 3] [--out FILE]

Each tree is measured in its own subprocess (``PYTHONPATH=TREE``, so each imports its own penny_env) and the
two alternate, round after round, so that both see the same load of a shared machine. ``--clock cpu`` times
CPU time instead of wall-clock time. Measured for every env id the two trees share: the single env through
``gymnasium.make`` (us per step, random actions, resets included) and the native vector env
(``gymnasium.make_vec``, its default backend) at N = 1, 16, 256, 4096 (env-steps per second).

Within a process a measurement depends on what ran before it (the heap, the garbage collector's
generations, numba's loaded code): the same code measured after other ids can differ by 15%. So each round
runs the measurements in its own shuffled order, the same for both trees, and a history effect becomes
round-to-round noise instead of a bias of one tree. The report gives two after / before speed ratios (above
1: faster): the ratio of the best rates of all rounds (timeit's convention) and the median over rounds of
the ratio within a round (the two trees measured back to back, in the same order); it lists every
measurement whose ratio of either kind shows a loss of more than ``--tolerance`` (default 5%).

``--busy``: one spinning Python process runs beside the whole measurement (a learner's core, as users
train beside the env; devtools.contention compares threading setups that way); docs/throughput_compare_busy.md
is that report.

``--quick`` (tests): one round, two ids, N <= 16, few steps, and the report goes to a temporary directory
unless ``--out`` is given (never docs/).
"""
from __future__ import annotations

import argparse
import json
import os
import random
import statistics
import subprocess
import sys
import tempfile
import time

SIZES = (1, 16, 256, 4096)
QUICK_IDS = ("PennyImpacts-Stadium-v0", "PennyReach-Plane-v0")


def _worker(args) -> dict:
    """Runs inside a subprocess whose PYTHONPATH is the tree under test: prints the rates as JSON."""
    import gymnasium as gym
    import numpy as np
    import penny_env  # noqa: F401  (registers the ids)
    from penny_env.envs.registration import env_ids

    clock = time.process_time if args.clock == "cpu" else time.perf_counter
    ids = [i for i in (args.ids or env_ids())]
    order = random.Random(args.order_seed)  # this round's order (module docstring)
    out = {"penny_env": os.path.dirname(penny_env.__file__), "single": {}, "vector": {}}
    for env_id in order.sample(ids, len(ids)):
        env = gym.make(env_id)
        env.reset(seed=0)
        env.action_space.seed(0)
        acts = [env.action_space.sample() for _ in range(args.single_steps)]
        for a in acts[:50]:  # warm up (numba's cache, first episode)
            if any(env.step(a)[2:4]):
                env.reset()
        t0 = clock()
        for a in acts:
            if any(env.step(a)[2:4]):
                env.reset()
        out["single"][env_id] = (clock() - t0) / len(acts) * 1e6
        env.close()
    for env_id, n in order.sample([(i, n) for i in ids for n in args.sizes], len(ids) * len(args.sizes)):
        steps = max(3, min(4000, args.vector_budget // n))
        venv = gym.make_vec(env_id, num_envs=n)
        venv.reset(seed=0)
        venv.action_space.seed(0)
        acts = [venv.action_space.sample() for _ in range(steps)]
        for a in acts[:3]:
            venv.step(a)
        t0 = clock()
        for a in acts:
            venv.step(a)
        out["vector"][f"{env_id}|{n}"] = n * steps / (clock() - t0)
        venv.close()
    np.asarray(0)  # numpy imported for gymnasium's spaces either way
    return out


def _measure(tree: str, args, order_seed: int) -> dict:
    env = dict(os.environ, PYTHONPATH=os.path.abspath(tree), PYTHONDONTWRITEBYTECODE="1")
    cmd = [sys.executable, os.path.abspath(__file__), "--worker", "--clock", args.clock, "--order-seed", str(order_seed),
           "--single-steps", str(args.single_steps),
           "--vector-budget", str(args.vector_budget), "--sizes", *map(str, args.sizes)]
    if args.ids:
        cmd += ["--ids", *args.ids]
    res = subprocess.run(cmd, env=env, cwd=tempfile.gettempdir(), capture_output=True, text=True)
    if res.returncode != 0:
        raise RuntimeError(f"measuring {tree} failed:\n{res.stderr[-3000:]}")
    data = json.loads(res.stdout.strip().splitlines()[-1])
    if os.path.realpath(data["penny_env"]) != os.path.realpath(os.path.join(tree, "penny_env")):
        raise RuntimeError(f"{tree}: the subprocess imported penny_env from {data['penny_env']}")
    return data


def _keys(runs: dict, kind: str) -> list:
    """The measurements of this kind that every run of both trees has."""
    keys = set(runs["before"][0][kind])
    for r in runs["before"] + runs["after"]:
        keys &= set(r[kind])
    return sorted(keys, key=lambda k: (k.split("|")[0], int(k.split("|")[1]) if "|" in k else 0))


def speed_ratios(runs: dict, kind: str) -> dict:
    """key -> (best before, best after, ratio of the bests, median of the per-round ratios) for
    kind "single" (us per step: lower is faster) or "vector" (env-steps per second); ratios are
    speed after / before."""
    faster = min if kind == "single" else max

    def speed(before, after):
        return before / after if kind == "single" else after / before

    out = {}
    for k in _keys(runs, kind):
        b = [r[kind][k] for r in runs["before"]]
        a = [r[kind][k] for r in runs["after"]]
        out[k] = (faster(b), faster(a), speed(faster(b), faster(a)), statistics.median(map(speed, b, a)))
    return out


def _options(ap) -> None:
    ap.add_argument("--before", help="source tree measured first in each round (the old code)")
    ap.add_argument("--after", help="source tree measured second in each round (the new code)")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--tolerance", type=float, default=0.05, help="a loss beyond this share is listed")
    ap.add_argument("--busy", action="store_true", help="one spinning Python process beside the measurement")
    ap.add_argument("--clock", choices=("wall", "cpu"), default="wall",
                    help="wall: time.perf_counter; cpu: time.process_time (all of the process's threads: steadier on a "
                         "machine loaded by other work, but it counts the threads' CPU time, not the elapsed time)")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--order-seed", type=int, default=0, help=argparse.SUPPRESS)
    ap.add_argument("--ids", nargs="*", default=None, help="env ids (default: every id both trees register)")
    ap.add_argument("--sizes", nargs="*", type=int, default=None)
    ap.add_argument("--single-steps", type=int, default=None)
    ap.add_argument("--vector-budget", type=int, default=None,
                    help="env-steps per vector measurement (3 to 4000 steps of the vector env)")


def main(argv: list[str] | None = None) -> str:
    argv = list(sys.argv[1:] if argv is None else argv)
    if "--worker" in argv:  # a worker runs this file against another source tree, which may have no lab/
        ap = argparse.ArgumentParser()
        ap.add_argument("--quick", action="store_true")
        ap.add_argument("--out")
        _options(ap)
        args = ap.parse_args(argv)
        rep = None
    else:
        from lab.common import report_command
        rep = report_command("devtools.throughput_compare", "throughput_compare.md", __doc__.split("\n")[0], argv,
                             options=_options, quick="one round, two ids, N <= 16, few steps (tests)")
        args = rep.args
    if args.quick:
        args.rounds, args.ids = 1, args.ids or list(QUICK_IDS)
    args.sizes = args.sizes or ([1, 16] if args.quick else list(SIZES))
    args.single_steps = args.single_steps or (300 if args.quick else 20_000)
    args.vector_budget = args.vector_budget or (2_000 if args.quick else 1_200_000)
    if rep is None:
        print(json.dumps(_worker(args)))
        return ""
    if not args.before or not args.after:
        rep.error("--before and --after are required")
    for name in ("before", "after"):
        tree = getattr(args, name)
        if not os.path.isdir(os.path.join(tree, "penny_env")):
            rep.error(f"--{name}: {tree!r} holds no penny_env package")
    if args.rounds < 1:
        rep.error(f"--rounds must be >= 1, got {args.rounds}")
    runs = {"before": [], "after": []}
    spinner = subprocess.Popen([sys.executable, "-c", "while True:\n    pass\n"]) if args.busy else None
    try:
        for r in range(args.rounds):
            for name in ("before", "after"):
                runs[name].append(_measure(getattr(args, name), args, order_seed=r))
                print(f"round {r + 1}/{args.rounds}: {name} measured", flush=True)
    finally:
        if spinner is not None:
            spinner.kill()
            spinner.wait()
    single, vector = speed_ratios(runs, "single"), speed_ratios(runs, "vector")
    lines = rep.header("Throughput before and after a change, side by side") + [
             "- beside: " + ("one spinning Python process for the whole run (a learner's core)" if args.busy
                             else "nothing added (the machine as it was)"),
             f"- before: `{args.before}`, after: `{args.after}`; {args.rounds} alternating round(s), each in its own "
             f"shuffled order (the same for both trees); clock: "
             f"{'CPU time (time.process_time)' if args.clock == 'cpu' else 'wall clock'}",
             "- speed after / before, above 1: faster. *best*: the ratio of the best of all rounds; *median*: the median "
             "over rounds of the ratio within a round",
             "", "## Single environment (us per step, gymnasium.make)", "",
             "| env | before | after | speed after / before (best) | (median) |", "| --- | ---: | ---: | ---: | ---: |"]
    losses = []
    limit = 1 - args.tolerance
    for k, (b, a, best, med) in single.items():
        lines.append(f"| {k} | {b:.2f} | {a:.2f} | {best:.3f} | {med:.3f} |")
        if min(best, med) < limit:
            losses.append(f"single {k}: best {best:.3f}, median {med:.3f}")
    lines += ["", "## Vector environment (env-steps per second, gymnasium.make_vec)", "",
              "| env | N | before | after | speed after / before (best) | (median) |",
              "| --- | ---: | ---: | ---: | ---: | ---: |"]
    for k, (b, a, best, med) in vector.items():
        env_id, n = k.split("|")
        lines.append(f"| {env_id} | {n} | {b:,.0f} | {a:,.0f} | {best:.3f} | {med:.3f} |")
        if min(best, med) < limit:
            losses.append(f"vector {env_id} N={n}: best {best:.3f}, median {med:.3f}")
    rows = list(single.values()) + list(vector.values())
    lines += ["", "## Summary", "",
              f"- {len(rows)} measurements; speed ratio after / before, best of rounds: min "
              f"{min(r[2] for r in rows):.3f}, max {max(r[2] for r in rows):.3f}; median of rounds: min "
              f"{min(r[3] for r in rows):.3f}, max {max(r[3] for r in rows):.3f}",
              f"- losses beyond {args.tolerance:.0%} (by either ratio): " + ("none" if not losses else "; ".join(losses))]
    report = "\n".join(lines) + "\n"
    rep.write(report, echo=True)
    return report


if __name__ == "__main__":
    main()
