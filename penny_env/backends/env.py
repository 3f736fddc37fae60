"""The env step built for a target: :func:`env_entry_points` returns the typed record of entry points of
one (target, table kind, task), built by backends/builder.py from step/functional.py's stages, the task's
record (step/tasks/) and the compiled physics (backends/physics.py).

Entry points take the constants packed as one float64 array (backends/packing.py) and the records as plain
tuples of arrays (numba unboxes a plain tuple several times faster than a NamedTuple): the small functions
below unpack them and call the stages. On the CPU the vector step is one parallel numba loop (serial for
few envs and in forked children, backends/threads.py); on CUDA every loop is a kernel with one thread per
env, whose body unpacks the constants itself (a kernel takes one pointer for them).
"""
from __future__ import annotations

from pathlib import Path
from typing import Callable, NamedTuple

import math

import numpy as np

from ..physics.build_names import build_supplied
from ..physics.scalar import FAULT_NONE, ImpactBuffers, flow_penny, period_is_free
from ..step import draws, functional
from ..step.functional import (NEXT_STEP, EnvState, PennyState, StepResults, actuate, angle_trig, clear_slots, conclude,
                               distance, env_row, env_step, initial_state, limit_of, observe_row, observe_rows,
                               record_step, reset_row, reset_rows, same_step_reset, step_env, step_envs,
                               write_observation)
from . import cache, generated, packing
from .builder import Builder, check_target
from .interrupts import compiling
from .physics import build_variant, check_kind, physics_build, physics_modules, variant_key

prange = range  # the loops below are kernels on CUDA (backends/builder.py)

# what each build supplies to the entry points below: the unpacker of the packed constants generated for the task's
# constants type (packing.unpacker), and on CUDA numba.cuda (the rare kernel's list is appended to atomically)
BUILD_SUPPLIED = ("unpack", "cuda")
unpack, cuda = build_supplied(__name__, BUILD_SUPPLIED)


class EnvEntryPoints(NamedTuple):
    """The compiled env step of one (target, table kind, task). Single env: ``env_step``, ``initial_state``,
    ``observe_state``; vector env: ``step_envs``, ``reset_rows``, ``observe_rows`` (CPU and python: plain
    callables; CUDA: builder.CudaLoop kernels), and on CUDA ``clear_work_count``, ``fast_step_envs`` and
    ``rare_step_envs``, the step in two kernels after the list's reset (module comment there). ``unpack``: the
    plain unpacker of the constants."""

    target: str
    env_step: Callable
    initial_state: Callable
    observe_state: Callable
    step_envs: Callable
    reset_rows: Callable
    observe_rows: Callable
    unpack: Callable
    fast_step_envs: Callable = None
    rare_step_envs: Callable = None
    clear_work_count: Callable = None


# -- the entry points' bodies (plain Python; copied into each build) ------------------------------------------
# the CPU loops' entry points: records from plain tuples (numba unboxes a plain tuple several times faster than a
# NamedTuple), constants unpacked once per call
def step_envs_packed(st, actions, consts, out, buf):
    """The vector step (CPU and python): records from plain tuples, constants unpacked once."""
    p, m, k = unpack(consts)
    step_envs(EnvState(*st), actions, p, m, k, StepResults(*out), ImpactBuffers(*buf))


def reset_rows_packed(rows, st, consts, obs):
    p, m, k = unpack(consts)
    reset_rows(rows, EnvState(*st), p, m, k, obs)


def observe_rows_packed(rows, st, consts, obs):
    p, m, k = unpack(consts)
    observe_rows(rows, EnvState(*st), p, m, k, obs)


def env_step_packed(st, a0, a1, consts, obs, buf):
    """env_step with st a plain tuple of PennyState's fields, buf a plain tuple of ImpactBuffers' arrays (one
    penny): the observation into row 0 of obs; returns the changed state fields (s, trig, count, dist, steps,
    time), the impact count, reward, terminated, truncated, kinetic energy and limit, flat (fewer objects for
    numba to box: the single env's whole step costs a few microseconds)."""
    p, m, k = unpack(consts)
    b = ImpactBuffers(*buf)
    new, r, te, tu, e, lim = env_step(PennyState(*st), a0, a1, p, m, k, b, 0, obs, 0)
    return new.s, new.trig, new.count, new.dist, new.steps, new.time, b.count[0], r, te, tu, e, lim


def initial_state_packed(key, episode, consts, obs):
    """initial_state of the single env: (s, trig, target, arc, dist); its observation into row 0 of obs."""
    p, m, k = unpack(consts)
    st = initial_state(key, episode, p, m, k)
    write_observation(obs, 0, st, p, k)
    return st.s, st.trig, st.target, st.arc, st.dist


