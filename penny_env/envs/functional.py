"""One environment step, written once, as functions of (state, action, params).

In the style of Gymnasium's functional environments (gymnasium/envs/phys2d/cartpole.py) and gymnax:
plain floats, tuples and NamedTuples of constants, no objects. PennyEnv calls :func:`env_step` for
its one penny; PennyVectorEnv calls :func:`step_envs`, a loop over the same :func:`env_step` (a
numba ``prange`` when compiled for the CPU, a kernel with one thread per env for CUDA: physics/builder.py). So a sub-env of the vector env and a single env run the very same
operations, bitwise.

* :func:`observe`: the observation of a state (layout in PennyEnv's docstring), a tuple of floats;
  :func:`write_row` stores it as a float32 row.
* :func:`env_step`: actions -> (the penny over one control period: physics/scalar.py's run_interval,
  the event loop's one driver), reward, termination, truncation, observation; the state is a
  :class:`PennyState` record, the vector env's an :class:`EnvState` of arrays.

The initial states are sampled by ``Core.sample`` (numpy, counter based, see core.py): resets are
rare, and numpy draws every resetting env at once.

Everything here is numba-compatible. :func:`compiled_env_functions` compiles copies of these
functions whose globals hold the compiled physics (physics/compiled.py); uncompiled (backend
"python") they run as they are, on physics/scalar.py's plain-Python functions, for debugging.
"""
from __future__ import annotations

import math
import types
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..physics.kernels import SCALAR
from ..physics.scalar import (FAULT_ENERGY, FAULT_NONE, FAULT_NONFINITE, NO_ARC, WHOLE_WALL, ImpactBuffers, Model,
                              clear_row, run_interval)
from .tasks import TaskConstants, step_reward

XP = SCALAR      # the math namespace of tasks.py's formulas (numba_math in the compiled copies)
prange = range   # numba.prange in the compiled copies

_COMPILED: dict = {}  # (target,) + physics/compiled.py's variant_key(kind, law) -> compiled entry points

# info["limit"]: which documented limit ended an episode (truncated), docs/envs.md#limits; 3 to 5: the event
# loop's run-time guard stopped the step at an impact (scalar.FAULT_* + 2, physics/faults.py)
LIMIT_NONE, LIMIT_SPEED, LIMIT_IMPACTS = 0, 1, 2
LIMIT_LAW_NONFINITE, LIMIT_LAW_ENERGY, LIMIT_OUTSIDE_WALL = 3, 4, 5
LIMIT_NAMES = ("", "speed", "impacts", "law_nonfinite", "law_energy", "outside_wall")


class EnvParams(NamedTuple):
    """The numbers of a scene the step needs besides the physics Model and the TaskConstants."""

    n_act: int
    steer_only: bool   # one control, and it is u1
    gain1: float       # acc1 = a * gain1 [rad/s^2]
    gain2: float
    dt: float          # control period [s]
    max_steps: int     # truncation after this many steps (a huge number: never)
    plane: bool        # no table: every period is one flow
    impacts: bool      # the impacts task (observation 10 is the arc count)
    inv_L: float
    s_W: float
    s_w: float
    goal: int
    Itot: float
    J: float
    W_max: float       # |theta_dot| beyond which the next step could pass MAX_ANGULAR_SPEED: LIMIT_SPEED
    w_max: float       # |phi_dot| likewise (and MAX_STEERED_PHASE)


def env_params(core, max_steps=None) -> EnvParams:
    """EnvParams of a Core; max_steps overrides the task's (None: the task's)."""
    steps = core.max_steps if max_steps is None else max_steps
    W_max, w_max = core.scene.step_speed_limits()
    return EnvParams(n_act=core.n_act, steer_only=core.controls == (0,), gain1=float(core.gain1),
                     gain2=float(core.gain2), dt=float(core.dt), max_steps=int(steps),
                     plane=bool(core.plane), impacts=bool(core.impacts), inv_L=float(core.inv_L),
                     s_W=float(core.s_W), s_w=float(core.s_w), goal=int(core.k.goal),
                     Itot=float(core.Itot), J=float(core.J), W_max=float(W_max), w_max=float(w_max))


def clip_action(v):
    """An action entry clipped to [-1, 1]."""
    return -1.0 if v < -1.0 else (1.0 if v > 1.0 else v)


