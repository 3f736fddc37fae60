"""Every CUDA kernel of the package, compiled to PTX without a GPU (numba-cuda's ``compile_ptx``).

``python -m penny_env.analysis.cuda_ptx [--cc 9.0 8.0]`` compiles, for every registered table kind and the
open plane, the kernels of the GPU backend (physics/builder.py, target "cuda"): the vector env's step and
observation kernels (envs/functional.py), its reset kernel (envs/cuda_step.py), and the batch's event loop
and first-impact search (physics/compiled.py); the law dispatch inside them covers the built-in laws (a
user's law enters only the builds that run it: compiled.build_laws).
It prints one line per kernel with the PTX size and the compile time.

numba-cuda looks up the current device's compute capability when it compiles device functions; on a
machine without a driver pass ``stand_in=True`` (the command does) to answer that look-up with the
compute capability asked for. Each compute capability is built from scratch (``fresh``): device
functions are compiled once per build.
"""
from __future__ import annotations

import argparse
import contextlib
import time

import numpy as np


def example_arguments(n: int = 4, K: int = 2):
    """Arguments of the right types for each kernel (name -> tuple), from the default reach scene (the
    constants' types do not depend on the table: the kernels are specialised by their build's kind)."""
    from ..envs.core import Core
    from ..envs.functional import EnvState, StepResults, env_params
    from ..envs.scene import resolve
    from ..physics.scalar import impact_buffers, scalar_model
    scene, task = resolve("ellipse", "reach")
    core = Core(scene, task, backend="python")
    p, m, k = env_params(core), scalar_model(core.params, core.table, core.law, core.settings), core.k
    z, i = np.zeros, np.int64
    st = EnvState(z((6, n)), z((4, n)), z((2, n)), z((2, n)), z(n, i), z(n), z(n, i), z(n))
    out = StepResults(z((n, 11), np.float32), z(n), z(n, bool), z(n, bool), z(n), z(n, np.int8))
    buf = impact_buffers(n, K)
    rows = z(n, i)
    return {
        "step_envs": (st, z((n, 2)), z(n, bool), p, m, k, out, buf),
        "observe_rows": (rows, st, p, out.obs),
        "reset_rows": (rows, z((6, n)), z((2, n)), z((2, n)), z(n), st),
        "advance_batch": (z((6, n)), z(n), z(n), z(n), m, False, 0, z((6, n)), z((4, n)), z(n), buf),
        "first_impact_batch": (z((6, n)), z(n), z(n), z(n), m, 64, z(n), z(n, i)),
    }


def cuda_kernels(kind: int, fresh: bool = True) -> dict:
    """name -> launcher (physics/builder.py) of every CUDA kernel for table kind ``kind``; under "laws", the
    build's device functions of its laws, the built-in ones (compiled into the kernels by the law dispatch)."""
    from ..envs import cuda_step
    from ..envs.functional import compiled_env_functions
    from ..physics.builder import Builder
    env = compiled_env_functions(kind, "cuda", fresh=fresh)
    b = Builder("cuda", f"reset_{kind}")
    b.copy(cuda_step.reset_row)
    return {"step_envs": env["step_envs_kernel"], "observe_rows": env["observe_rows_kernel"],
            "reset_rows": b.loop(cuda_step.reset_rows), "advance_batch": env["physics"]["advance_batch"],
            "first_impact_batch": env["physics"]["first_impact_batch"], "laws": env["laws"]}


@contextlib.contextmanager
def device_stand_in(cc):
    """numba-cuda's current-device look-up (made when it compiles device functions) answered with a
    stand-in of compute capability ``cc``, for compiling without a driver."""
    from numba.cuda import dispatcher

    class StandIn:
        compute_capability = tuple(cc)
        name = f"stand-in sm_{cc[0]}{cc[1]}"

    saved = dispatcher.get_current_device
    dispatcher.get_current_device = StandIn
    try:
        yield
    finally:
        dispatcher.get_current_device = saved


def compile_kernels(kind: int, cc=(9, 0), stand_in=False) -> dict:
    """name -> (PTX text, seconds) of every kernel for table kind ``kind``, built from scratch for ``cc``; under
    "laws", the number of device-code signatures each registered law was compiled for (at least 1 each)."""
    import numba
    from numba import cuda
    args = example_arguments()
    out = {}
    with device_stand_in(cc) if stand_in else contextlib.nullcontext():
        kernels = cuda_kernels(kind)
        laws = kernels.pop("laws")
        for name, launcher in kernels.items():
            sig = tuple(numba.typeof(a) for a in args[name])
            t0 = time.perf_counter()
            ptx, _ = cuda.compile_ptx(launcher.kernel.py_func, sig, cc=tuple(cc))
            out[name] = (ptx, time.perf_counter() - t0)
    out["laws"] = [len(law.overloads) for law in laws]
    return out


def main(argv=None) -> int:
    from ..physics.tables import COMPILED_FORMULAS
    from ..physics.compiled import variant_name
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cc", nargs="+", default=["9.0", "8.0"], help="compute capabilities (major.minor)")
    ap.add_argument("--kinds", nargs="+", type=int, default=None, help="table kinds (-1: the plane); default: all")
    a = ap.parse_args(argv)
    ccs = [tuple(int(v) for v in c.split(".")) for c in a.cc]
    kinds = a.kinds if a.kinds is not None else [-1] + list(range(len(COMPILED_FORMULAS)))
    for cc in ccs:
        for kind in kinds:
            out = compile_kernels(kind, cc, stand_in=True)
            print(f"sm_{cc[0]}{cc[1]} {variant_name(kind):40s} laws compiled: {out.pop('laws')}")
            for name, (ptx, sec) in out.items():
                print(f"sm_{cc[0]}{cc[1]} {variant_name(kind):40s} {name:20s} {len(ptx):8d} chars PTX  {sec:6.2f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