def observe_state_packed(st, consts, obs):
    """The single env at step 0 of PennyState st's state and target (reset options): (trig, dist); the
    observation into row 0 of obs."""
    p, m, k = unpack(consts)
    st = PennyState(*st)
    trig = angle_trig(st.s)
    d = distance(st.s, st.target)
    write_observation(obs, 0, PennyState(st.s, trig, st.target, st.arc, 0, d, 0, 0.0), p, k)
    return trig, d


def step_env_device(i, st, actions, consts, out, buf):
    """One env of the vector step on CUDA (one thread): the constants unpacked by the thread itself."""
    p, m, k = unpack(consts)
    step_env(i, st, actions, p, m, k, out, buf)


def step_envs_device(st, actions, consts, out, buf):
    for i in prange(st.S.shape[1]):
        step_env_device(i, st, actions, consts, out, buf)


def reset_row_device(j, rows, st, consts, obs):
    p, m, k = unpack(consts)
    reset_row(j, rows, st, p, m, k, obs)


def reset_rows_device(rows, st, consts, obs):
    for j in prange(rows.shape[0]):
        reset_row_device(j, rows, st, consts, obs)


def observe_row_device(j, rows, st, consts, obs):
    p, m, k = unpack(consts)
    observe_row(j, rows, st, p, m, k, obs)


def observe_rows_device(rows, st, consts, obs):
    for j in prange(rows.shape[0]):
        observe_row_device(j, rows, st, consts, obs)


# -- the GPU's vector step in two kernels: the common, impact-free step, and the rest ---------------------------------
# A kernel's registers are those of its heaviest path: with the event loop and the reset's draws in it, the step
# kernel needs about 250 per thread (an eighth of an H100's threads resident). The fast kernel runs what most
# envs do at most steps, a period the certificate shows free of impacts (scalar.period_is_free: then
# run_interval is one flow), with the same functions in the same order as step_env; the envs it cannot finish
# (an impact search, a NEXT_STEP reset, a non-finite action; SAME_STEP's reset after a finished step) go on a
# list that the rare kernel, one thread per listed env, finishes with step_env itself (or same_step_reset). The
# list's length is cleared by a one-thread kernel before the fast one: every step is whole in itself, so that a
# CUDA graph may hold any number of steps (a clear by the next step's fast kernel would leave a graph of one
# step, replayed, appending past the list's end).
FULL_STEP, RESET_ONLY = 0, 1
# the fast kernel's per-thread register cap (numba-cuda's max_registers): 80 lets 6 blocks of 128 threads share an
# SM (37.5 % occupancy; unconstrained it takes about 124, 25 %); ptxas reports its spills (docs/gpu.md)
FAST_MAX_REGISTERS = 80


def clear_count_at(i, count):
    count[i] = 0


def clear_work_count(count):
    """The rare kernel's list emptied (count: its length, one int64), before the step's fast kernel."""
    for i in prange(count.shape[0]):
        clear_count_at(i, count)


def enqueue(work, count, i, what):
    """Env i onto the rare kernel's list (atomic: threads append concurrently)."""
    j = cuda.atomic.add(count, 0, 1)
    work[j] = 2 * i + what


def fast_step_env(i, st, actions, p, m, k, out, buf, work, count):
    """Env i's step where it is a certified impact-free period (module comment above), else onto the list."""
    pending = st[10]
    obs = out[0]
    clear_slots(i, buf)
    if p.autoreset == NEXT_STEP and pending[i]:
        enqueue(work, count, i, FULL_STEP)
    else:
        st_i = env_row(st, i)
        a0 = actions[i, 0]
        a1 = actions[i, 1] if p.n_act == 2 else 0.0
        if math.isfinite(a0) and math.isfinite(a1):
            acc1, acc2, ctrl = actuate(a0, a1, p)
            if p.plane or period_is_free(st_i.s, st_i.trig[2], st_i.trig[3], acc1, acc2, p.dt, m):
                s1 = flow_penny(st_i.s, acc1, acc2, p.dt, m.R)
                new, r, te, tu, e, lim = conclude(st_i, s1, p.dt, limit_of(s1, p.dt, FAULT_NONE, p), ctrl, 0, p, k,
                                                  obs, i)
                if record_step(st, i, new, r, te, tu, e, lim, p, out):  # (the shared bookkeeping; the reset: rare kernel)
                    enqueue(work, count, i, RESET_ONLY)
            else:
                enqueue(work, count, i, FULL_STEP)
        else:
            enqueue(work, count, i, FULL_STEP)


