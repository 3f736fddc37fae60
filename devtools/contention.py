"""The vector env's throughput on a quiet machine and beside a busy process, for each threading setup.

    python -m devtools.contention [--quick] [--out docs/contention.md]

A learner (SB3, torch) beside the vector env keeps a core busy. numba's parallel loop then shares the
cores with it, and how its idle threads wait decides the throughput: OpenMP's threads spin by default
(OMP_WAIT_POLICY=active in GNU OpenMP), which starves the process that holds the core they wait on.
For each setup, in its own process (the threading layer is chosen once per process):

* ``penny_env default``: no variable set, the setup penny_env picks (backends/threads.py);
* ``omp spinning``: NUMBA_THREADING_LAYER=omp, OMP_WAIT_POLICY=active (GNU OpenMP's default: numba's own
  setup where its OpenMP layer loads, before penny_env set the policy), threads spinning;
* ``omp passive``: the same with OMP_WAIT_POLICY=passive;
* ``workqueue``: NUMBA_THREADING_LAYER=workqueue (numba's own pool, threads sleep when idle);
* ``tbb``: NUMBA_THREADING_LAYER=tbb, where the tbb package is installed;
* ``1 thread``: NUMBA_NUM_THREADS=1.

Each measures ``gymnasium.make_vec(ENV_ID, num_envs=N)`` (random actions drawn beforehand) in
env-steps per second, quiet and beside one spinning Python process (``busy``: a core's worth of
work, as a learner's), the best of ``--repeats`` rounds (every setup in turn in each round), and the ratio busy / quiet and to the
penny_env default. ``--quick`` (the tests): N = 64, few steps, two setups, into a temporary folder (never
docs/).
"""
from __future__ import annotations

import json
import os
import subprocess
import sys

ENV_ID = "PennyReach-Ellipse-v0"
SETUPS = {
    "penny_env default": {},
    "omp spinning": {"NUMBA_THREADING_LAYER": "omp", "OMP_WAIT_POLICY": "active"},
    "omp passive": {"NUMBA_THREADING_LAYER": "omp", "OMP_WAIT_POLICY": "passive"},
    "workqueue": {"NUMBA_THREADING_LAYER": "workqueue"},
    "tbb": {"NUMBA_THREADING_LAYER": "tbb"},
    "1 thread": {"NUMBA_NUM_THREADS": "1"},
}
_CLEARED = ("NUMBA_THREADING_LAYER", "OMP_WAIT_POLICY", "NUMBA_NUM_THREADS", "OMP_NUM_THREADS")

_CHILD = r"""
import json, sys, time
import numpy as np
import gymnasium as gym
import penny_env
env_id, n, steps, repeats = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
venv = gym.make_vec(env_id, num_envs=n)
rng = np.random.default_rng(0)
acts = rng.uniform(-1, 1, size=(steps,) + venv.action_space.shape).astype(venv.action_space.dtype)
best = 0.0
for r in range(repeats):
    venv.reset(seed=r)
    for a in acts[:5]:
        venv.step(a)
    t0 = time.perf_counter()
    for a in acts:
        venv.step(a)
    best = max(best, n * steps / (time.perf_counter() - t0))
import numba
try:
    layer = numba.threading_layer()
except ValueError:  # no parallel call ran: fewer pennies than threads.SERIAL_BELOW run on the calling thread
    layer = "serial"
print(json.dumps({"rate": best, "layer": layer, "threads": numba.get_num_threads()}))
"""

_BUSY = "while True:\n    pass\n"


def available(setup: str) -> bool:
    """The setup can run here (tbb needs the tbb package)."""
    if setup == "tbb":
        import importlib.util
        return importlib.util.find_spec("tbb") is not None
    return True


