"""Every CUDA kernel of the package, compiled to PTX without a GPU, and its registers from ptxas.

``python -m devtools.cuda_kernels [--cc 9.0 8.0] [--kinds ...] [--ptxas PATH] [--max-registers 80] [--out FILE]``
compiles, for every registered table kind and the open plane, the kernels of the GPU backend
(backends/builder.py, target "cuda"): the vector env's step (with its autoreset), reset and observation
kernels (backends/env.py), and the batch's event loop and first-impact search (backends/physics.py); the law
dispatch inside them covers every registered law. With ptxas (the CUDA toolkit's PTX assembler, found on PATH,
in $CUDA_HOME/bin or /usr/local/cuda*/bin) it reports each kernel's registers per thread, stack frame and
spills, and the theoretical occupancy they allow (CUDA's occupancy rules for the compute capability, 128
threads per block as the backend launches), and writes that table (``--out``). The backend caps the fast step
kernel at backends/env.FAST_MAX_REGISTERS registers: ``--max-registers`` with that value reports the kernel as
built (docs/cuda_kernels.md: ``--cc 9.0 --max-registers 80 --out docs/cuda_kernels.md``); without it the fast
kernel is reported uncapped.

numba-cuda looks up the current device's compute capability when it compiles device functions; on a machine
without a driver the command answers that look-up with a stand-in of the compute capability asked for. Each
compute capability is built from scratch (``fresh``).
"""
from __future__ import annotations

import contextlib
import glob
import os
import re
import shutil
import subprocess
import tempfile
import time

import numpy as np

THREADS = 128  # backends.builder.CUDA_THREADS


def example_arguments(n: int = 4, K: int = 2, task="impacts"):
    """Arguments of the right types for each kernel (name -> tuple): arrays as the device step holds them (the
    constants' types do not depend on the table: the kernels are specialised by their build's kind)."""
    from penny_env.backends.packing import pack
    from penny_env.envs.core import Core
    from penny_env.step.functional import EnvState, StepResults, env_params
    from penny_env.envs.scene import resolve
    from penny_env.physics.scalar import ImpactBuffers, impact_buffers, scalar_model
    scene, tk = resolve("ellipse", task)
    core = Core(scene, tk, backend="python")
    p, m = env_params(core), scalar_model(core.params, core.table, core.law, core.settings)
    consts = pack(p, m, core.k)
    z, i = np.zeros, np.int64
    st = EnvState(z((6, n)), z((4, n)), z((2, n)), z((2, n)), z(n, i), z(n), z(n, i), z(n), z(n, np.uint64), z(n, i),
                  z(n, bool))
    d = core.obs_dim
    out = StepResults(z((n, d), np.float32), z(n), z(n, bool), z(n, bool), z(n), z(n, np.int8), z(n), z(n), z(n, i),
                      z((0, d), np.float32), z(n, bool))
    env_buf = ImpactBuffers(z(n, i), z((K, n)), z((K, n), np.int8), z((0, 6, n)), z((0, n), np.int8), z(n, i),
                            z(n, np.int8))
    buf = impact_buffers(n, K)
    rows = z(n, i)
    work = (z(n, i), z(1, i))
    return {
        "step_envs": (st, z((n, 2)), consts, out, env_buf),
        "fast_step_envs": (st, z((n, 2)), p, m, core.k, out, env_buf) + work,
        "rare_step_envs": (st, z((n, 2)), p, m, core.k, out, env_buf) + work,
        "clear_work_count": (z(1, i),),
        "reset_rows": (rows, st, consts, out.obs),
        "observe_rows": (rows, st, consts, out.obs),
        "advance_batch": (z((6, n)), z(n), z(n), z(n), m, False, 0, z((6, n)), z((4, n)), z(n), buf),
        "first_impact_batch": (z((6, n)), z(n), z(n), z(n), m, 64, z(n), z(n, i)),
    }


