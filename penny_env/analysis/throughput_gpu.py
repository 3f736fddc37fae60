"""GPU throughput of the vector env: env-steps per second on one CUDA GPU against the compiled CPU backend on
every core of the same machine and CartPole-v1's native vector env, with the device memory per env.

``python -m penny_env.analysis.throughput_gpu [--quick] [--out PATH] [--env-id ID] [--sizes N ...]``

For each N (default 4096, 65536, 1M, 4M): PennyVectorEnv(N, backend="cuda") with torch outputs and
actions drawn on the device beforehand (torch), timed over a run of steps after warm-up steps, with
torch.cuda.synchronize() at the end; the CPU backend (numba, all cores) and CartPole's native vector env
on the same N (fewer steps where N is large). Memory per env: the bytes of the env's device arrays (its
state and one step's outputs) divided by N.

It needs a CUDA GPU with numba-cuda and torch. Where there is none (the CUDA simulator does not count:
it measures nothing about a GPU) it prints so and writes no report: the README then says the GPU backend
is built and tested in simulation (tests/test_cuda.py) and not yet measured. Targets when it runs: at
least 1e9 env-steps/s on one H100 at the best N and at least 50 times the CPU backend of that machine.
"""
from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from .common import header, report_path, table, write

SIZES = (4096, 65536, 1_048_576, 4_194_304)
ENV_ID = "PennyReach-Ellipse-v0"


def gpu_here() -> str | None:
    """The GPU's name where numba-cuda and torch see a real CUDA device, else None."""
    import importlib.util
    import os
    if os.environ.get("NUMBA_ENABLE_CUDASIM") == "1" or importlib.util.find_spec("numba_cuda") is None:
        return None
    try:
        import torch
        from numba import cuda
        if not (cuda.is_available() and torch.cuda.is_available()):
            return None
        return torch.cuda.get_device_name(0)
    except Exception:  # noqa: BLE001 (a broken driver: no GPU)
        return None


def gpu_rate(env_id: str, n: int, steps: int, warmup: int = 3) -> tuple[float, float]:
    """(env-steps/s, device bytes per env) of the CUDA backend at N = n."""
    import gymnasium as gym
    import torch
    env = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", backend="cuda").unwrapped
    env.reset(seed=0)
    k = env.single_action_space.shape[0]
    g = torch.Generator(device="cuda").manual_seed(0)
    acts = [torch.rand((n, k), device="cuda", dtype=torch.float64, generator=g) * 2 - 1 for _ in range(steps + warmup)]
    for a in acts[:warmup]:
        out = env.step(a)
    torch.cuda.synchronize()
    t0 = time.perf_counter()
    for a in acts[warmup:]:
        out = env.step(a)
    torch.cuda.synchronize()
    dt = time.perf_counter() - t0
    st = env._gpu.st
    state_bytes = sum(a.nbytes for a in st)
    out_bytes = sum(t.element_size() * t.nelement() for t in out[:4]) + sum(
        v.element_size() * v.nelement() for v in out[4].values() if hasattr(v, "element_size"))
    env.close()
    return n * steps / dt, (state_bytes + out_bytes) / n


def cpu_rate(env_id: str, n: int, steps: int) -> float:
    import gymnasium as gym

    from .throughput import vector_rate
    return vector_rate(lambda m: gym.make_vec(env_id, num_envs=m, vectorization_mode="vector_entry_point"), n, steps)


def cartpole_rate(n: int, steps: int) -> float:
    import gymnasium as gym

    from .throughput import vector_rate
    return vector_rate(lambda m: gym.make_vec("CartPole-v1", num_envs=m, vectorization_mode="vector_entry_point"), n, steps)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small sizes and few steps (a smoke run)")
    ap.add_argument("--out", default=None, help="report path (default runs/reports/throughput_gpu.md; "
                    "docs/throughput_gpu.md for the committed report)")
    ap.add_argument("--env-id", default=ENV_ID)
    ap.add_argument("--sizes", nargs="+", type=int, default=None, help=f"numbers of envs (default {SIZES})")
    a = ap.parse_args(argv)
    sizes = a.sizes or ((256, 4096) if a.quick else SIZES)
    if any(n < 1 for n in sizes):
        ap.error(f"--sizes must be positive, got {sizes}")
    name = gpu_here()
    if name is None:
        print("throughput_gpu: no CUDA GPU here (numba-cuda and torch see no device; the CUDA simulator does not "
              "count): nothing measured, no report written. The GPU backend is built and tested in simulation "
              "(tests/test_cuda.py).")
        return 0
    rows, best = [], (0.0, 0)
    for n in sizes:
        steps = 20 if a.quick else max(20, min(200, 2**24 // n))
        g, mem = gpu_rate(a.env_id, n, steps)
        cpu_steps = max(2, min(steps, 2**21 // n))
        c = cpu_rate(a.env_id, n, cpu_steps)
        cp = cartpole_rate(n, cpu_steps)
        best = max(best, (g, n))
        rows.append([f"{n:,}", f"{g:,.0f}", f"{c:,.0f}", f"{g / c:.1f}x", f"{cp:,.0f}", f"{mem:.0f} B"])
        print(f"N={n:>9,}  GPU {g:14,.0f}/s  CPU {c:12,.0f}/s  ({g / c:.1f}x)  CartPole {cp:12,.0f}/s  {mem:.0f} B/env",
              flush=True)
    import os
    lines = header("GPU throughput of the vector env", "penny_env.analysis.throughput_gpu", argv)
    lines += [f"- device: {name}; CPU backend on {os.cpu_count()} cores of the same machine", "",
              f"{a.env_id}, actions drawn on the device beforehand, torch outputs; env-steps per second.", "",
              *table(["N", "GPU (cuda)", "CPU (numba, all cores)", "GPU / CPU", "CartPole-v1 native vector",
                      "device memory per env"], rows), "",
              f"Best: {best[0]:,.0f} env-steps/s at N = {best[1]:,} (targets: 1e9 on one H100, 50x the CPU backend)."]
    path = report_path(a.out, a.quick, "throughput_gpu.md")
    write(str(path), lines)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
