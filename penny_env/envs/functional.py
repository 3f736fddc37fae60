"""One environment step, written once, as functions of (state, action, params).

In the style of Gymnasium's functional environments (gymnasium/envs/phys2d/cartpole.py) and gymnax:
plain floats, tuples and NamedTuples of constants, no objects. PennyEnv calls :func:`env_step` for
its one penny; PennyVectorEnv calls :func:`step_envs`, a loop over the same :func:`env_step` (a
numba ``prange`` when compiled). So a sub-env of the vector env and a single env run the very same
operations, bitwise.

* :func:`observe`: the observation of a state (layout in PennyEnv's docstring), a tuple of floats;
  :func:`write_row` stores it as a float32 row.
* :func:`transition`: the penny over one control period (physics/scalar.py's per-penny loop).
* :func:`env_step`: actions -> (transition, reward, termination, truncation, observation).

The initial states are sampled by ``Core.sample`` (numpy, counter based, see core.py): resets are
rare, and numpy draws every resetting env at once.

Everything here is numba-compatible. :func:`compiled_env_functions` compiles copies of these
functions whose globals hold the compiled physics (physics/compiled.py); uncompiled (backend
"python") they run as they are, on physics/scalar.py's plain-Python functions, for debugging.
"""
from __future__ import annotations

import builtins
import math
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..physics.kernels import SCALAR
from ..physics.scalar import Model, advance_m, advance_through_m, certified_free_trig, flow1  # noqa: F401
from .tasks import TaskConstants, on_arc, step_reward

XP = SCALAR      # the math namespace of tasks.py's formulas (numba_math in the compiled copies)
prange = range   # numba.prange in the compiled copies

_COMPILED: dict = {}  # physics/compiled.py's variant_key(kind) -> compiled entry points

# info["limit"]: which documented limit ended an episode (truncated), docs/envs.md#limits
LIMIT_NONE, LIMIT_SPEED, LIMIT_IMPACTS = 0, 1, 2
LIMIT_NAMES = ("", "speed", "impacts")


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


def transition(s, c_ph, s_ph, acc1, acc2, p, m, k, arc_c, arc_s, times, ends, row):
    """(new state, impacts, arc impacts, elapsed) of the penny over one control period; c_ph, s_ph:
    cos and sin of the heading s[3]. The times (since the period's start) and ends of the first
    times.shape[1] impacts go into row `row` of times and ends; the counts are exact.

    A period the certificate (scalar.certified_free_trig) shows free of impacts is one flow. Any
    other goes through the physics' event loop (scalar.advance_m), one call: its per-call event cap
    (m.max_events = SolverSettings.max_events_per_interval impacts) bounds the step's work. Where
    the cap stopped it, elapsed < p.dt and the state is the one right after the cap's impact, the
    true motion up to there (never altered); env_step then ends the episode (LIMIT_IMPACTS)."""
    if p.plane or certified_free_trig(s, c_ph, s_ph, acc1, acc2, p.dt, m):
        return flow1(s, acc1, acc2, p.dt, m.R), 0, 0, p.dt
    s, impacts, _, elapsed = advance_m(s, acc1, acc2, p.dt, m, 0)
    n_arc = 0
    cap = times.shape[1]
    for j in range(len(impacts)):
        t_j, end, post = impacts[j]
        sR = end * m.R
        if on_arc(post[0] + sR * math.cos(post[3]), post[1] + sR * math.sin(post[3]), arc_c, arc_s, k, XP):
            n_arc += 1
        if j < cap:
            times[row, j] = t_j
            ends[row, j] = end
    return s, len(impacts), n_arc, elapsed


def env_step(s, trig, a0, a1, tx, ty, arc_c, arc_s, count, d_prev, steps, p, m, k, times, ends, row):
    """One step of one env: clip the actions (a1 unused with one control), advance the penny,
    count the arc impacts, reward, termination, truncation and observation; impact times and ends
    go into row `row` of times and ends (see transition).

    The step is truncated at max_steps, and where the physics reaches a documented limit (the
    episode ends, the motion is never altered): LIMIT_IMPACTS when the period needed more than the
    event cap's impacts (the state is then the one at `elapsed` < dt), LIMIT_SPEED when the new
    state's |theta_dot| > p.W_max or |phi_dot| > p.w_max (a further step could pass
    MAX_ANGULAR_SPEED). So every step does bounded work: at most m.max_events impacts, from a state
    within the speed limits.

    Returns (state, trig, observation, impacts, count, distance, reward, terminated, truncated,
    kinetic energy, limit, elapsed) with trig angle_trig(state), observation observe()'s tuple, count
    the running arc count, limit a LIMIT_* code and elapsed the simulated time of the step."""
    a0 = clip_action(a0)
    if p.n_act == 2:
        a1 = clip_action(a1)
        acc1, acc2 = a0 * p.gain1, a1 * p.gain2
        ctrl = (a0 * a0 + a1 * a1) / 2
    else:
        acc1, acc2 = (a0 * p.gain1, 0.0) if p.steer_only else (0.0, a0 * p.gain2)
        ctrl = (a0 * a0) / 1
    s1, n_imp, n_arc, elapsed = transition(s, trig[2], trig[3], acc1, acc2, p, m, k, arc_c, arc_s, times, ends, row)
    limit = LIMIT_NONE
    if elapsed < p.dt:
        limit = LIMIT_IMPACTS
    elif abs(s1[4]) > p.W_max or abs(s1[5]) > p.w_max:
        limit = LIMIT_SPEED
    count = count + n_arc
    dx, dy = tx - s1[0], ty - s1[1]
    d = math.sqrt(dx * dx + dy * dy)
    r, success = step_reward(k, d_prev, d, s1[4], s1[5], ctrl, n_arc, count, XP)
    trig1 = angle_trig(s1)
    o = observe(s1, trig1, tx, ty, count, p)
    truncated = steps + 1 >= p.max_steps or limit != LIMIT_NONE
    return s1, trig1, o, n_imp, count, d, r, bool(success), truncated, kinetic_energy(s1, p), limit, elapsed