def observe(s, trig, tx, ty, count, p):
    """The observation of state s as an 11-tuple of floats (layout in PennyEnv's docstring; entry 10,
    the arc count, belongs to the impacts task only and is 0 otherwise); trig = (cos theta,
    sin theta, cos phi, sin phi) of s; (tx, ty) the target; count the arc impacts so far."""
    x, y = s[0], s[1]
    inv = p.inv_L
    ox, oy = x * inv, y * inv
    rx, ry = (tx - x) * inv, (ty - y) * inv
    if p.plane:
        ox, oy, rx, ry = math.tanh(ox), math.tanh(oy), math.tanh(rx), math.tanh(ry)
    arcs = min(count / p.goal, 1.0) if p.impacts else 0.0
    return (ox, oy, trig[0], trig[1], trig[2], trig[3], math.tanh(s[4] * p.s_W), math.tanh(s[5] * p.s_w), rx, ry, arcs)


def write_row(obs, i, o):
    """Row i of the float32 observations obs (N, obs_dim) from observe()'s tuple (indexing obs
    in place: a row view would touch the array's shared reference count from every thread)."""
    obs[i, 0] = o[0]  # (unrolled: constant indices into the tuple compile to plain moves)
    obs[i, 1] = o[1]
    obs[i, 2] = o[2]
    obs[i, 3] = o[3]
    obs[i, 4] = o[4]
    obs[i, 5] = o[5]
    obs[i, 6] = o[6]
    obs[i, 7] = o[7]
    obs[i, 8] = o[8]
    obs[i, 9] = o[9]
    if obs.shape[1] > 10:
        obs[i, 10] = o[10]


def kinetic_energy(s, p):
    """0.5 (I + m R^2) theta_dot^2 + 0.5 J phi_dot^2 of state s (a tuple, or a (6, N) array: the resets),
    the info's ``kinetic_energy``: one formula for the single and the vector env, bitwise the same.
    Squares as products: numba and numpy square by multiplying, but Python's float ``**`` calls libm's
    pow, which here differs from x * x in about 1 of 1300 draws (found by tests/test_env_step.py)."""
    W, w = s[4], s[5]
    return 0.5 * (p.Itot * (W * W) + p.J * (w * w))


def angle_trig(s):
    """(cos theta, sin theta, cos phi, sin phi) of state s."""
    return math.cos(s[2]), math.sin(s[2]), math.cos(s[3]), math.sin(s[3])


def initial_observation(obs, s, tx, ty, p):
    """Row 0 of obs (1, obs_dim) from observe() of a fresh episode (count 0); returns angle_trig(s)."""
    trig = angle_trig(s)
    write_row(obs, 0, observe(s, trig, tx, ty, 0, p))
    return trig


# -- the step's records --------------------------------------------------------------------------------
class PennyState(NamedTuple):
    """One env between two steps, in plain floats (the single env's state, a row of :class:`EnvState`)."""

    s: tuple         # (x, y, theta, phi, theta_dot, phi_dot)
    trig: tuple      # angle_trig(s)
    target: tuple    # (tx, ty)
    arc: tuple       # (cos b, sin b) of the marked arc's centre (the impacts task)
    count: int       # arc impacts so far
    dist: float      # distance to the target
    steps: int       # steps so far
    time: float      # simulated time since the reset [s]


class EnvState(NamedTuple):
    """The vector env's state, arrays over its N envs: S (6, N), trig (4, N), target (2, N), arc (2, N),
    count (N,) int64, dist (N,), steps (N,) int64, time (N,)."""

    S: object
    trig: object
    target: object
    arc: object
    count: object
    dist: object
    steps: object
    time: object


class StepResults(NamedTuple):
    """What a step returns per env, arrays over N envs: obs (N, obs_dim) float32, reward (N,), terminated
    and truncated (N,) bool, kinetic_energy (N,), limit (N,) int8 (a LIMIT_* code). The impacts go into
    a scalar.ImpactBuffers (count, times, ends, ...)."""

    obs: object
    reward: object
    terminated: object
    truncated: object
    kinetic_energy: object
    limit: object


