"""The backends layer: every compile concern of penny_env in one place.

The physics (penny_env/physics/) and the env step's stages (penny_env/step/functional.py, step/tasks/) are
plain Python and import no numba. This layer compiles them:

==================  ===========================================================================================
stepping.py         the envs' one door into this layer: the backend's choice, the single env's step, the vector
                    env's runner (CPU or CUDA), packed, announced and warm (envs/ imports nothing else here)
builder.py          copies of plain functions for a target ("python", "cpu": numba, "cuda": numba-cuda), loops
                    over pennies (parallel on the CPU, kernels on CUDA); loud failures (BuildError)
generated.py        generated source (loops, kernels, unpackers, the law dispatch) written to real files
cache.py            numba's disk cache: which builds may be cached, under which names; the first-use line
numba_repairs.py    two defects of numba's disk cache, repaired (concurrent saves; parallel loops' callers)
interrupts.py       Ctrl-C around compiles and llvmlite's finalizers; numba imported once, repaired
threads.py          the CPU's threading: layer, idle policy, the lock around parallel calls, serial paths
choice.py           which backend a table runs on
numba_math.py,      the math namespaces (``xp``) of the CPU and CUDA copies
cuda_math.py
packing.py          the step's constants as one float64 array, and their generated unpacker
physics.py          the compiled physics for one (target, table kind)
batch.py            CompiledBatch: batches of pennies over an interval (penny_env.batch, simulate's batches)
env.py              the env step for one (target, table kind, task): a typed record of entry points
runner.py           the vector env's runner interface (Runner, a Protocol) and its CPU runner
cuda_env.py         the vector env's step resident on a GPU (the CUDA runner), and its CUDA-graph capture
==================  ===========================================================================================

One function per target and table kind returns a typed record of entry points:
:func:`env_entry_points` (the env step) and :func:`batch_entry_points` (the batch loops). The few names a build
puts into its namespace for the plain functions to call (a task's stages, a table's formulas, the constants'
unpacker) are declared by the modules that call them (``BUILD_SUPPLIED``, physics/build_names.py), and every
build checks that it supplies exactly those its copies call (builder.Builder.check_supplied).
"""
from __future__ import annotations

from typing import Callable, NamedTuple

from .builder import TARGETS, BuildError, check_target, cuda_available
from .choice import available, choose_backend, compiles
from .env import EnvEntryPoints, env_entry_points


class BatchEntryPoints(NamedTuple):
    """The compiled batch loops of one (target, table kind): ``advance_batch(S, acc1, acc2, dt, m, plane,
    stop_after, out, trig, elapsed, buf)`` and ``first_impact_batch(S, acc1, acc2, horizon, m, rounds, t_out,
    end_out)`` (physics/batch_loops.py), ``functions`` (every compiled physics function by name) and ``laws``
    (the compiled laws, in laws.COMPILED_LAWS' order)."""

    target: str
    advance_batch: Callable
    first_impact_batch: Callable
    functions: dict
    laws: list


def batch_entry_points(target: str, kind: int, law: int = -1) -> BatchEntryPoints:
    """The batch loops for ``target``, table kind ``kind`` (Model.kind; the python target runs any) and law
    ``law`` (Model.law: the build holds the built-in laws and that one)."""
    from .physics import physics_build
    b = physics_build(target, kind, law=law)
    return BatchEntryPoints(b.target, b.functions["advance_batch"], b.functions["first_impact_batch"], b.functions,
                            b.laws)


__all__ = ["TARGETS", "BuildError", "check_target", "cuda_available", "available", "choose_backend", "compiles",
           "EnvEntryPoints", "env_entry_points", "BatchEntryPoints", "batch_entry_points"]