def step_envs(S, trig, actions, skip, target, arc, count, dist, steps, time, p, m, k,
              obs, rew, term, trunc, n_imp, times, ends, ke, limit):
    """env_step over every env i not in skip (in parallel when compiled), in place: S (6, N),
    trig (4, N), count, dist, steps and time advance; obs, rew, term, trunc, n_imp, times (N, K)
    (NaN-padded), ends (N, K) (0-padded), ke (kinetic energy) and limit (LIMIT_* codes) receive
    the step's results.
    Skipped envs (they reset at this step, NEXT_STEP autoreset) keep their state and get zero
    rewards and no flags; their obs and ke rows are left for the caller (it resets them)."""
    for i in prange(S.shape[1]):
        for j in range(times.shape[1]):
            times[i, j] = np.nan
            ends[i, j] = 0
        if skip[i]:
            rew[i] = 0.0
            term[i] = False
            trunc[i] = False
            n_imp[i] = 0
            limit[i] = LIMIT_NONE
            continue
        s = (S[0, i], S[1, i], S[2, i], S[3, i], S[4, i], S[5, i])
        tr = (trig[0, i], trig[1, i], trig[2, i], trig[3, i])
        a1 = actions[i, 1] if p.n_act == 2 else 0.0
        s1, tr1, o, n, c, d, r, te, tu, e, lim, el = env_step(s, tr, actions[i, 0], a1, target[0, i], target[1, i],
                                                              arc[0, i], arc[1, i], count[i], dist[i], steps[i], p, m,
                                                              k, times, ends, i)
        write_row(obs, i, o)
        for row in range(6):
            S[row, i] = s1[row]
        for row in range(4):
            trig[row, i] = tr1[row]
        n_imp[i] = n
        count[i] = c
        dist[i] = d
        steps[i] += 1
        time[i] += el
        rew[i] = r
        term[i] = te
        trunc[i] = tu
        ke[i] = e
        limit[i] = lim


def observe_rows(rows, S, trig, target, count, p, obs):
    """trig and obs of the envs in rows (after their reset)."""
    for i in rows:
        s = (S[0, i], S[1, i], S[2, i], S[3, i], S[4, i], S[5, i])
        tr = angle_trig(s)
        for row in range(4):
            trig[row, i] = tr[row]
        write_row(obs, i, observe(s, tr, target[0, i], target[1, i], count[i], p))


def plane_advance(s, acc1, acc2, dt, m, stop_after=0):
    """advance_m and advance_through_m in the open plane's compiled step: one flow, which is the whole
    motion where there is no wall (and transition never calls them there: p.plane). It keeps the event
    loop and the impact search out of the plane's machine code, a third of its compile time."""
    impacts = [(0.0, 0, s)]  # typed by example, as in scalar.advance_m
    impacts.pop()
    rests = [(0.0, False)]
    rests.pop()
    return flow1(s, acc1, acc2, dt, m.R), impacts, rests, dt


# -- entry points called from Python -----------------------------------------------------------------
# The constants travel as plain tuples, consts = pack(p, m, k), rebuilt into their NamedTuples inside:
# numba unboxes a plain tuple several times faster than a NamedTuple, which matters for the single
# env, whose whole step costs a few microseconds.
def pack(p, m, k):
    """(EnvParams, Model, TaskConstants) as plain tuples, for the entry points below."""
    return tuple(p), tuple(m), tuple(k)


def env_step_packed(s, trig, a0, a1, tx, ty, arc_c, arc_s, count, d_prev, steps, consts, obs, times, ends):
    """env_step with consts = pack(p, m, k) (PennyEnv's entry point): the observation goes into row 0
    of obs (1, obs_dim), the impacts into row 0 of times and ends (1, K); returns env_step's tuple
    without the observation."""
    pt, mt, kt = consts
    s1, trig1, o, n, c, d, r, te, tu, e, lim, el = env_step(s, trig, a0, a1, tx, ty, arc_c, arc_s, count, d_prev, steps,
                                                            EnvParams(*pt), Model(*mt), TaskConstants(*kt), times, ends, 0)
    write_row(obs, 0, o)
    return s1, trig1, n, c, d, r, te, tu, e, lim, el


