"""The environment step, written once, as named stages on plain floats, tuples and NamedTuples.

In the style of Gymnasium's functional environments (gymnasium/envs/phys2d/cartpole.py) and gymnax: no
objects, only functions of (state, action, constants). The stages:

==================  ===================================================================================
:func:`initial_state`  a fresh episode of one env: the scene's draws (position, angles, speeds) and the
                       task's target (counter-based draws: step/draws.py)
:func:`actuate`        the action, clipped to [-1, 1], as angular accelerations and the control cost
:func:`transition`     the penny over one control period (physics/scalar.run_interval, the event loop's
                       one driver) and the documented limit that ends the episode, if any
task ``reward``        the reward and the success (the task's record: step/tasks/)
:func:`termination`    terminated (success) and truncated (time limit, or a documented limit)
:func:`observation`    the observation row (and the task's own entries)
==================  ===================================================================================

:func:`env_step` composes them for one env (PennyEnv's step). :func:`step_env` is one env of the vector
step with its autoreset, written once for every target: NEXT_STEP resets an env in the step after its
episode ended, SAME_STEP in the step that ended it (the last observation goes to ``final_obs``), DISABLED
never. :func:`step_envs` loops over the envs; the backends (penny_env/backends/) compile that loop for the
CPU (numba, parallel over envs) and for CUDA (one thread per env, the state resident on the device), and
run it as it is in plain Python (backend "python", the readable reference). So a single env, a sub-env
of the vector env on the CPU and one on a GPU run the very same operations.

Nothing here imports numba. ``XP`` is the math namespace (kernels.SCALAR here; the backends substitute
their own). The task's stages, which the step calls by the names in :data:`BUILD_SUPPLIED`, are put into
each build's namespace by the backends (step/tasks/, backends/env.py); here those names are stand-ins
(physics/build_names.py).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..physics.faults import FAULT_ENERGY, FAULT_NONE, FAULT_NONFINITE, FAULT_OUTSIDE, FAULT_OUTWARD
from ..physics.kernels import SCALAR
from ..physics.numbers import real_array
from ..physics.scalar import NO_ARC, clear_row, run_interval
from ..physics.build_names import build_supplied
from .draws import draw_stream, draw_uniform

XP = SCALAR      # the math namespace (numba_math or cuda_math in the compiled copies)
prange = range   # numba.prange in the CPU copies; one thread per env on CUDA

# the task's stages as the step calls them, which each build supplies (backends/env.py: the task record's reward,
# target, observation and marked arc, and the bounds check generated from its extra_obs); stand-ins here
BUILD_SUPPLIED = ("task_reward", "task_target", "task_observation", "task_obs_in_bounds", "task_marked_arc")
task_reward, task_target, task_observation, task_obs_in_bounds, task_marked_arc = build_supplied(__name__,
                                                                                                  BUILD_SUPPLIED)

# info["limit"]: which documented limit ended an episode (truncated), docs/envs.md#limits. 3 to 5 and 7: the event
# loop's run-time guard stopped the step at an impact (FAULT_OF_LIMIT, physics/faults.py); 6: a non-finite action
# met on the device (the host refuses it before the step otherwise)
LIMIT_NONE, LIMIT_SPEED, LIMIT_IMPACTS = 0, 1, 2
LIMIT_LAW_NONFINITE, LIMIT_LAW_ENERGY, LIMIT_OUTSIDE_WALL, LIMIT_ACTION, LIMIT_LAW_OUTWARD = 3, 4, 5, 6, 7
LIMIT_TASK_OUTPUT = 8  # the task's reward, target or own observation entries not finite or out of bounds (conclude)
LIMIT_NAMES = ("", "speed", "impacts", "law_nonfinite", "law_energy", "outside_wall", "action", "law_outward",
               "task_output")
# the observation space's bounds of the entries every task has (Core.obs_bounds builds the Box from them): 0 to 7
# (positions in table sizes; cos, sin and tanh) within [-1, 1]; 8 and 9, the target relative to the contact point in
# table sizes, within [-2, 2] on a table (both points on it), tanh'd into [-1, 1] on the open plane. The step's guard
# (conclude) holds the task's target to them: a target off the table ends the episode (LIMIT_TASK_OUTPUT)
OBS_BOUND = 1.0
TARGET_OBS_BOUND = 2.0
FAULT_OF_LIMIT = {LIMIT_LAW_NONFINITE: FAULT_NONFINITE, LIMIT_LAW_ENERGY: FAULT_ENERGY, LIMIT_OUTSIDE_WALL: FAULT_OUTSIDE,
                  LIMIT_LAW_OUTWARD: FAULT_OUTWARD}
# the vector env's autoreset (gymnasium.vector.AutoresetMode), as EnvParams.autoreset
NEXT_STEP, SAME_STEP, DISABLED = 0, 1, 2


class EnvParams(NamedTuple):
    """The numbers of a scene (and of the vector env's autoreset) the step needs besides the physics
    Model and the task's constants."""

    n_act: int
    steer_only: bool           # one control, and it is u1
    gain1: float               # acc1 = a * gain1 [rad/s^2]
    gain2: float
    dt: float                  # control period [s]
    max_steps: int             # truncation after this many steps (a huge number: never)
    plane: bool                # no table: every period is one flow
    inv_length_scale: float    # 1 / L: positions are observed as position / L
    inv_scale_theta_dot: float  # 1 / obs_scale.theta_dot
    inv_scale_phi_dot: float
    Itot: float
    J: float
    W_max: float               # |theta_dot| beyond which the next step could pass MAX_ANGULAR_SPEED: LIMIT_SPEED
    w_max: float               # |phi_dot| likewise (and MAX_STEERED_PHASE)
    autoreset: int             # NEXT_STEP, SAME_STEP or DISABLED (the single env: DISABLED)
    spawn_ax: float            # the spawn ellipse's semi-axes [m]
    spawn_ay: float
    spawn_fraction: float
    theta_lo: float            # the initial angles' and speeds' uniform ranges
    theta_hi: float
    phi_lo: float
    phi_hi: float
    theta_dot_lo: float
    theta_dot_hi: float
    phi_dot_lo: float
    phi_dot_hi: float


def env_params(core, max_steps=None, autoreset=DISABLED) -> EnvParams:
    """EnvParams of a Core; max_steps overrides the task's (None: the task's)."""
    scene = core.scene
    W_max, w_max = scene.step_speed_limits()
    init = scene.init
    return EnvParams(
        n_act=core.n_act, steer_only=core.controls == (0,), gain1=float(core.gain1), gain2=float(core.gain2),
        dt=float(core.dt), max_steps=int(core.max_steps if max_steps is None else max_steps), plane=bool(core.plane),
        inv_length_scale=float(core.inv_L), inv_scale_theta_dot=1.0 / scene.obs_scale["theta_dot"],
        inv_scale_phi_dot=1.0 / scene.obs_scale["phi_dot"], Itot=float(core.Itot), J=float(core.J),
        W_max=float(W_max), w_max=float(w_max), autoreset=int(autoreset), spawn_ax=float(core.ax),
        spawn_ay=float(core.ay), spawn_fraction=float(init["spawn_fraction"]),
        theta_lo=float(init["theta"][0]), theta_hi=float(init["theta"][1]), phi_lo=float(init["phi"][0]),
        phi_hi=float(init["phi"][1]), theta_dot_lo=float(init["theta_dot"][0]),
        theta_dot_hi=float(init["theta_dot"][1]), phi_dot_lo=float(init["phi_dot"][0]),
        phi_dot_hi=float(init["phi_dot"][1]))


# -- the records -------------------------------------------------------------------------------------
class PennyState(NamedTuple):
    """One env between two steps, in plain floats (the single env's state, a row of :class:`EnvState`)."""

    s: tuple         # (x, y, theta, phi, theta_dot, phi_dot)
    trig: tuple      # angle_trig(s)
    target: tuple    # (tx, ty)
    arc: tuple       # (cos b, sin b) of the marked arc's centre (drawn for every task; the impacts task's)
    count: int       # impacts on the marked arc so far
    dist: float      # distance to the target
    steps: int       # steps so far
    time: float      # simulated time since the reset [s]


class EnvState(NamedTuple):
    """The vector env's state, arrays over its N envs: S (6, N), trig (4, N), target (2, N), arc (2, N),
    count (N,) int64, dist (N,), steps (N,) int64, time (N,); and the episodes' draws: key (N,) uint64 (the
    seed's key, draws.seed_keys), episode (N,) int64, pending (N,) bool (NEXT_STEP: the episode ended at the
    last step, the env resets at the next)."""

    S: object
    trig: object
    target: object
    arc: object
    count: object
    dist: object
    steps: object
    time: object
    key: object
    episode: object
    pending: object


class StepResults(NamedTuple):
    """What the vector step writes per env: obs (N, obs_dim) float32, reward (N,), terminated and truncated
    (N,) bool, kinetic_energy (N,), limit (N,) int8 (a LIMIT_* code), and the info's time (N,), distance
    (N,) and arc count (N,) int64 after the step (the ended episode's under SAME_STEP, the new one's for an
    env reset at this step under NEXT_STEP), final_obs (N, obs_dim) float32 (SAME_STEP: the last
    observation of the envs whose episode ended), ended (N,) bool (terminated or truncated: final_obs's
    mask). The impacts go into a scalar.ImpactBuffers."""

    obs: object
    reward: object
    terminated: object
    truncated: object
    kinetic_energy: object
    limit: object
    time: object
    dist: object
    arc_count: object
    final_obs: object
    ended: object


def _check_positions():
    """step_env, write_state and write_observation take the arrays they write by position: the records'
    fields must stay in this order."""
    assert EnvState._fields == ("S", "trig", "target", "arc", "count", "dist", "steps", "time", "key", "episode",
                                "pending")
    assert StepResults._fields == ("obs", "reward", "terminated", "truncated", "kinetic_energy", "limit", "time",
                                   "dist", "arc_count", "final_obs", "ended")


_check_positions()


# -- small pieces --------------------------------------------------------------------------------------
def clip_action(v):
    """An action entry clipped to [-1, 1]."""
    return -1.0 if v < -1.0 else (1.0 if v > 1.0 else v)


def angle_trig(s):
    """(cos theta, sin theta, cos phi, sin phi) of state s."""
    return math.cos(s[2]), math.sin(s[2]), math.cos(s[3]), math.sin(s[3])


def kinetic_energy(s, p):
    """0.5 (I + m R^2) theta_dot^2 + 0.5 J phi_dot^2 of state s (a tuple, or a (6, N) array), the info's
    ``kinetic_energy``: one formula for the single and the vector env, bitwise the same. Squares as
    products: numba and numpy square by multiplying, but Python's float ``**`` calls libm's pow, which
    here differs from x * x in about 1 of 1300 draws."""
    W, w = s[4], s[5]
    return 0.5 * (p.Itot * (W * W) + p.J * (w * w))


def distance(s, target):
    dx, dy = target[0] - s[0], target[1] - s[1]
    return math.sqrt(dx * dx + dy * dy)


# -- the stages ------------------------------------------------------------------------------------------
def initial_state(key, episode, p, m, k):
    """Stage "reset": episode ``episode`` of the env with seed key ``key`` (draws.py): the contact point
    uniform in spawn_fraction times the spawn ellipse (draws 0, 1), theta, phi, theta_dot, phi_dot uniform
    in their ranges (draws 2 to 5), then the task's target and marked arc (task_target). Returns a
    PennyState at step 0."""
    base = draw_stream(key, episode, XP)
    r = p.spawn_fraction * math.sqrt(draw_uniform(base, 0, XP))
    a = 2.0 * XP.pi * draw_uniform(base, 1, XP) - XP.pi
    x = r * p.spawn_ax * math.cos(a)
    y = r * p.spawn_ay * math.sin(a)
    th = p.theta_lo + (p.theta_hi - p.theta_lo) * draw_uniform(base, 2, XP)
    ph = p.phi_lo + (p.phi_hi - p.phi_lo) * draw_uniform(base, 3, XP)
    W = p.theta_dot_lo + (p.theta_dot_hi - p.theta_dot_lo) * draw_uniform(base, 4, XP)
    w = p.phi_dot_lo + (p.phi_dot_hi - p.phi_dot_lo) * draw_uniform(base, 5, XP)
    s = (x, y, th, ph, W, w)
    trig = angle_trig(s)
    tx, ty, cb, sb = task_target(k, p, m, s, trig, base, XP)
    return PennyState(s, trig, (tx, ty), (cb, sb), 0, distance(s, (tx, ty)), 0, 0.0)


def check_actions(actions, shape, name="action"):
    """Stage "action" on the host, before a step changes anything: a float64 array of the given shape from
    actions; a TypeError for a wrong type (strings, None, bools, complex numbers, objects), a ValueError naming
    the sub-env(s) for a wrong shape or non-finite entries. Nothing is clipped here (:func:`actuate` clips)."""
    if isinstance(actions, np.ndarray) and actions.dtype.kind == "f":  # (the usual case, without the entry-wise checks)
        arr = np.array(actions, dtype=np.float64)
    else:
        arr = real_array(actions, name, "an array")  # also finds a bool or string inside a list
    if arr.shape != shape:
        if len(shape) == 2 and shape[1] == 1 and arr.shape == shape[:1]:
            arr = arr[:, None]
        else:
            raise ValueError(f"{name} must have shape {shape}, got shape {arr.shape}")
    finite = np.isfinite(arr)
    if not finite.all():
        if arr.ndim == 1:
            raise ValueError(f"{name} has a non-finite entry: {arr.tolist()}")
        bad = np.flatnonzero(~finite.all(axis=1))
        raise ValueError(f"{name}: non-finite action in sub-env(s) {bad[:10].tolist()}{' ...' if bad.size > 10 else ''}")
    return np.ascontiguousarray(arr)


def actuate(a0, a1, p):
    """Stage "action": (acc1, acc2, ctrl): the actions clipped to [-1, 1] and scaled to the torque limits (a1
    unused with one control), ctrl = mean squared clipped action."""
    a0 = clip_action(a0)
    if p.n_act == 2:
        a1 = clip_action(a1)
        return a0 * p.gain1, a1 * p.gain2, (a0 * a0 + a1 * a1) / 2
    if p.steer_only:
        return a0 * p.gain1, 0.0, (a0 * a0) / 1
    return 0.0, a0 * p.gain2, (a0 * a0) / 1


def transition(st, acc1, acc2, p, m, k, buf, row):
    """Stage "transition": the penny over one control period (scalar.run_interval, one call of the event
    loop: its per-call event cap, m.max_events impacts, bounds the step's work; the impacts go into row
    ``row`` of the ImpactBuffers buf, those on the task's marked arc counted there too). Returns (state,
    elapsed, limit) (:func:`limit_of`). The motion is never altered."""
    s1, elapsed = run_interval(st.s, st.trig[2], st.trig[3], acc1, acc2, p.dt, m, p.plane, False, 0, buf, row,
                               task_marked_arc(k, st))
    # (the guard's fault is read only where the period stopped early: off the hot path of impact-free steps)
    fault = buf.fault[row] if elapsed < p.dt else FAULT_NONE
    return s1, elapsed, limit_of(s1, elapsed, fault, p)


def limit_of(s1, elapsed, fault, p):
    """The documented limit a period reached: LIMIT_IMPACTS when it needed more than the event cap's impacts
    (the state is then the one at elapsed < dt), LIMIT_LAW_NONFINITE, LIMIT_LAW_ENERGY, LIMIT_LAW_OUTWARD or LIMIT_OUTSIDE_WALL
    where the event loop's run-time guard stopped it at an impact (``fault``: a law or a table breaking its
    contract, physics/faults.py; the state is the one of that impact, finite), LIMIT_SPEED when |theta_dot| >
    W_max or |phi_dot| > w_max (a further step could pass MAX_ANGULAR_SPEED), else LIMIT_NONE."""
    limit = LIMIT_NONE
    if elapsed < p.dt:
        if fault == FAULT_NONE:
            limit = LIMIT_IMPACTS
        elif fault == FAULT_NONFINITE:
            limit = LIMIT_LAW_NONFINITE
        elif fault == FAULT_ENERGY:
            limit = LIMIT_LAW_ENERGY
        elif fault == FAULT_OUTWARD:
            limit = LIMIT_LAW_OUTWARD
        else:
            limit = LIMIT_OUTSIDE_WALL
    elif abs(s1[4]) > p.W_max or abs(s1[5]) > p.w_max:
        limit = LIMIT_SPEED
    return limit


def termination(after, success, limit, p):
    """Stage "termination": (terminated, truncated): terminated on success; truncated at max_steps or where
    a documented limit was reached."""
    return bool(success), after.steps >= p.max_steps or limit != LIMIT_NONE


def observation(st, p):
    """Stage "observation": the ten entries every task has (layout in PennyEnv's docstring) of PennyState
    st, a tuple of floats; the task adds its own (task_observation)."""
    s, trig = st.s, st.trig
    x, y = s[0], s[1]
    inv = p.inv_length_scale
    ox, oy = x * inv, y * inv
    rx, ry = (st.target[0] - x) * inv, (st.target[1] - y) * inv
    if p.plane:
        ox, oy, rx, ry = math.tanh(ox), math.tanh(oy), math.tanh(rx), math.tanh(ry)
    return (ox, oy, trig[0], trig[1], trig[2], trig[3], math.tanh(s[4] * p.inv_scale_theta_dot),
            math.tanh(s[5] * p.inv_scale_phi_dot), rx, ry)


def write_observation(obs, i, st, p, k):
    """Row i of the float32 observations obs from PennyState st (indexing obs in place: a row view would
    touch the array's shared reference count from every thread)."""
    o = observation(st, p)
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
    task_observation(k, st, obs, i)


def conclude(st, s1, elapsed, limit, ctrl, n_arc, p, k, obs, i):
    """The stages after the transition from PennyState st to state s1: reward, observation (into row i of obs)
    and termination, the task's outputs guarded: a reward that is not finite (returned as 0), a target that is
    not (the distance) or that puts the observation's target entries (8, 9) outside the observation space (a
    target off the table), or an observation entry of the task's own outside its extra_obs bounds
    (task_obs_in_bounds, generated from the task's record by backends/env.py) ends the episode, truncated, with
    LIMIT_TASK_OUTPUT. The entries are compared as the float32 values the observation holds, with bounds that
    float32 holds exactly: the guard and observation_space.contains agree bound by bound on every target.
    Returns (new PennyState, reward, terminated, truncated, kinetic energy, limit)."""
    new = PennyState(s1, angle_trig(s1), st.target, st.arc, st.count + n_arc, distance(s1, st.target), st.steps + 1,
                     st.time + elapsed)
    r, success = task_reward(k, st, new, ctrl, n_arc, XP)
    write_observation(obs, i, new, p, k)
    bound = OBS_BOUND if p.plane else TARGET_OBS_BOUND
    target_seen = -bound <= obs[i, 8] <= bound and -bound <= obs[i, 9] <= bound  # (False for NaN)
    if not (math.isfinite(r) and math.isfinite(new.dist) and target_seen and task_obs_in_bounds(obs, i)):
        # the task's outputs guarded (a user's task that slipped past its registration trials): the episode ends
        r = 0.0 if not math.isfinite(r) else r
        limit = LIMIT_TASK_OUTPUT
    terminated, truncated = termination(new, success, limit, p)
    return new, r, terminated, truncated, kinetic_energy(s1, p), limit


def env_step(st, a0, a1, p, m, k, buf, row, obs, i):
    """One step of one env from PennyState st: the stages in order; the observation goes into row i of obs,
    the impacts into row ``row`` of buf. Returns (new PennyState, reward, terminated, truncated, kinetic
    energy, limit)."""
    acc1, acc2, ctrl = actuate(a0, a1, p)
    s1, elapsed, limit = transition(st, acc1, acc2, p, m, k, buf, row)
    return conclude(st, s1, elapsed, limit, ctrl, buf.arc_count[row], p, k, obs, i)


# -- the vector step: one env of N, autoreset included -------------------------------------------------------
def env_row(st, i):
    """Row i of the EnvState st as a PennyState."""
    S, tr = st.S, st.trig
    return PennyState((S[0, i], S[1, i], S[2, i], S[3, i], S[4, i], S[5, i]), (tr[0, i], tr[1, i], tr[2, i], tr[3, i]),
                      (st.target[0, i], st.target[1, i]), (st.arc[0, i], st.arc[1, i]), st.count[i], st.dist[i],
                      st.steps[i], st.time[i])


def write_state(st, i, new):
    """Row i of the EnvState st from PennyState new. (Arrays taken by position, one statement each: inlined
    into numba's parallel loop, a write through an array reached by a NamedTuple's attribute is lost, numba
    issues 7135 and 10338.)"""
    S = st[0]
    trig = st[1]
    target = st[2]
    arc = st[3]
    count = st[4]
    dist = st[5]
    steps = st[6]
    time = st[7]
    for r in range(6):
        S[r, i] = new.s[r]
    for r in range(4):
        trig[r, i] = new.trig[r]
    target[0, i] = new.target[0]
    target[1, i] = new.target[1]
    arc[0, i] = new.arc[0]
    arc[1, i] = new.arc[1]
    count[i] = new.count
    dist[i] = new.dist
    steps[i] = new.steps
    time[i] = new.time


def reset_env(st, i, p, m, k):
    """Env i of st starts its next episode (episode counter + 1); returns the new PennyState."""
    episode = st[9]
    new = initial_state(st.key[i], episode[i] + 1, p, m, k)
    episode[i] += 1
    write_state(st, i, new)
    return new


def clear_slots(i, buf):
    """Env i's impact slots emptied before a step writes them: the info's times NaN-padded and ends 0-padded
    past the count (only the slots the row filled at the buffer's last use, so a row costs what it held; a
    fresh buffer's counts start at its capacity), then its counts set to 0 (scalar.clear_row)."""
    counts = buf[0]
    times = buf[1]
    ends = buf[2]
    for j in range(min(counts[i], times.shape[0])):
        times[j, i] = np.nan
        ends[j, i] = 0
    clear_row(buf, i)


def write_outputs(out, i, new, r, te, tu, e, lim):
    """Row i of the step's outputs (StepResults) from a step's results; the info's time, distance and arc
    count of PennyState new."""
    reward = out[1]
    terminated = out[2]
    truncated = out[3]
    energy = out[4]
    limit = out[5]
    info_time = out[6]
    info_dist = out[7]
    info_count = out[8]
    ended = out[10]
    reward[i] = r
    terminated[i] = te
    truncated[i] = tu
    energy[i] = e
    limit[i] = lim
    info_time[i] = new.time
    info_dist[i] = new.dist
    info_count[i] = new.count
    ended[i] = te or tu


def pending_reset(st, i, p, m, k, out):
    """NEXT_STEP: env i, whose episode ended at the last step, starts its next one at this step: its
    observation is the reset's, reward 0, no flags, no impacts."""
    pending = st[10]
    new = reset_env(st, i, p, m, k)
    pending[i] = False
    write_observation(out[0], i, new, p, k)
    write_outputs(out, i, new, 0.0, False, False, kinetic_energy(new.s, p), LIMIT_NONE)


def same_step_reset(st, i, p, m, k, out):
    """SAME_STEP: env i's episode ended at this step: its last observation goes to final_obs, it starts its
    next episode, and its observation is the reset's (the other outputs stay the ended step's)."""
    obs = out[0]
    final_obs = out[9]
    for j in range(obs.shape[1]):
        final_obs[i, j] = obs[i, j]
    fresh = reset_env(st, i, p, m, k)
    write_observation(obs, i, fresh, p, k)


def record_step(st, i, new, r, te, tu, e, lim, p, out):
    """Env i's step results stored (state, outputs) and the autoreset's bookkeeping, written once for every target:
    NEXT_STEP marks an ended episode for reset at the next step; the result is True where SAME_STEP resets the
    ended episode now (the caller does: :func:`same_step_reset` on the CPU, the rare kernel on CUDA)."""
    pending = st[10]
    write_state(st, i, new)
    write_outputs(out, i, new, r, te, tu, e, lim)
    done = te or tu
    if p.autoreset == NEXT_STEP:
        pending[i] = done
    return p.autoreset == SAME_STEP and done


def step_env(i, st, actions, p, m, k, out, buf):
    """Env i of the vector step, in place (the per-env body of :func:`step_envs`): NEXT_STEP's pending reset,
    or env_step with SAME_STEP's reset of an ended episode; the outputs into row i of out (StepResults), the
    impacts into row i of buf (:func:`clear_slots`). A non-finite action (which the host refuses before the
    step on the CPU; a GPU meets it here, without a round trip) ends the env's episode unstepped:
    truncated, LIMIT_ACTION."""
    pending = st[10]
    obs = out[0]
    clear_slots(i, buf)
    if p.autoreset == NEXT_STEP and pending[i]:
        pending_reset(st, i, p, m, k, out)
    else:
        st_i = env_row(st, i)
        a0 = actions[i, 0]
        a1 = actions[i, 1] if p.n_act == 2 else 0.0
        if math.isfinite(a0) and math.isfinite(a1):
            new, r, te, tu, e, lim = env_step(st_i, a0, a1, p, m, k, buf, i, obs, i)
        else:
            new = st_i
            r = 0.0
            te = False
            tu = True
            e = kinetic_energy(st_i.s, p)
            lim = LIMIT_ACTION
            write_observation(obs, i, new, p, k)
        reset_now = record_step(st, i, new, r, te, tu, e, lim, p, out)
        if reset_now:
            same_step_reset(st, i, p, m, k, out)


def step_envs(st, actions, p, m, k, out, buf):
    for i in prange(st.S.shape[1]):
        step_env(i, st, actions, p, m, k, out, buf)


def reset_row(j, rows, st, p, m, k, obs):
    """Env rows[j] starts a fresh episode: the episode its counter names (the caller sets key and episode
    first), its observation into obs."""
    i = rows[j]
    new = initial_state(st.key[i], st.episode[i], p, m, k)
    write_state(st, i, new)
    write_observation(obs, i, new, p, k)


def reset_rows(rows, st, p, m, k, obs):
    for j in prange(rows.shape[0]):
        reset_row(j, rows, st, p, m, k, obs)


def observe_row(j, rows, st, p, m, k, obs):
    """Env rows[j]'s trig, distance and observation from its state and target (a reset's rows, after
    reset options set a state or a target; the other rows, whose values this leaves as they were)."""
    i = rows[j]
    trig = st[1]
    dist = st[5]
    st_i = env_row(st, i)
    tr = angle_trig(st_i.s)
    d = distance(st_i.s, st_i.target)
    for r in range(4):
        trig[r, i] = tr[r]
    dist[i] = d
    write_observation(obs, i, PennyState(st_i.s, tr, st_i.target, st_i.arc, st_i.count, d, st_i.steps, st_i.time),
                      p, k)


def observe_rows(rows, st, p, m, k, obs):
    for j in prange(rows.shape[0]):
        observe_row(j, rows, st, p, m, k, obs)


def no_task_observation(k, st, obs, i):
    """task_observation of a task without observation entries of its own."""


def no_task_obs_bounds(obs, i):
    """task_obs_in_bounds of a task without observation entries of its own."""
    return True


def no_marked_arc(k, st):
    """task_marked_arc of a task without a marked arc: no impact is counted."""
    return NO_ARC