def _check_positions():
    """step_env and observe_row take the arrays they write by position: the records' fields must stay in
    this order."""
    assert EnvState._fields == ("S", "trig", "target", "arc", "count", "dist", "steps", "time")
    assert StepResults._fields == ("obs", "reward", "terminated", "truncated", "kinetic_energy", "limit")
    assert ImpactBuffers._fields == ("count", "time", "end", "post", "rest", "arc_count", "fault")  # (also scalar.clear_row)


_check_positions()


def arc_window(st, p, k):
    """The marked arc of scalar.record_impact for the state st: the task's arc (the impacts task), the
    whole wall when its half-width is pi, none otherwise (nothing to count)."""
    if not p.impacts:
        return NO_ARC
    if k.all_arc:
        return (st.arc[0], st.arc[1], WHOLE_WALL[1])
    return (st.arc[0], st.arc[1], k.cos_hw)


def env_step(st, a0, a1, p, m, k, buf, row):
    """One step of one env from PennyState st: clip the actions (a1 unused with one control), advance the
    penny over the control period (scalar.run_interval, one call of the event loop: its per-call event
    cap, m.max_events impacts, bounds the step's work; the impacts go into row ``row`` of the
    ImpactBuffers buf, the marked arc's impacts counted there too), reward, termination, truncation and
    observation.

    The step is truncated at max_steps, and where the physics reaches a documented limit (the
    episode ends, the motion is never altered): LIMIT_IMPACTS when the period needed more than the
    event cap's impacts (the state is then the one at `elapsed` < dt), LIMIT_SPEED when the new
    state's |theta_dot| > p.W_max or |phi_dot| > p.w_max (a further step could pass
    MAX_ANGULAR_SPEED), and LIMIT_LAW_NONFINITE, LIMIT_LAW_ENERGY, LIMIT_OUTSIDE_WALL where the event loop's
    run-time guard stopped the period at an impact (a law or a table breaking its contract, physics/faults.py;
    the state is the one of that impact, finite). So every step does bounded work: at most m.max_events
    impacts, from a state within the speed limits.

    Returns (new PennyState, observation (observe()'s tuple), reward, terminated, truncated, kinetic
    energy, limit)."""
    a0 = clip_action(a0)
    if p.n_act == 2:
        a1 = clip_action(a1)
        acc1, acc2 = a0 * p.gain1, a1 * p.gain2
        ctrl = (a0 * a0 + a1 * a1) / 2
    else:
        acc1, acc2 = (a0 * p.gain1, 0.0) if p.steer_only else (0.0, a0 * p.gain2)
        ctrl = (a0 * a0) / 1
    s1, elapsed = run_interval(st.s, st.trig[2], st.trig[3], acc1, acc2, p.dt, m, p.plane, False, 0, buf, row,
                               arc_window(st, p, k))
    limit = LIMIT_NONE
    if elapsed < p.dt:
        # the event cap, or the run-time guard at an impact (scalar.advance_into; the fault is read only here,
        # off the hot path: a guard's stop at an impact exactly at the period's end is seen at the next step,
        # which meets that impact again at once)
        fault = buf.fault[row]
        if fault == FAULT_NONE:
            limit = LIMIT_IMPACTS
        elif fault == FAULT_NONFINITE:
            limit = LIMIT_LAW_NONFINITE
        elif fault == FAULT_ENERGY:
            limit = LIMIT_LAW_ENERGY
        else:
            limit = LIMIT_OUTSIDE_WALL
    elif abs(s1[4]) > p.W_max or abs(s1[5]) > p.w_max:
        limit = LIMIT_SPEED
    count = st.count + buf.arc_count[row]
    tx, ty = st.target
    dx, dy = tx - s1[0], ty - s1[1]
    d = math.sqrt(dx * dx + dy * dy)
    r, success = step_reward(k, st.dist, d, s1[4], s1[5], ctrl, buf.arc_count[row], count, XP)
    trig1 = angle_trig(s1)
    o = observe(s1, trig1, tx, ty, count, p)
    truncated = st.steps + 1 >= p.max_steps or limit != LIMIT_NONE
    new = PennyState(s1, trig1, st.target, st.arc, count, d, st.steps + 1, st.time + elapsed)
    return new, o, r, bool(success), truncated, kinetic_energy(s1, p), limit