def cuda_kernels(kind: int, task="impacts", fresh: bool = True, max_registers=None) -> dict:
    """name -> builder.CudaLoop of every CUDA kernel for table kind ``kind`` and a task; under "laws", the
    build's device functions of the registered laws (compiled into the kernels by the law dispatch)."""
    from penny_env.backends import batch_entry_points
    from penny_env.backends.env import env_entry_points
    from penny_env.backends.physics import physics_build
    from penny_env.envs.core import Core
    from penny_env.envs.scene import resolve
    core = Core(*resolve("ellipse", task), backend="python")
    env = env_entry_points("cuda", kind, core.task_record, type(core.k), fresh=fresh, max_registers=max_registers)
    phys = physics_build("cuda", kind) if not fresh else None
    batch = batch_entry_points("cuda", kind) if phys is not None else None
    if batch is None:
        from penny_env.backends import physics as bp
        b = bp.physics_build("cuda", kind, fresh=True)
        loops = (b.functions["advance_batch"], b.functions["first_impact_batch"], b.laws)
    else:
        loops = (batch.advance_batch, batch.first_impact_batch, batch.laws)
    return {"step_envs": env.step_envs, "fast_step_envs": env.fast_step_envs, "rare_step_envs": env.rare_step_envs,
            "clear_work_count": env.clear_work_count,
            "reset_rows": env.reset_rows, "observe_rows": env.observe_rows,
            "advance_batch": loops[0], "first_impact_batch": loops[1], "laws": loops[2]}


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


def compile_kernels(kind: int, cc=(9, 0), stand_in=False, names=None, max_registers=None) -> dict:
    """name -> (PTX text, seconds) of every kernel (or those in ``names``) for table kind ``kind``, built from
    scratch for ``cc``; under "laws", the number of device-code signatures each registered law was compiled for."""
    import numba
    from numba import cuda
    args = example_arguments()
    out = {}
    with device_stand_in(cc) if stand_in else contextlib.nullcontext():
        kernels = cuda_kernels(kind, max_registers=max_registers)
        laws = kernels.pop("laws")
        for name, launcher in kernels.items():
            if names is not None and name not in names:
                continue
            sig = tuple(numba.typeof(a) for a in args[name])
            t0 = time.perf_counter()
            ptx, _ = cuda.compile_ptx(launcher.kernel.py_func, sig, cc=tuple(cc))
            out[name] = (ptx, time.perf_counter() - t0)
    out["laws"] = [len(law.overloads) for law in laws]
    return out


def find_ptxas():
    """The ptxas executable: on PATH, in $CUDA_HOME/bin, or the newest /usr/local/cuda*/bin; None if absent."""
    found = shutil.which("ptxas")
    if found:
        return found
    for root in [os.environ.get("CUDA_HOME", "")] + sorted(glob.glob("/usr/local/cuda*"), reverse=True):
        path = os.path.join(root, "bin", "ptxas")
        if root and os.path.exists(path):
            return path
    return None


def ptxas_usage(ptx: str, cc=(9, 0), ptxas=None, max_registers=None) -> dict:
    """{"registers", "stack", "spill_stores", "spill_loads"} of the kernel in ``ptx``, from ``ptxas -v``."""
    ptxas = ptxas or find_ptxas()
    if ptxas is None:
        raise FileNotFoundError("ptxas not found (the CUDA toolkit's PTX assembler): set CUDA_HOME or put it on PATH")
    with tempfile.TemporaryDirectory() as tmp:
        src = os.path.join(tmp, "k.ptx")
        with open(src, "w") as f:
            f.write(ptx)
        cmd = [ptxas, f"-arch=sm_{cc[0]}{cc[1]}", "-v", src, "-o", os.path.join(tmp, "k.cubin")]
        if max_registers:
            cmd.insert(2, f"-maxrregcount={int(max_registers)}")
        r = subprocess.run(cmd, capture_output=True, text=True, check=True)
    text = r.stdout + r.stderr
    regs = re.search(r"Used (\d+) registers", text)
    frame = re.search(r"(\d+) bytes stack frame, (\d+) bytes spill stores, (\d+) bytes spill loads", text)
    if regs is None or frame is None:
        raise RuntimeError(f"unexpected ptxas output: {text[-500:]}")
    return {"registers": int(regs.group(1)), "stack": int(frame.group(1)), "spill_stores": int(frame.group(2)),
            "spill_loads": int(frame.group(3))}


