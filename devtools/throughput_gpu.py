"""GPU throughput of the vector env: ``env.step``, its kernels alone, and the step replayed from a CUDA graph,
side by side per N, against the compiled CPU backend on every core of the same machine.

``python -m devtools.throughput_gpu [--quick] [--out PATH] [--env-id ID] [--sizes N ...] [--variants]``

For each N (default 4096, 65536, 1M, 4M), PennyVectorEnv(N, backend="cuda") with torch outputs, actions drawn on
the device beforehand (float32, as a policy gives them), timed over a run of steps after warm-up steps, with
torch.cuda.synchronize() at the end:

* ``env.step``: the whole step as users call it (the actions' copy into the env's buffer, the kernels, the
  outputs and the info dict);
* kernels alone: the step's prepared launches (backends/cuda_env.DeviceStep.launch) in a loop, no Python around
  them: what the GPU itself does per step (the autoreset included);
* graph replay: backends/cuda_env.CudaGraphStep (the step captured in a CUDA graph, then replayed);
* the CPU backend (numba, all cores) on the same N (fewer steps where N is large);
* device memory per env: the bytes of the env's state, buffers and two output sets, over N.

``--variants`` also times the kernels alone for the other ways to build the step (one kernel for everything;
the fast kernel without a register cap or with 64): the measurement that chose the defaults
(backends/env.FAST_MAX_REGISTERS, the split into a fast and a rare kernel).

It needs a CUDA GPU with numba-cuda and torch. Where there is none (the CUDA simulator does not count: it
measures nothing about a GPU) it prints so and writes no report. Targets: env.step at least 1e9
env-steps/s at the best N, at least 0.8 of the kernels alone at N >= 65,536, at least 1.2e7 at N = 4096.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

SIZES = (4096, 65536, 1_048_576, 4_194_304)
ENV_ID = "PennyReach-Ellipse-v0"
VARIANTS = ({"kernels": "one"}, {"kernels": "split", "max_registers": None}, {"kernels": "split", "max_registers": 64})


def gpu_here() -> str | None:
    """The GPU's name where numba-cuda and torch see a real CUDA device, else None."""
    import importlib.util
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


def make(env_id, n, **cuda_options):
    import gymnasium as gym
    env = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", backend="cuda",
                       cuda_options=cuda_options or None).unwrapped
    env.reset(seed=0)
    return env


def timed(f, steps, warmup=3):
    import torch
    for _ in range(warmup):
        f()
    torch.cuda.synchronize()
    t0 = time.perf_counter()
    for _ in range(steps):
        f()
    torch.cuda.synchronize()
    return time.perf_counter() - t0


def rates(env_id, n, steps, **cuda_options) -> dict:
    """env.step, kernels alone and graph replay (env-steps/s) at N = n, and the device bytes per env."""
    import torch

    from penny_env.backends.cuda_env import CudaGraphStep
    env = make(env_id, n, **cuda_options)
    k = env.single_action_space.shape[0]
    g = torch.Generator(device="cuda").manual_seed(0)
    acts = torch.rand((8, n, k), device="cuda", dtype=torch.float32, generator=g) * 2 - 1
    i = [0]

    def step():
        env.step(acts[i[0] % 8])
        i[0] += 1
    # each way from the same state (a reset with seed 0): the state's impacts, not the order, set the work
    out = {"env.step": n * steps / timed(step, steps)}
    dev = env._runner
    parity = [0]

    def kernels():
        dev.launch(parity[0])
        parity[0] ^= 1
    env.reset(seed=0)
    env.step(acts[0])  # (the actions' buffer holds one set of actions; the kernels alone step on them)
    out["kernels alone"] = n * steps / timed(kernels, steps)
    out["prepared"] = all(p.fast for pair in dev.launches for p in pair)  # (False: numba's dispatcher launched)
    env.reset(seed=0)
    graphed = CudaGraphStep(env)
    out["graph replay"] = n * steps / timed(lambda: graphed(acts[0]), steps)
    arrays = list(dev.st) + [dev.actions, dev.work, dev.reset_obs] + [a for s in dev.sets for part in s for a in part]
    out["bytes per env"] = sum(a.nbytes for a in arrays) / n
    env.close()
    return out


def kernel_rate(env_id, n, steps, **cuda_options) -> float:
    env = make(env_id, n, **cuda_options)
    dev = env._runner
    parity = [0]

    def kernels():
        dev.launch(parity[0])
        parity[0] ^= 1
    r = n * steps / timed(kernels, steps)
    env.close()
    return r