def env_row(st, i):
    """Row i of the EnvState st as a PennyState."""
    S, tr = st.S, st.trig
    return PennyState((S[0, i], S[1, i], S[2, i], S[3, i], S[4, i], S[5, i]), (tr[0, i], tr[1, i], tr[2, i], tr[3, i]),
                      (st.target[0, i], st.target[1, i]), (st.arc[0, i], st.arc[1, i]), st.count[i], st.dist[i],
                      st.steps[i], st.time[i])


def step_env(i, st, actions, skip, p, m, k, out, buf):
    """env_step of env i of the EnvState st in place (st's row advances; out's row and buf's row receive
    the step's results; the info's impact times are NaN-padded, its ends 0-padded, past the count).
    A skipped env (it resets at this step, NEXT_STEP autoreset) keeps its state and gets a zero reward,
    no flags and no impacts; its obs and kinetic-energy rows are left for the caller (it resets them)."""
    # The arrays this body writes are taken from the records by position, one statement each (fields
    # checked by _check_positions): inlined into numba's parallel loop, a write through an array reached
    # by a NamedTuple attribute is lost (numba issues 7135 and 10338), and so is one through an array
    # unpacked from a tuple of four or more; reads by name, and writes in called functions, are fine.
    S = st[0]
    trig = st[1]
    count = st[4]
    dist = st[5]
    steps = st[6]
    time = st[7]
    obs = out[0]
    reward = out[1]
    terminated = out[2]
    truncated = out[3]
    energy = out[4]
    limit = out[5]
    times = buf[1]
    ends = buf[2]
    for j in range(times.shape[1]):  # (padding first, over the whole row: a loop with fixed bounds is cheaper)
        times[i, j] = np.nan
        ends[i, j] = 0
    clear_row(buf, i)
    if skip[i]:
        reward[i] = 0.0
        terminated[i] = False
        truncated[i] = False
        limit[i] = LIMIT_NONE
    else:
        a1 = actions[i, 1] if p.n_act == 2 else 0.0
        new, o, r, te, tu, e, lim = env_step(env_row(st, i), actions[i, 0], a1, p, m, k, buf, i)
        write_row(obs, i, o)
        for row in range(6):
            S[row, i] = new.s[row]
        for row in range(4):
            trig[row, i] = new.trig[row]
        count[i] = new.count
        dist[i] = new.dist
        steps[i] = new.steps
        time[i] = new.time
        reward[i] = r
        terminated[i] = te
        truncated[i] = tu
        energy[i] = e
        limit[i] = lim


def step_envs(st, actions, skip, p, m, k, out, buf):
    for i in prange(st.S.shape[1]):
        step_env(i, st, actions, skip, p, m, k, out, buf)


def observe_row(j, rows, st, p, obs):
    """trig and obs of env rows[j] (after its reset)."""
    i = rows[j]
    trig = st[1]  # (by position, as in step_env: written in a parallel loop)
    s = (st.S[0, i], st.S[1, i], st.S[2, i], st.S[3, i], st.S[4, i], st.S[5, i])
    tr = angle_trig(s)
    for row in range(4):
        trig[row, i] = tr[row]
    write_row(obs, i, observe(s, tr, st.target[0, i], st.target[1, i], st.count[i], p))


def observe_rows(rows, st, p, obs):
    for j in prange(rows.shape[0]):
        observe_row(j, rows, st, p, obs)


# -- entry points called from Python -----------------------------------------------------------------
# The constants travel as one float64 array, consts = pack(p, m, k), rebuilt into their NamedTuples inside
# by unpack(): numba unboxes one array in about 0.1 us where the 56 numbers of three tuples cost about
# 0.6 us, a tenth of the single env's whole step. The records travel as plain tuples, rebuilt into their
# NamedTuples inside (numba unboxes a plain tuple several times faster than a NamedTuple).
_PACKED = (EnvParams, Model, TaskConstants)


def _field_kinds(records) -> tuple:
    """("int" | "bool" | "float") of every field of the records, in order (from their annotations)."""
    out = []
    for cls in records:
        for name in cls._fields:
            ann = cls.__annotations__[name]
            kind = getattr(ann, "__forward_arg__", getattr(ann, "__name__", ann))
            if kind not in ("int", "bool", "float"):
                raise TypeError(f"{cls.__name__}.{name}: pack() holds int, bool and float fields, not {kind}")
            out.append(kind)
    return tuple(out)


