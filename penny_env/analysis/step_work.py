"""Work per env-step by preset (issue 10.6: why PennyPark-Stadium-v0 at N = 4096 ran slower).

    python -m penny_env.analysis.step_work [--n 256] [--steps 292]

1. Counters (the plain-Python step, instrumented): event-loop calls, impact searches, search
   iterations, curvature steps and impacts per env-step, random actions, NEXT_STEP autoreset.
2. The costliest pennies: every penny whose step had more than 8 impacts (what 960f394's vector
   step reran alone, serially, to fill its impact buffer) is stepped again alone with the compiled
   env_step (best of 3), at N = 4096."""
from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import penny_env  # noqa: F401
from penny_env.envs import functional
from penny_env.physics import scalar

PRESETS = ("PennyPark-Stadium-v0", "PennyImpacts-Stadium-v0", "PennyPark-Circle-v0", "PennyImpacts-Ellipse-v0",
           "PennyReach-Ellipse-v0")


def counters(n, steps):
    cnt = {}

    def wrap(mod, name, key):
        f = getattr(mod, name)

        def counted(*a, **k):
            cnt[key] = cnt.get(key, 0) + 1
            return f(*a, **k)
        setattr(mod, name, counted)
        return f

    saved = [(scalar, "end_plain1", wrap(scalar, "end_plain1", "ends")),
             (scalar, "first_impact_m", wrap(scalar, "first_impact_m", "searches")),
             (functional, "advance_m", wrap(functional, "advance_m", "loops")),
             (scalar, "with_curvature1", wrap(scalar, "with_curvature1", "curv"))]
    try:
        for env_id in PRESETS:
            cnt.clear()
            venv = gym.make_vec(env_id, num_envs=n, backend="python").unwrapped
            venv.reset(seed=0)
            venv.action_space.seed(0)
            imp = 0
            for _ in range(steps):
                imp += int(venv.step(venv.action_space.sample())[4]["impacts"].sum())
            k = n * steps
            print(f"{env_id:26s} per env-step: event-loop calls {cnt.get('loops', 0) / k:.3f}, searches "
                  f"{cnt.get('searches', 0) / k:.3f}, search iterations {cnt.get('ends', 0) / 2 / k:.2f}, curvature steps "
                  f"{cnt.get('curv', 0) / k:.2f}, impacts {imp / k:.3f}", flush=True)
    finally:
        for mod, name, f in saved:
            setattr(mod, name, f)


def heavy_pennies(n, steps):
    for env_id in PRESETS:
        venv = gym.make_vec(env_id, num_envs=n).unwrapped
        fn = functional.compiled_env_functions(venv._m.kind)["env_step"]
        venv.reset(seed=0)
        venv.action_space.seed(0)
        obs = np.empty((1, venv._core.obs_dim), np.float32)
        times, ends = np.empty((1, 64)), np.empty((1, 64), np.int64)
        costs, step_times = [], []
        for _ in range(steps):
            a = venv.action_space.sample()
            S, trig, cnt, d, st = venv._S.copy(), venv._trig.copy(), venv._count.copy(), venv._d.copy(), venv._steps.copy()
            t0 = time.perf_counter()
            info = venv.step(a)[4]
            step_times.append(time.perf_counter() - t0)
            for i in np.flatnonzero(info["impacts"] > 8):
                args = (tuple(S[:, i]), tuple(trig[:, i]), float(a[i, 0]), float(a[i, 1]), venv._target[0, i],
                        venv._target[1, i], venv._arc[0, i], venv._arc[1, i], int(cnt[i]), d[i], int(st[i]), venv._consts,
                        obs, times, ends)
                best = np.inf
                for _ in range(3):
                    t0 = time.perf_counter()
                    fn(*args)
                    best = min(best, time.perf_counter() - t0)
                costs.append(best * 1e6)
        c = np.array(costs) if costs else np.zeros(1)
        print(f"{env_id:26s} N={n}: median step {np.median(step_times) * 1e6:.0f} us; pennies with > 8 impacts: "
              f"{len(costs)} in {steps} steps, each {np.median(c):.0f} us (median), {c.max():.0f} us (max)", flush=True)


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=256, help="envs for the counters (plain Python: keep it small)")
    ap.add_argument("--steps", type=int, default=292)
    args = ap.parse_args()
    counters(args.n, args.steps)
    heavy_pennies(4096, args.steps)
