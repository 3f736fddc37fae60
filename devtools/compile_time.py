"""How long the first use of each table shape takes in a fresh install (numba compiles), and later
runs (numba's cache loads), for the single env, the vector env and the batch API.

    python -m devtools.compile_time [--quick] [--out docs/compile_time.md]

Each measurement is a new Python process with its own empty NUMBA_CACHE_DIR (a cold start: nothing
compiled) run twice: "cold" is the first run (compiles and writes the cache), "warm" the second (loads
it). A process builds one entry point for one shape: ``gymnasium.make(id)`` and ``reset`` (single),
``gymnasium.make_vec(id, 64)`` and ``reset`` (vector), or ``penny_env.batch.simulate`` of 64 pennies
(batch). Seconds are the wall and CPU time of that build, excluding the interpreter's start and imports.

``--quick`` (used by the tests): the open plane's single env only, into a temporary folder unless --out.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile

SHAPES = {  # shape -> an env id on it (and the batch table spec)
    "Ellipse": ("PennyReach-Ellipse-v0", {"kind": "ellipse", "a": 0.3, "b": 0.2}),
    "Circle": ("PennyPark-Circle-v0", {"kind": "circle", "radius": 0.2}),
    "Stadium": ("PennyImpacts-Stadium-v0", {"kind": "stadium", "radius": 0.1, "length": 0.15}),
    "RoundedRectangle": ("PennyReach-RoundedRectangle-v0", {"kind": "rounded_rectangle", "width": 0.3,
                                                            "height": 0.2, "radius": 0.04}),
    "Plane": ("PennyReach-Plane-v0", None),
}
ENTRIES = ("single", "vector", "batch")

_CHILD = r"""
import json, sys, time
import numpy as np
import gymnasium as gym
import penny_env, penny_env.batch as pb
entry, env_id, table = sys.argv[1], sys.argv[2], json.loads(sys.argv[3])
t0, c0 = time.perf_counter(), time.process_time()
if entry == "single":
    gym.make(env_id).reset(seed=0)
elif entry == "vector":
    gym.make_vec(env_id, num_envs=64).reset(seed=0)
else:
    S = np.zeros((64, 6)); S[:, 4] = 5.0; S[:, 3] = np.linspace(0, 6, 64)
    pb.simulate(S, table=table, law="elastic", t_final=0.5)
print(json.dumps([time.perf_counter() - t0, time.process_time() - c0]))
"""


def build_seconds(entry: str, shape: str, cache_dir: str) -> tuple[float, float]:
    """(wall, CPU) seconds to build ``entry`` on ``shape`` in a new process whose numba cache is ``cache_dir``."""
    env_id, table = SHAPES[shape]
    env = dict(os.environ, NUMBA_CACHE_DIR=cache_dir)
    out = subprocess.run([sys.executable, "-c", _CHILD, entry, env_id, json.dumps(table)], env=env,
                         capture_output=True, text=True)
    if out.returncode != 0:
        raise RuntimeError(f"{entry} on {shape} failed (exit {out.returncode}): {out.stderr[-2000:]}")
    wall, cpu = json.loads(out.stdout.strip().splitlines()[-1])
    return float(wall), float(cpu)


def measure(shapes, entries) -> list[dict]:
    """Rows {shape, entry, cold, warm} (seconds), each pair in its own empty cache directory."""
    rows = []
    for shape in shapes:
        for entry in entries:
            with tempfile.TemporaryDirectory(prefix="penny_numba_cache_") as cache:
                cold = build_seconds(entry, shape, cache)
                warm = build_seconds(entry, shape, cache)
            rows.append({"shape": shape, "entry": entry, "cold": cold[0], "cold_cpu": cold[1], "warm": warm[0],
                         "warm_cpu": warm[1]})
            print(f"{shape:17s} {entry:7s} cold {cold[0]:6.1f} s (CPU {cold[1]:6.1f} s)  warm {warm[0]:5.2f} s "
                  f"(CPU {warm[1]:5.2f} s)", file=sys.stderr, flush=True)
    return rows


def report(rows, rep) -> list[str]:
    lines = rep.header("First-use compile time") + [
             "Cold: a new process with an empty numba cache (compiles, writes the cache); warm: the same "
             "again (loads it). Seconds of the build only (not the interpreter's start or imports): wall, and the "
             "process's CPU time, which a machine shared with other work inflates less.", "",
             "| shape | entry point | cold wall [s] | cold CPU [s] | warm wall [s] | warm CPU [s] |",
             "|---|---|---:|---:|---:|---:|"]
    lines += [f"| {r['shape']} | {r['entry']} | {r['cold']:.1f} | {r['cold_cpu']:.1f} | {r['warm']:.2f} | "
              f"{r['warm_cpu']:.2f} |" for r in rows]
    by_shape = {}
    for r in rows:
        by_shape.setdefault(r["shape"], 0.0)
        by_shape[r["shape"]] += r["cold_cpu"]
    lines += ["", "Total cold CPU seconds per shape (the entry points above, each in its own fresh cache): "
              + ", ".join(f"{s} {t:.0f} s" for s, t in by_shape.items()) + "."]
    return lines


def main(argv=None):
    from lab.common import report_command

    def options(ap):
        ap.add_argument("--shapes", nargs="+", choices=list(SHAPES), help="shapes (default: all)")
        ap.add_argument("--entries", nargs="+", choices=ENTRIES, help="entry points (default: all)")
    rep = report_command("devtools.compile_time", "compile_time.md", __doc__.split("\n\n")[0], argv, options=options,
                         quick="the open plane's single env only (for the tests)")
    args = rep.args
    shapes = ["Plane"] if args.quick else (args.shapes or list(SHAPES))
    entries = ["single"] if args.quick else (args.entries or list(ENTRIES))
    return rep.write(report(measure(shapes, entries), rep), echo=True)


if __name__ == "__main__":
    main()
