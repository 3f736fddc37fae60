"""Throughput of the environments, side by side with Gymnasium's classic-control envs.

    python -m devtools.throughput [--quick] [--out docs/throughput.md]

Measured in one run on this machine:

* single env through ``gymnasium.make`` (wrappers included): every Penny preset, Pendulum-v1 and
  CartPole-v1; microseconds per step and the ratio to Pendulum-v1 (random actions drawn beforehand,
  resets included);
* PennyVectorEnv at N = 1, 16, 256, 4096 (``gymnasium.make_vec``, native; the default backend,
  the compiled step) against gymnasium's SyncVectorEnv of
  PennyEnv and CartPole-v1's native vector env, in env-steps per second, and the peak memory per
  env of PennyVectorEnv (tracemalloc, construction + reset + steps). Each native run is a few
  hundred steps from reset, so episodes run through their autoresets.

Every rate is the best of ``--repeats`` runs (default 3), the convention of Python's timeit: on a
shared machine the fastest run is the one least slowed down by other load. Every env, Penny or
Gymnasium, is measured the same way.

``--quick`` (used by the tests) runs few steps, N up to 256, two presets and one repeat, into a temporary folder
unless --out names another (never docs/).
"""
from __future__ import annotations

import gc
import time
import tracemalloc

import numpy as np
import gymnasium as gym

import penny_env  # noqa: F401  (registers the ids)
from penny_env.envs.registration import env_ids

WALLED = "PennyImpacts-Stadium-v0"
VECTOR_PRESETS = ("PennyReach-Ellipse-v0", "PennyImpacts-Stadium-v0", "PennyReach-Plane-v0", "PennyDrive-Circle-v0")


def single_step_us(env_id: str, steps: int, seed: int = 0, repeats: int = 1) -> tuple[float, float]:
    """(us per step through gymnasium.make, impacts per step): the best of ``repeats`` runs."""
    runs = [_single_run(env_id, steps, seed) for _ in range(repeats)]
    return min(r[0] for r in runs), runs[0][1]


def _single_run(env_id: str, steps: int, seed: int) -> tuple[float, float]:
    env = gym.make(env_id)
    env.reset(seed=seed)
    env.action_space.seed(seed)
    acts = [env.action_space.sample() for _ in range(steps)]
    for a in acts[: min(50, steps)]:  # warm up
        _, _, te, tr, _ = env.step(a)
        if te or tr:
            env.reset()
    impacts = 0
    t0 = time.perf_counter()
    for a in acts:
        _, _, te, tr, info = env.step(a)
        impacts += info.get("impacts", 0)
        if te or tr:
            env.reset()
    dt = time.perf_counter() - t0
    env.close()
    return dt / steps * 1e6, impacts / steps


def vector_rate(make, n: int, steps: int, seed: int = 0, repeats: int = 1) -> float:
    """env-steps per second of a vector env (random actions drawn beforehand): the best of
    ``repeats`` runs, each from a new env and reset."""
    return max(_vector_run(make, n, steps, seed) for _ in range(repeats))


def _vector_run(make, n: int, steps: int, seed: int) -> float:
    venv = make(n)
    venv.reset(seed=seed)
    venv.action_space.seed(seed)
    acts = [venv.action_space.sample() for _ in range(steps)]
    for a in acts[: min(3, steps)]:
        venv.step(a)
    t0 = time.perf_counter()
    for a in acts:
        venv.step(a)
    dt = time.perf_counter() - t0
    venv.close()
    return n * steps / dt


def peak_memory_per_env(env_id: str, n: int, steps: int = 5) -> float:
    gc.collect()
    tracemalloc.start()
    venv = gym.make_vec(env_id, num_envs=n)
    venv.reset(seed=0)
    a = np.zeros(venv.action_space.shape, np.float32)
    for _ in range(steps):
        venv.step(a)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    venv.close()
    return peak / n


def _numba_version() -> str:
    try:
        from importlib.metadata import version
        return version("numba")
    except Exception:  # not installed
        return "not installed"