_KINDS = _field_kinds(_PACKED)


def pack(p, m, k) -> np.ndarray:
    """(EnvParams, Model, TaskConstants) as one float64 array for the entry points below: floats as they
    are, ints and bools as the bits of an int64 (exact over the whole int64 range; unpack() reads them
    back through an int64 view)."""
    values = tuple(p) + tuple(m) + tuple(k)
    if len(values) != len(_KINDS):
        raise ValueError(f"pack() takes an EnvParams, a Model and a TaskConstants ({len(_KINDS)} fields), "
                         f"got {len(values)} fields")
    out = np.empty(len(values))
    bits = out.view(np.int64)
    for j, (v, kind) in enumerate(zip(values, _KINDS)):
        if kind == "float":
            out[j] = v
        else:
            bits[j] = int(v)
    return out


def _unpack_source() -> str:
    """Source of unpack(c): one expression per field, so that numba types every field statically."""
    parts, j = [], 0
    for cls in _PACKED:
        args = []
        for _ in cls._fields:
            kind = _KINDS[j]
            args.append(f"float(c[{j}])" if kind == "float" else f"int(b[{j}])" if kind == "int" else f"bool(b[{j}] != 0)")
            j += 1
        parts.append(f"{cls.__name__}({', '.join(args)})")
    return ("def unpack(c):\n"
            "    \"\"\"(EnvParams, Model, TaskConstants) from pack()'s array (generated from their fields).\"\"\"\n"
            "    b = c.view(np.int64)\n"
            f"    return ({', '.join(parts)})\n")


# compiled with this file's name, so that numba's disk cache finds its copies (the source is this file's)
exec(compile(_unpack_source(), __file__, "exec"))  # noqa: S102 (our own generated source: defines unpack)


def env_step_packed(st, a0, a1, consts, obs, buf):
    """env_step with st a plain tuple of PennyState's fields, consts = pack(p, m, k) and buf a plain tuple
    of ImpactBuffers' arrays (one row) (PennyEnv's entry point): the observation goes into row 0 of obs
    (1, obs_dim); returns (the new state's fields that a step changes: s, trig, count, dist, steps, time;
    then the impact count, reward, terminated, truncated, kinetic energy, limit), flat (fewer objects for
    numba to box: the single env's whole step costs a few microseconds)."""
    p, m, k = unpack(consts)
    b = ImpactBuffers(*buf)
    new, o, r, te, tu, e, lim = env_step(PennyState(*st), a0, a1, p, m, k, b, 0)
    write_row(obs, 0, o)
    return new.s, new.trig, new.count, new.dist, new.steps, new.time, b.count[0], r, te, tu, e, lim


def step_envs_packed(st, actions, skip, consts, out, buf):
    """step_envs with plain tuples: st of EnvState's arrays, consts = pack(p, m, k), out of StepResults'
    arrays, buf of ImpactBuffers' (PennyVectorEnv's entry point)."""
    p, m, k = unpack(consts)
    step_envs(EnvState(*st), actions, skip, p, m, k, StepResults(*out), ImpactBuffers(*buf))


def observe_rows_packed(rows, st, consts, obs):
    """observe_rows with st a plain tuple of EnvState's arrays and consts = pack(p, m, k)."""
    observe_rows(rows, EnvState(*st), unpack(consts)[0], obs)


def initial_observation_packed(obs, s, tx, ty, consts):
    """initial_observation with consts = pack(p, m, k)."""
    return initial_observation(obs, s, tx, ty, unpack(consts)[0])


PYTHON_FUNCTIONS = {"env_step": env_step_packed, "step_envs": step_envs_packed, "observe_rows": observe_rows_packed,
                    "initial_observation": initial_observation_packed}


def _vector_count(args):
    return args[1].shape[0]  # step_envs_packed's actions (N, n_act)