def occupancy(registers: int, cc=(9, 0), threads: int = THREADS) -> float:
    """Theoretical occupancy (resident warps / the SM's maximum) of a kernel using ``registers`` per thread, in
    blocks of ``threads``, limited by registers and blocks per SM (no shared memory): CUDA's occupancy rules for
    compute capability 8.0 and 9.0 (65,536 registers per SM allocated per warp in units of 256, 64 warps and 32
    blocks per SM at most)."""
    warps_per_block = -(-threads // 32)
    regs_per_warp = -(-registers * 32 // 256) * 256
    max_warps = 64
    blocks_by_regs = (65536 // regs_per_warp) // warps_per_block
    blocks = min(blocks_by_regs, 32, max_warps // warps_per_block)
    return blocks * warps_per_block / max_warps


def main(argv=None) -> int:
    from lab.common import report_command
    from penny_env.backends.physics import variant_name
    from penny_env.physics.tables import COMPILED_FORMULAS

    def options(ap):
        ap.add_argument("--cc", nargs="+", default=["9.0"], help="compute capabilities (major.minor)")
        ap.add_argument("--kinds", nargs="+", type=int, default=None, help="table kinds (-1: the plane); default: all")
        ap.add_argument("--ptxas", default=None, help="path of ptxas (default: found automatically)")
        ap.add_argument("--max-registers", type=int, default=None, help="numba-cuda's max_registers for the step kernel")
    rep = report_command("devtools.cuda_kernels", "cuda_kernels.md", __doc__.splitlines()[0], argv, options=options,
                         quick="the open plane's small kernels (observe_rows, clear_work_count) at the first --cc only, "
                         "for the tests", out_help="the register table (markdown)")
    a = rep.args
    ccs = [tuple(int(v) for v in c.split(".")) for c in a.cc]
    kinds = a.kinds if a.kinds is not None else [-1] + list(range(len(COMPILED_FORMULAS)))
    if a.quick:
        ccs, kinds = ccs[:1], [-1]
    names = {"observe_rows", "clear_work_count"} if a.quick else None
    ptxas = a.ptxas or find_ptxas()
    rows = []
    for cc in ccs:
        for kind in kinds:
            out = compile_kernels(kind, cc, stand_in=True, names=names, max_registers=a.max_registers)
            print(f"sm_{cc[0]}{cc[1]} {variant_name(kind):40s} laws compiled: {out.pop('laws')}")
            for name, (ptx, sec) in out.items():
                line = f"sm_{cc[0]}{cc[1]} {variant_name(kind):40s} {name:20s} {len(ptx):8d} chars PTX  {sec:6.2f} s"
                if ptxas:
                    u = ptxas_usage(ptx, cc, ptxas, a.max_registers if name == "fast_step_envs" else None)
                    occ = occupancy(u["registers"], cc)
                    line += (f"  {u['registers']:4d} registers  {u['stack']:4d} B stack  "
                             f"{u['spill_stores']}/{u['spill_loads']} B "
                             f"spills  occupancy {occ:.1%}")
                    rows.append((f"sm_{cc[0]}{cc[1]}", variant_name(kind), name, u, occ))
                print(line, flush=True)
    if rows:
        import datetime
        import platform
        lines = ["# Registers and theoretical occupancy of the CUDA kernels", "",
                 f"`python -m devtools.cuda_kernels --cc {' '.join(a.cc)}"
                 + (f" --max-registers {a.max_registers}" if a.max_registers else "") + f" --out {rep.out.name}` on "
                 f"{platform.node() or 'this machine'} (no GPU: PTX from numba-cuda, registers from `ptxas -v`), "
                 f"{datetime.date.today().isoformat()}. Occupancy: resident warps per SM over 64, from registers alone "
                 f"(blocks of {THREADS} threads, no shared memory).", "",
                 "| cc | table | kernel | registers | stack [B] | spill stores / loads [B] | theoretical occupancy |",
                 "|---|---|---|---:|---:|---:|---:|"]
        for cc, table, name, u, occ in rows:
            lines.append(f"| {cc} | {table} | {name} | {u['registers']} | {u['stack']} | {u['spill_stores']} / "
                         f"{u['spill_loads']} | {occ:.1%} |")
        rep.write(lines)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