def fast_step_envs(st, actions, p, m, k, out, buf, work, count):
    for i in prange(st.S.shape[1]):
        fast_step_env(i, st, actions, p, m, k, out, buf, work, count)


def rare_step_env(j, st, actions, p, m, k, out, buf, work, count):
    """Entry j of the list the fast kernel made: step_env for the env, or SAME_STEP's reset alone."""
    if j < count[0]:
        entry = work[j]
        i = entry // 2
        if entry - 2 * i == FULL_STEP:
            step_env(i, st, actions, p, m, k, out, buf)
        else:
            same_step_reset(st, i, p, m, k, out)


def rare_step_envs(st, actions, p, m, k, out, buf, work, count):
    for j in prange(st.S.shape[1]):
        rare_step_env(j, st, actions, p, m, k, out, buf, work, count)


def _vector_count(args):
    return args[1].shape[0]  # step_envs_packed's actions (N, n_act)


def _rows_count(args):
    return args[0].shape[0]


# -- the build ---------------------------------------------------------------------------------------------------
# the functions the CPU's vector loop has pasted in at the source level (builder.inline_source): every array they
# take from the records is then taken once, before the loop, and none is passed to a call per env
STEP_PASTED = (functional.clear_slots, functional.clear_row, env_step, functional.transition, functional.run_interval,
               functional.conclude, functional.pending_reset, functional.record_step, functional.write_outputs,
               functional.write_state, functional.same_step_reset, functional.reset_env)
_ENTRY: dict = {}  # (target, variant_key(kind), task record, constants type) -> EnvEntryPoints


def float32_bound(value) -> float:
    """A bound as the float32 observation space holds it (Box rounds low and high to float32), as a Python float,
    which holds it exactly."""
    return float(np.float32(value))


def obs_bounds_check(extra_obs):
    """``task_obs_in_bounds(obs, i)``: the task's own observation entries of row i (columns 10 on) within their
    declared bounds (a task record's extra_obs), generated with the bounds as literals (a real file:
    backends/generated.py). The literals are the bounds rounded to float32, as observation_space holds them: numba
    compares the float32 entry with a float64 literal in float64, and the declared 0.1 is below float32(0.1), the
    entry a task writes for 0.1, so the guard refused what the space contains; float32's own bounds are exact in
    float64, and the guard and observation_space.contains agree bound by bound, compiled or not. NaN fails every
    comparison, so it is out of bounds too."""
    terms = [f"({float32_bound(lo)!r} <= obs[i, {10 + j}] <= {float32_bound(hi)!r})" for j, (lo, hi) in enumerate(extra_obs)]
    source = ("def task_obs_in_bounds(obs, i):\n    return " + " and ".join(terms) + "\n") if terms else \
        "def task_obs_in_bounds(obs, i):\n    return True\n"
    f = generated.define("task_obs_in_bounds", source, {}, __name__)["task_obs_in_bounds"]
    return f


def env_modules(record) -> tuple:
    """The modules the env build inlines (their sources go into the copies' names: backends/cache.py): the
    physics, the step, this module, and the modules (with a source file) that define the task's stages."""
    import sys
    stages = [f for f in (record.reward, record.target, record.observation, record.marked_arc) if f is not None]
    task_modules = tuple(dict.fromkeys(m for m in (sys.modules.get(f.__module__) for f in stages)
                                       if m is not None and getattr(m, "__file__", None)))
    return physics_modules() + (functional, draws, sys.modules[__name__], packing) + task_modules


def env_entry_points(target: str, kind: int, record, constants_type, fresh: bool = False,
                     max_registers=None, law: int = -1) -> EnvEntryPoints:
    """The entry points of the env step for ``target`` ("python", "cpu", "cuda"), table kind ``kind`` (the
    Model.kind of the constants they will receive: the compiled physics calls that table's formulas whatever
    Model.kind says; the python target runs any), the task ``record`` (step/tasks/) and its constants' type.
    Built once per process and key; fresh: build anew, keep nothing (the PTX tests). max_registers: CUDA's
    per-thread register cap of the fast step kernel (None: the compiler's choice). law: the Model.law of the
    constants (a user's law is compiled only into the builds that run it: physics.build_laws)."""
    target = check_target(target)
    if target == "python":
        kind, law = -1, -1
    kind = check_kind(kind)
    key = (target, variant_key(kind, law), record, constants_type, max_registers)
    if key in _ENTRY and not fresh:
        return _ENTRY[key]
    with compiling():  # (a Ctrl-C is held while numba loads and the copies are made, and kept: backends/interrupts.py)
        out = _build_entry_points(target, kind, record, constants_type, fresh, max_registers, law)
        if not fresh:
            _ENTRY[key] = out
    return out