def rate(setup: str, n: int, steps: int, repeats: int, busy: bool) -> dict:
    """{rate (env-steps/s), layer, threads} of one setup in a new process, beside a spinning process if busy."""
    env = {k: v for k, v in os.environ.items() if k not in _CLEARED}
    env.update(SETUPS[setup])
    spinner = subprocess.Popen([sys.executable, "-c", _BUSY]) if busy else None
    try:
        out = subprocess.run([sys.executable, "-c", _CHILD, ENV_ID, str(n), str(steps), str(repeats)], env=env,
                             capture_output=True, text=True, timeout=1800)
    finally:
        if spinner is not None:
            spinner.kill()
            spinner.wait()
    if out.returncode != 0:
        raise RuntimeError(f"setup {setup!r} failed (exit {out.returncode}): {out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def measure(setups, n: int, steps: int, repeats: int) -> list[dict]:
    """Rows {setup, layer, threads, quiet, busy}: the best of ``repeats`` rounds, each round running every
    setup quiet then busy in turn (so that a change in the machine's other load hits every setup alike)."""
    setups = [s for s in setups if available(s) or print(f"{s}: not available here, skipped", file=sys.stderr)]
    best: dict = {}
    for r in range(repeats):
        for setup in setups:
            quiet = rate(setup, n, steps, 1, busy=False)
            loaded = rate(setup, n, steps, 1, busy=True)
            row = best.setdefault(setup, {"setup": setup, "layer": quiet["layer"], "threads": quiet["threads"],
                                          "quiet": 0.0, "busy": 0.0})
            row["quiet"], row["busy"] = max(row["quiet"], quiet["rate"]), max(row["busy"], loaded["rate"])
            print(f"round {r + 1}: {setup:18s} {quiet['layer']:9s} quiet {quiet['rate'] / 1e6:6.2f} M/s  "
                  f"busy {loaded['rate'] / 1e6:6.2f} M/s", file=sys.stderr, flush=True)
    return list(best.values())


def report(rows, n: int, steps: int, repeats: int, rep, load_before: float) -> list[str]:
    ref = next((r for r in rows if r["setup"] == "penny_env default"), None)
    head = rep.header("Vector env beside a busy process")
    lines = head + [
             f"Load average {load_before:.2f} at the start and {os.getloadavg()[0]:.2f} at the end.", "",
             f"`gymnasium.make_vec(\"{ENV_ID}\", num_envs={n})`, {steps} steps, best of {repeats} rounds (each round "
             "runs every setup quiet, then busy, in turn); busy: one "
             "spinning Python process beside it (a learner's core). Ratios: busy / quiet, and each setup's rate "
             "over the penny_env default's.", "",
             "| setup | layer | threads | quiet [M steps/s] | busy [M steps/s] | busy / quiet | quiet / default "
             "| busy / default |",
             "|---|---|---:|---:|---:|---:|---:|---:|"]
    # (the load at the end includes this command's own threads and busy process: only the start tells
    # whether other work was running)
    if load_before > 0.5 * (os.cpu_count() or 1):
        lines[len(head):len(head)] = [
                      f"**Preliminary: the machine was not quiet** (load average above half its {os.cpu_count()} CPUs): "
                      "\"quiet\" only means no busy process was added, and other work moved every figure. Rerun on an "
                      "idle machine for the quiet-machine comparison.", ""]
    for r in rows:
        rel_q = f"{r['quiet'] / ref['quiet']:.2f}" if ref else "-"
        rel_b = f"{r['busy'] / ref['busy']:.2f}" if ref else "-"
        lines.append(f"| {r['setup']} | {r['layer']} | {r['threads']} | {r['quiet'] / 1e6:.2f} | {r['busy'] / 1e6:.2f} | "
                     f"{r['busy'] / r['quiet']:.2f} | {rel_q} | {rel_b} |")
    return lines


def main(argv=None):
    from lab.common import report_command

    def options(ap):
        ap.add_argument("--num-envs", type=int, default=4096)
        ap.add_argument("--steps", type=int, default=300)
        ap.add_argument("--repeats", type=int, default=3)
        ap.add_argument("--setups", nargs="+", choices=list(SETUPS), help="setups (default: all available)")
    rep = report_command("devtools.contention", "contention.md", __doc__.split("\n\n")[0], argv, options=options,
                         quick="N = 64, few steps, two setups (for the tests)")
    args = rep.args
    if args.quick:
        n, steps, repeats, setups = 64, 20, 1, ["penny_env default", "1 thread"]
    else:
        n, steps, repeats, setups = args.num_envs, args.steps, args.repeats, args.setups or list(SETUPS)
    load_before = os.getloadavg()[0]
    return rep.write(report(measure(setups, n, steps, repeats), n, steps, repeats, rep, load_before), echo=True)


if __name__ == "__main__":
    main()