def _steps_for(n: int, quick: bool) -> int:
    budget = 20_000 if quick else 1_200_000  # env-steps per measurement
    return max(3, min(200 if quick else 1000, budget // n))


def main(argv: list[str] | None = None) -> str:
    from lab.common import report_command

    def options(ap):
        ap.add_argument("--repeats", type=int, default=None, help="runs per measurement, the best is reported "
                                                                   "(default 3, --quick 1)")
        ap.add_argument("--readme", default=None, help="also replace the block between <!-- throughput:start --> "
                        "and <!-- throughput:end --> in this file (README.md) with the tables")
    rep = report_command("devtools.throughput", "throughput.md", __doc__.split("\n")[0], argv, options=options,
                         quick="few steps, N <= 256 (for tests)")
    args = rep.args
    quick = args.quick
    if quick and args.readme:
        rep.error("--readme writes the README's throughput table: it takes a full run, not --quick")
    repeats = args.repeats if args.repeats is not None else (1 if quick else 3)
    if repeats < 1:
        rep.error(f"--repeats must be >= 1, got {repeats}")
    single_steps = 1000 if quick else 20_000
    lines = rep.header("Throughput of penny_env")[:-1] + [
             f"- gymnasium {gym.__version__}, numba {_numba_version()}",
             f"- every rate: the best of {repeats} run(s), for every env alike",
             "", "## Single environment (gymnasium.make, random actions, resets included)", "",
             "| env | us/step | steps/s | vs Pendulum-v1 (time ratio) | impacts/step |", "| --- | ---: | ---: | ---: | ---: |"]
    pend, _ = single_step_us("Pendulum-v1", single_steps, repeats=repeats)
    cart, _ = single_step_us("CartPole-v1", single_steps, repeats=repeats)
    ids = [WALLED, "PennyReach-Plane-v0"] if quick else env_ids()
    rows = [("Pendulum-v1", pend, 0.0), ("CartPole-v1", cart, 0.0)]
    for env_id in ids:
        us, imp = single_step_us(env_id, single_steps, repeats=repeats)
        rows.append((env_id, us, imp))
    for name, us, imp in rows:
        lines.append(f"| {name} | {us:.1f} | {1e6 / us:,.0f} | {us / pend:.2f} | {imp:.3f} |")
        print(f"single {name:28s} {us:7.1f} us/step  x{us / pend:.2f} Pendulum  impacts/step {imp:.3f}", flush=True)
    sizes = (1, 16, 256) if quick else (1, 16, 256, 4096)
    backend = gym.make_vec(WALLED, num_envs=1).unwrapped._core.backend
    presets = (WALLED, "PennyReach-Plane-v0") if quick else VECTOR_PRESETS
    lines += ["", "## Vector environments (env-steps per second, random actions)", "",
              f"PennyVectorEnv's default backend here: **{backend}**.", "",
              "| env | N | PennyVectorEnv | SyncVectorEnv(PennyEnv) | native / sync | CartPole-v1 native vector "
              "| peak memory per env |",
              "| --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
    big = []  # (env, N, native rate, sync rate) at the largest N
    for env_id in presets:
        for n in sizes:
            steps = _steps_for(n, quick)
            native = vector_rate(lambda k: gym.make_vec(env_id, num_envs=k), n, steps, repeats=repeats)
            sync_steps = max(3, min(steps, (2_000 if quick else 40_000) // n))
            sync = vector_rate(lambda k: gym.make_vec(env_id, num_envs=k, vectorization_mode="sync"), n, sync_steps,
                               repeats=repeats)
            cp = vector_rate(lambda k: gym.make_vec("CartPole-v1", num_envs=k, vectorization_mode="vector_entry_point"),
                             n, steps, repeats=repeats)
            mem = peak_memory_per_env(env_id, n)
            if n == max(sizes):
                big.append((env_id, n, native, sync))
            lines.append(f"| {env_id} | {n} | {native:,.0f} | {sync:,.0f} | {native / sync:.1f} | {cp:,.0f} "
                         f"| {mem / 1024:.1f} KiB |")
            print(f"vector {env_id:28s} N={n:5d} native {native:12,.0f}/s  sync {sync:10,.0f}/s  x{native / sync:6.1f}"
                  f"  CartPole {cp:12,.0f}/s  mem/env {mem / 1024:.1f} KiB", flush=True)
    lines += ["", "## Targets, from the numbers above", ""] + _targets(rows, pend, big)
    report = "\n".join(lines) + "\n"
    if args.readme:
        start, end = "<!-- throughput:start -->", "<!-- throughput:end -->"
        if not rep.readme(args.readme, start, end, "\n".join(readme_summary(lines)).rstrip()):
            raise ValueError(f"{args.readme}: no {start} ... {end} block to replace")
    rep.write(report)
    return report


def _targets(single_rows, pend_us: float, big) -> list[str]:
    """Met / not met, for each target, from the measured numbers."""
    walled = sorted((us, name) for name, us, imp in single_rows if name.startswith("Penny") and imp > 0)
    out = []
    if walled:
        ok = [name for us, name in walled if us <= 2.0 * pend_us]
        (best_us, best), (worst_us, worst) = walled[0], walled[-1]
        out.append(f"- single env at least half of Pendulum-v1's steps/s on a walled preset with impacts: "
                   f"{'met' if ok else 'NOT met'}, on {len(ok)} of the {len(walled)} walled presets "
                   f"(step time {best_us / pend_us:.2f}x Pendulum-v1's for {best} to {worst_us / pend_us:.2f}x for {worst})")
    for env_id, n, native, sync in big:
        rate_ok = native >= 5e6
        ratio_ok = native >= 30.0 * sync
        out.append(f"- {env_id}, N = {n}: {native / 1e6:.2f} M env-steps/s, 5 M target {'met' if rate_ok else 'NOT met'}; "
                   f"{native / sync:.0f}x SyncVectorEnv, 30x target {'met' if ratio_ok else 'NOT met'}")
    return out


def readme_summary(lines: list[str]) -> list[str]:
    """The README's short throughput block from a report's lines: its machine, date and command, and the targets
    (the tables themselves stay in docs/throughput.md)."""
    head = [ln for ln in lines if ln.startswith(("- machine:", "- date:", "- command:", "- load when"))]
    targets = lines[lines.index("## Targets, from the numbers above") + 2:]
    return head + ["", "Targets met or not, from the tables of [docs/throughput.md](docs/throughput.md):", ""] + targets



if __name__ == "__main__":
    main()