def compiled_env_functions(kind: int, target: str = "cpu", fresh: bool = False, law: int = -1) -> dict:
    """PYTHON_FUNCTIONS built for ``target`` (physics/builder.py) for the scenes whose Model.kind is
    ``kind`` (the open plane: scalar.OTHER), once per process for each target, kind and registry state.
    CPU: numba copies whose globals hold the compiled physics and task functions (physics/compiled.py's
    physics_build, whose namespace they extend), cached on disk where compiled.cacheable(kind); the
    vector step's loop parallel over envs. CUDA: device functions, and the loops step_envs and
    observe_rows as kernels (one thread per env) taking the records (NamedTuples of device arrays)
    and the NamedTuples of constants: entries "step_envs_kernel" and "observe_rows_kernel". fresh: build
    anew (physics included) and keep nothing (the PTX tests compile each compute capability from scratch).
    law: the Model.law of the scenes (-1: a built-in law); a user's law is compiled only into its own builds
    (physics/compiled.py's build_laws)."""
    from ..physics import compiled
    from ..physics.builder import check_target

    target = check_target(target)
    kind = compiled.check_kind(kind)
    key = (target,) + compiled.variant_key(kind, law)
    if key in _COMPILED and not fresh:
        return _COMPILED[key]
    if target == "python":
        _COMPILED[key] = PYTHON_FUNCTIONS
        return PYTHON_FUNCTIONS
    from . import functional, tasks

    phys = compiled.physics_build(target, kind, fresh, law)  # (also picks the threading layer: physics/parallel.py)
    own = phys.cache
    modules = compiled.physics_modules() + (tasks, functional)
    if own:
        compiled.drop_stale_cache(Path(__file__).with_name("__pycache__"), modules)
    from ..physics.builder import Builder
    # the digest of every inlined source in the copies' names: never stale, whatever the cache location
    variant = f"{compiled.variant_name(kind)}_{compiled.source_digest(modules)}" + ("_cuda" if target == "cuda" else "")
    b = Builder(target, variant, cache=own)
    b.namespace.update({k: v for k, v in phys.namespace.items() if k != "__builtins__"})
    b.add(tasks)  # the task formulas' constants (REACH, PARK, IMPACTS)
    b.add({k: v for k, v in vars(functional).items() if not isinstance(v, types.FunctionType) and k != "prange"})
    b.namespace["XP"] = b.math
    for name in ("run_interval", "clear_row"):
        b.namespace[name] = phys.namespace[name]
    b.copies((tasks.step_reward, clip_action, observe, angle_trig, kinetic_energy))
    # inlined: a call that passes arrays increments and decrements their reference counts, atomically (and
    # arc_window's records of constants would be copied into every call)
    b.copies((write_row, env_row, arc_window, unpack), inline=True)
    b.copy(initial_observation)
    if target == "cuda":
        b.copies((env_step, step_env, observe_row))
        fns = {"step_envs_kernel": b.loop(step_envs), "observe_rows_kernel": b.loop(observe_rows)}
    else:
        # inlined into the entries and the loop: called as a function, its many arguments cost more than its work
        b.copy(env_step, inline=True)
        single = b.copy(env_step_packed)
        # inlined into the parallel loop: called there as a function, its many arguments cost more than its
        # work (they write by position, see step_env; tests/test_parallel.py checks parallel against serial)
        b.copies((step_env, observe_row), inline=True)
        fns = {"env_step": single,
               # one parallel call at a time (parallel.locked), serially for few envs or in a forked child
               "step_envs": b.loop(step_envs, entry=step_envs_packed, count=_vector_count,
                                   inline=(env_step, run_interval))}
        b.namespace["observe_rows"] = b.copy(observe_rows)
        fns["observe_rows"] = b.copy(observe_rows_packed)
        fns["initial_observation"] = b.copy(initial_observation_packed)
    if target == "cuda":
        fns["physics"] = phys.functions
        fns["laws"] = phys.laws
    if not fresh:
        _COMPILED[key] = fns
    return fns


def env_functions(backend: str, kind: int, law: int = -1) -> dict:
    """The entry points of a backend ("env_step", "step_envs", "observe_rows", "initial_observation",
    taking consts = pack(p, m, k)): "numba" (compiled for Model.kind ``kind``: it must be m.kind of
    the consts they will receive, as the compiled physics calls that table's formulas whatever m
    says), "cuda" (the kernels, see compiled_env_functions) or "python" (these functions as they are,
    for any kind); law: the Model.law they will receive (a user's law is compiled into its own builds only)."""
    if backend == "numba":
        return compiled_env_functions(kind, "cpu", law=law)
    if backend == "cuda":
        return compiled_env_functions(kind, "cuda", law=law)
    return PYTHON_FUNCTIONS