def step_envs_packed(S, trig, actions, skip, target, arc, count, dist, steps, time, consts,
                     obs, rew, term, trunc, n_imp, times, ends, ke, limit):
    """step_envs with consts = pack(p, m, k) (PennyVectorEnv's entry point)."""
    pt, mt, kt = consts
    step_envs(S, trig, actions, skip, target, arc, count, dist, steps, time, EnvParams(*pt), Model(*mt),
              TaskConstants(*kt), obs, rew, term, trunc, n_imp, times, ends, ke, limit)


def observe_rows_packed(rows, S, trig, target, count, consts, obs):
    """observe_rows with consts = pack(p, m, k)."""
    observe_rows(rows, S, trig, target, count, EnvParams(*consts[0]), obs)


def initial_observation_packed(obs, s, tx, ty, consts):
    """initial_observation with consts = pack(p, m, k)."""
    return initial_observation(obs, s, tx, ty, EnvParams(*consts[0]))


PYTHON_FUNCTIONS = {"env_step": env_step_packed, "step_envs": step_envs_packed, "observe_rows": observe_rows_packed,
                    "initial_observation": initial_observation_packed}


def compiled_env_functions(kind: int) -> dict:
    """PYTHON_FUNCTIONS compiled with numba for the scenes whose Model.kind is ``kind`` (the open
    plane: scalar.OTHER), once per process for each kind and registry state (see
    physics/compiled.py's compiled_functions, whose physics they call); the machine code is cached
    on disk where compiled.cacheable(kind).

    The functions above are compiled as copies whose globals hold the compiled physics and task
    functions (closures over compiled functions would miss numba's on-disk cache in every new
    process); see physics/compiled.py."""
    from ..physics import compiled

    kind = compiled.check_kind(kind)
    key = compiled.variant_key(kind)
    if key in _COMPILED:
        return _COMPILED[key]
    import numba

    from ..physics import numba_math, parallel
    from . import functional, tasks

    phys = compiled.compiled_functions(kind)  # (also picks the threading layer: physics/parallel.py)
    own = compiled.cacheable(kind) and compiled.disk_cache_available()
    modules = compiled.physics_modules() + (tasks, functional)
    if own:
        compiled.drop_stale_cache(Path(__file__).with_name("__pycache__"), modules)
    # the digest of every inlined source in the copies' names: never stale, whatever the cache location
    variant = f"{compiled.variant_name(kind)}_{compiled.source_digest(modules)}"
    jit = numba.njit(cache=own)
    # inlined: a call that passes arrays increments and decrements their reference counts, atomically
    inline = numba.njit(cache=own, inline="always")

    def copy(f, compiler=jit):
        return compiled.jit_copy(f, namespace, compiler, variant)

    namespace = dict(vars(tasks))  # the task formulas' constants (REACH, PARK, IMPACTS)
    namespace.update(vars(functional), __builtins__=builtins, XP=numba_math, prange=numba.prange)
    for name in ("certified_free_trig", "flow1", "advance_m", "advance_through_m"):
        namespace[name] = phys[name]
    if kind < 0:  # the open plane (the only kind -1 that compiles): no event loop to compile
        namespace["advance_m"] = namespace["advance_through_m"] = copy(plane_advance)
    for f in (tasks.on_arc, tasks.step_reward, clip_action, observe, angle_trig, kinetic_energy):
        namespace[f.__name__] = copy(f)
    for f in (write_row, transition):
        namespace[f.__name__] = copy(f, inline)
    namespace["observe_rows"] = copy(observe_rows)
    namespace["initial_observation"] = copy(initial_observation)
    namespace["env_step"] = copy(env_step)
    single = copy(env_step_packed)
    # inlined into the parallel loop: called there as a function, its many arguments cost more than its work
    namespace["env_step"] = copy(env_step, inline)
    namespace["step_envs"] = copy(step_envs, numba.njit(parallel=True, cache=own))
    def serial_step_envs():  # for a child forked after OpenMP ran: the same loop without prange's threads
        serial = dict(namespace)
        serial["step_envs"] = compiled.jit_copy(step_envs, serial, jit, f"{variant}_serial")
        return compiled.jit_copy(step_envs_packed, serial, jit, f"{variant}_serial")

    _COMPILED[key] = {"env_step": single,
                      # one parallel call at a time
                      "step_envs": parallel.locked(copy(step_envs_packed), serial_step_envs),
                      "observe_rows": copy(observe_rows_packed),
                      "initial_observation": copy(initial_observation_packed)}
    return _COMPILED[key]


def env_functions(backend: str, kind: int) -> dict:
    """The entry points of a backend ("env_step", "step_envs", "observe_rows", "initial_observation",
    taking consts = pack(p, m, k)): "numba" (compiled for Model.kind ``kind``: it must be m.kind of
    the consts they will receive, as the compiled physics calls that table's formulas whatever m
    says) or "python" (these functions as they are, for any kind)."""
    return compiled_env_functions(kind) if backend == "numba" else PYTHON_FUNCTIONS
