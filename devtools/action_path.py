"""Which source files one action crosses, from ``env.step(action)`` to the observation it returns.

    python -m devtools.action_path [--env-id PennyReach-Ellipse-v0] [--steps 200] [--quick]

A profiler hook (sys.setprofile) records every Python function called during ``steps`` warm steps of the single
env and of the vector env, both built with backend="python": the plain-Python target runs the very functions
the compiled targets compile (backends/builder.py; the CPU and CUDA builds add only their generated loop and the
lock around it), so the files it records are the files an action crosses on every target, counted once per
file. Printed per env with the files in the order first crossed, and the call depth (the deepest stack of
penny_env frames). Steps are random actions with impacts among them (an impact-free step crosses fewer).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def crossed(env, actions) -> tuple[list, int]:
    """(the package's source files called into while stepping ``actions``, the deepest stack of package frames)."""
    import penny_env
    from penny_env.backends.generated import generated_dir
    pkg = str(Path(penny_env.__file__).resolve().parent)
    generated = str(generated_dir())
    files: dict = {}
    depth = [0, 0]

    def hook(frame, event, arg):
        if event == "call":
            f = frame.f_code.co_filename
            inside = f.startswith(pkg) or f.startswith(generated)
            if inside:
                files.setdefault(str(Path(f).resolve().relative_to(Path(pkg).parent))
                                 if f.startswith(pkg) else "(generated) " + Path(f).name, None)
                d, g = 0, frame
                while g is not None:
                    if g.f_code.co_filename.startswith(pkg):
                        d += 1
                    g = g.f_back
                depth[0] = max(depth[0], d)
    sys.setprofile(hook)
    try:
        for a in actions:
            out = env.step(a)
            if np.ndim(out[2]) == 0 and (out[2] or out[3]):
                env.reset()
    finally:
        sys.setprofile(None)
    return list(files), depth[0]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--env-id", default="PennyReach-Ellipse-v0")
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--quick", action="store_true", help="20 steps")
    args = ap.parse_args(argv)
    import gymnasium as gym

    import penny_env  # noqa: F401
    steps = 20 if args.quick else args.steps
    rng = np.random.default_rng(0)
    single = gym.make(args.env_id, backend="python").unwrapped
    single.reset(seed=0)
    single.step(single.action_space.sample())  # (warm: first-call imports are not the step's path)
    a1 = rng.uniform(-1, 1, (steps,) + single.action_space.shape)
    vec = penny_env.PennyVectorEnv(4, **_spec(args.env_id), backend="python")
    vec.reset(seed=0)
    vec.step(vec.action_space.sample())
    a4 = rng.uniform(-1, 1, (steps,) + vec.action_space.shape)
    rows = {}
    for name, env, acts in (("single env", single, a1), ("vector env (CPU)", vec, a4)):
        files, depth = crossed(env, acts)
        rows[name] = (files, depth)
        print(f"{name}: {len(files)} source files, {depth} package frames deep")
        for f in files:
            print(f"    {f}")
    return rows


def _spec(env_id):
    """PennyVectorEnv's scene and task keywords for a registered id."""
    import gymnasium as gym
    kw = dict(gym.spec(env_id).kwargs)
    return kw


if __name__ == "__main__":
    main()