def _build_entry_points(target, kind, record, constants_type, fresh, max_registers, law) -> EnvEntryPoints:
    from ..step.functional import EnvParams
    from ..physics.scalar import Model
    phys = physics_build(target, kind, fresh, law)  # (also picks the threading layer: backends/threads.py)
    stages = [f for f in (record.reward, record.target, record.observation, record.marked_arc) if f is not None]
    own = phys.cache and cache.cacheable(stages)
    modules = env_modules(record) if target != "python" else ()
    if own:
        cache.drop_stale_cache(Path(functional.__file__).with_name("__pycache__"), modules)
    # (the variant's name ends with the sources' digest: numba names its cache files after it)
    variant = build_variant(target, kind, modules, record.name) if modules else "python"
    b = Builder(target, variant, cache=own)
    b.extend(phys)
    b.add({k: v for k, v in vars(functional).items() if not callable(v) or isinstance(v, type)})
    b.namespace.update(ImpactBuffers=ImpactBuffers, PennyState=PennyState, EnvState=EnvState,
                       StepResults=StepResults)
    b.add({k: v for k, v in vars(draws).items() if not callable(v)})
    b.copies((draws.draw_mix, draws.draw_stream, draws.draw_uniform))
    # the task's stages under the names the step calls
    b.copy_foreign(record.reward, "task_reward")
    b.copy_foreign(record.target, "task_target")
    if record.observation is not None:
        b.copy_foreign(record.observation, "task_observation")
        b.copy(obs_bounds_check(record.extra_obs), name="task_obs_in_bounds")
    else:
        b.copy(functional.no_task_observation, name="task_observation")
        b.copy(functional.no_task_obs_bounds, name="task_obs_in_bounds")
    if record.marked_arc is not None:
        b.copy_foreign(record.marked_arc, "task_marked_arc")
    else:
        b.copy(functional.no_marked_arc, name="task_marked_arc")
    records = (EnvParams, Model, constants_type)
    unpack = packing.unpacker(records)
    b.namespace.update(packing.record_names(records))
    b.copy(unpack, inline=True)  # (under its build-supplied name)
    b.copies((functional.clip_action, functional.angle_trig, functional.kinetic_energy, functional.distance,
              functional.observation, functional.actuate, functional.termination, functional.initial_state,
              functional.limit_of))
    # inlined: a call that passes arrays increments and decrements their reference counts, atomically
    b.copies((functional.write_observation, functional.env_row, functional.write_state, functional.reset_env,
              functional.clear_slots, functional.write_outputs, functional.pending_reset, functional.same_step_reset,
              functional.record_step, functional.conclude), inline=True)
    if target == "cuda":
        b.supply("cuda", b.cuda)
        b.namespace.update(FULL_STEP=FULL_STEP, RESET_ONLY=RESET_ONLY, math=math)
        b.copies((functional.transition, env_step, step_env, functional.reset_row, functional.observe_row,
                  step_env_device, reset_row_device, observe_row_device, enqueue, fast_step_env, rare_step_env,
                  clear_count_at))
        step = b.kernel(step_envs_device)
        resets = b.kernel(reset_rows_device)
        observes = b.kernel(observe_rows_device)
        single = initial = observe_state = None
        fast, rare = b.kernel(fast_step_envs, max_registers=max_registers), b.kernel(rare_step_envs)
        clear = b.kernel(clear_work_count)
    else:
        # inlined into the entries and the loop: called as functions, their many arguments cost more than
        # their work (the loop's bodies write by position, see functional.write_state)
        b.copies((functional.transition, env_step), inline=True)
        single = b.copy(env_step_packed)
        initial = b.copy(initial_state_packed)
        observe_state = b.copy(observe_state_packed)
        b.copies((step_env, functional.reset_row, functional.observe_row), inline=True)
        # one parallel call at a time (threads.locked), serially for few envs or in a forked child; the step
        # and the event loop's driver pasted into the loop (builder.inline_source)
        step = b.loop(step_envs, entry=step_envs_packed, count=_vector_count, inline=STEP_PASTED)
        resets = b.loop(reset_rows, entry=reset_rows_packed, count=_rows_count)
        observes = b.loop(observe_rows, entry=observe_rows_packed, count=_rows_count)
        fast = rare = clear = None
    b.check_supplied()
    return EnvEntryPoints(target, single, initial, observe_state, step, resets, observes, unpack, fast, rare, clear)


def cuda_launch_functions(entry: EnvEntryPoints) -> dict:
    """The CUDA kernels of ``entry`` by name (for the PTX tests and the register report)."""
    return {"step_envs": entry.step_envs, "reset_rows": entry.reset_rows, "observe_rows": entry.observe_rows}

