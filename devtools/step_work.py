"""Work per env-step by preset (why PennyPark-Stadium-v0 at N = 4096 ran slower).

    python -m devtools.step_work [--n 256] [--steps 292] [--quick]

1. Counters (the plain-Python step, instrumented): event-loop calls, impact searches, search
   iterations, curvature steps and impacts per env-step, random actions, NEXT_STEP autoreset.
2. Every penny's step, run again alone with the compiled env_step (at N = 4096): the median, the
   99.99th percentile and the largest cost of one penny's step (a penny stuck in a slow search
   would stand out), and the pennies with more than 8 impacts in a step (what 960f394's vector step
   reran alone, serially, to fill its impact buffer).
(Resets are drawn per env inside the step since the step carries its autoreset: functional.step_env.)"""
from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import penny_env  # noqa: F401
from penny_env.physics import scalar

PRESETS = ("PennyPark-Stadium-v0", "PennyImpacts-Stadium-v0", "PennyPark-Circle-v0", "PennyImpacts-Ellipse-v0",
           "PennyReach-Ellipse-v0")


COUNTED = {"end_search_step": "ends", "first_impact_search": "searches", "advance_into": "loops",
           "end_search_step_curved": "curv"}


def counters(n, steps):
    """The plain-Python step's calls of the event loop's functions, counted in the python build's namespace (the
    copies there call each other by name: backends/builder.py)."""
    cnt = {}
    for env_id in PRESETS:
        cnt.clear()
        venv = gym.make_vec(env_id, num_envs=n, backend="python").unwrapped
        step_ns = venv._fns.step_envs.__globals__
        missing = [name for name in COUNTED if name not in step_ns]
        if missing:
            raise RuntimeError(f"the python build's namespace lacks {missing}: the counters would read 0")
        # the env's namespace and the physics build's (whose copies call each other there)
        spaces = [step_ns] + [step_ns[name].__globals__ for name in COUNTED]
        spaces = [ns for k, ns in enumerate(spaces) if all(ns is not other for other in spaces[:k])]
        saved = [(ns, name, ns[name]) for ns in spaces for name in COUNTED if name in ns]

        def counted(f, key):
            def call(*a, **k):
                cnt[key] = cnt.get(key, 0) + 1
                return f(*a, **k)
            return call
        try:
            for ns, name, f in saved:
                ns[name] = counted(f, COUNTED[name])
            venv.reset(seed=0)
            venv.action_space.seed(0)
            imp = 0
            for _ in range(steps):
                imp += int(venv.step(venv.action_space.sample())[4]["impacts"].sum())
        finally:
            for ns, name, f in saved:
                ns[name] = f
        if imp and not cnt.get("searches"):
            raise RuntimeError(f"{env_id}: impacts without counted searches: the counters miss the build's calls")
        k = n * steps
        print(f"{env_id:26s} per env-step: event-loop calls {cnt.get('loops', 0) / k:.3f}, searches "
              f"{cnt.get('searches', 0) / k:.3f}, search iterations {cnt.get('ends', 0) / 2 / k:.2f}, curvature steps "
              f"{cnt.get('curv', 0) / k:.2f}, impacts {imp / k:.3f}", flush=True)


def penny_costs(n, steps):
    """One penny's compiled single-env step (the same stages as a vector env's row), timed on the vector env's own
    states step after step: its median, tail and the cost of pennies with many impacts."""
    for env_id in PRESETS:
        venv = gym.make_vec(env_id, num_envs=n).unwrapped
        fn = venv._core.entry_points("cpu").env_step
        venv.reset(seed=0)
        venv.action_space.seed(0)
        obs = np.empty((1, venv._core.obs_dim), np.float32)
        buf = tuple(scalar.impact_buffers(1, 64))
        costs, heavy = [], []
        for t in range(steps):
            a = venv.action_space.sample()
            st = venv._runner.st
            S, trig, cnt, d, stp = st.S.copy(), st.trig.copy(), st.count.copy(), st.dist.copy(), st.steps.copy()
            for i in np.flatnonzero(~st.pending):  # (the envs that reset at this step take no step)
                state = (tuple(S[:, i]), tuple(trig[:, i]), (st.target[0, i], st.target[1, i]),
                         (st.arc[0, i], st.arc[1, i]), int(cnt[i]), d[i], int(stp[i]), st.time[i])
                args = (state, float(a[i, 0]), float(a[i, -1]), venv._consts, obs, buf)
                if t == 0 and not costs:
                    fn(*args)  # the first call checks the argument types: not a penny's cost
                t0 = time.perf_counter()
                fn(*args)
                impacts = int(buf[0][0])
                costs.append(time.perf_counter() - t0)
                if impacts > 8:
                    heavy.append(costs[-1])
            venv.step(a)
        c = np.array(costs) * 1e6
        h = np.array(heavy or [0.0]) * 1e6
        print(f"{env_id:26s} N={n}: one penny's step {np.median(c):.1f} us (median), {np.percentile(c, 99.99):.0f} us "
              f"(99.99th percentile), {c.max():.0f} us (max); pennies with > 8 impacts: {len(heavy)} in {steps} steps, "
              f"{np.median(h):.0f} us (median), {h.max():.0f} us (max)", flush=True)


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=256, help="envs for the counters (plain Python: keep it small)")
    ap.add_argument("--steps", type=int, default=292)
    ap.add_argument("--quick", action="store_true", help="16 envs, 5 steps (tests)")
    args = ap.parse_args()
    n_big = 16 if args.quick else 4096
    steps = 5 if args.quick else args.steps
    counters(16 if args.quick else args.n, steps)
    penny_costs(n_big, steps)