def cpu_rate(env_id: str, n: int, steps: int) -> float:
    import gymnasium as gym

    from devtools.throughput import vector_rate
    return vector_rate(lambda m: gym.make_vec(env_id, num_envs=m, vectorization_mode="vector_entry_point"), n, steps)


def main(argv: list[str] | None = None) -> int:
    from studies.common import header, report_path, table, write
    argv = sys.argv[1:] if argv is None else argv
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small sizes and few steps (a smoke run)")
    ap.add_argument("--out", default=None, help="report path (default runs/reports/throughput_gpu.md; "
                    "docs/throughput_gpu.md for the committed report)")
    ap.add_argument("--env-id", default=ENV_ID)
    ap.add_argument("--sizes", nargs="+", type=int, default=None, help=f"numbers of envs (default {SIZES})")
    ap.add_argument("--variants", action="store_true", help="also time the other ways to build the step's kernels")
    ap.add_argument("--variant-sizes", nargs="+", type=int, default=[65536, 1_048_576],
                    help="the N at which --variants times them (default 65536 1048576)")
    ap.add_argument("--no-cpu", action="store_true", help="skip the CPU backend's column")
    a = ap.parse_args(argv)
    sizes = a.sizes or ((256, 4096) if a.quick else SIZES)
    if any(n < 1 for n in sizes):
        ap.error(f"--sizes must be positive, got {sizes}")
    name = gpu_here()
    if name is None:
        print("throughput_gpu: no CUDA GPU here (numba-cuda and torch see no device; the CUDA simulator does not "
              "count): nothing measured, no report written. The GPU backend is built and tested in simulation "
              "(tests/backends/test_cuda.py).")
        return 0
    from penny_env.backends.env import FAST_MAX_REGISTERS
    rows, var_rows, best = [], [], (0.0, 0)
    for n in sizes:
        steps = 20 if a.quick else max(20, min(400, 2**26 // n))
        r = rates(a.env_id, n, steps)
        c = float("nan") if a.no_cpu else cpu_rate(a.env_id, n, max(2, min(steps, 2**21 // n)))
        best = max(best, (r["env.step"], n))
        rows.append([f"{n:,}", f"{r['env.step']:,.0f}", f"{r['kernels alone']:,.0f}", f"{r['graph replay']:,.0f}",
                     f"{r['env.step'] / r['kernels alone']:.2f}", f"{c:,.0f}", f"{r['env.step'] / c:.1f}x",
                     f"{r['bytes per env']:.0f} B"])
        prepared = r["prepared"]
        print("  ".join(rows[-1]) + f"  (prepared launches: {prepared})", flush=True)
        if a.variants and (n in a.variant_sizes or a.quick):
            v = [f"{n:,}", f"{r['kernels alone']:,.0f}"]
            for opts in VARIANTS:
                v.append(f"{kernel_rate(a.env_id, n, steps, **opts):,.0f}")
            var_rows.append(v)
            print("  variants: " + "  ".join(v), flush=True)
    lines = header("GPU throughput of the vector env", "devtools.throughput_gpu", argv)
    lines += [f"- device: {name}; CPU backend on {os.cpu_count()} cores of the same machine", "",
              f"{a.env_id}, random actions drawn on the device beforehand (float32), torch outputs; env-steps per "
              "second. Kernels alone: the step's prepared launches in a loop (no action copy, no outputs); graph "
              "replay: the step captured in a CUDA graph (backends/cuda_env.CudaGraphStep).", "",
              *table(["N", "env.step", "kernels alone", "graph replay", "env.step / kernels", "CPU (numba, all cores)",
                      "env.step / CPU", "device memory per env"], rows), "",
              "Launches: " + ("prepared once (builder.PreparedLaunch)" if prepared
                              else "through numba dispatcher (the prepared path failed here)") + ".", "",
              f"Best env.step: {best[0]:,.0f} env-steps/s at N = {best[1]:,} (targets: at least 1e9 at the best N, "
              "0.8 of the kernels alone at N >= 65,536, 1.2e7 at N = 4096)."]
    if var_rows:
        heads = ["N", f"split, fast kernel capped at {FAST_MAX_REGISTERS} registers (the default)"] + [
            "one kernel" if o["kernels"] == "one" else
            f"split, {'no cap' if o['max_registers'] is None else str(o['max_registers']) + ' registers'}" for o in VARIANTS]
        lines += ["", "The step's kernels alone, built other ways (env-steps/s):", "", *table(heads, var_rows)]
    path = report_path(a.out, a.quick, "throughput_gpu.md")
    write(str(path), lines)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
