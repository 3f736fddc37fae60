"""The vector environment's whole step, compiled (numba backend, optional).

One parallel pass over the envs does, for each env, what PennyEnv.step does for its penny: clip
the actions, advance the penny (physics/compiled.py's copies of physics/scalar.py), count the
impacts on the arc and compute reward and termination (tasks.py's formulas, compiled the same
way), and write the observation. The numpy backend needs some forty array passes for the same
work; here the envs that reset at this step (NEXT_STEP autoreset) are skipped, and the cos and sin
of the heading kept from the previous step's observation feed the no-impact certificate.

Every number comes from the same operations as in PennyEnv (libm's cos, sin and tanh, the same
order), so sub-env i equals a single env bitwise; tests/test_vector_env.py checks it.
"""
from __future__ import annotations

import builtins
import math
from pathlib import Path
from typing import NamedTuple

import numpy as np


_COMPILED = None


class EnvConstants(NamedTuple):
    """The numbers of a scene the compiled step needs besides the physics Model and the task's
    constants (see Core)."""

    n_act: int
    steer_only: bool   # one control, and it is u1
    gain1: float       # acc1 = a * gain1 [rad/s^2]
    gain2: float
    dt: float
    max_steps: int
    plane: bool        # no table: every period is one flow
    impacts: bool      # the impacts task (observation 10 is the arc count)
    inv_L: float
    s_W: float
    s_w: float
    goal: int
    Itot: float
    J: float


def env_constants(core) -> EnvConstants:
    return EnvConstants(n_act=core.n_act, steer_only=core.controls == (0,), gain1=float(core.gain1),
                        gain2=float(core.gain2), dt=float(core.dt), max_steps=int(core.max_steps),
                        plane=bool(core.plane), impacts=bool(core.impacts), inv_L=float(core.inv_L),
                        s_W=float(core.s_W), s_w=float(core.s_w), goal=int(core.k.goal),
                        Itot=float(core.Itot), J=float(core.J))


def _clip(v):
    """PennyEnv._action's clipping."""
    return -1.0 if v < -1.0 else (1.0 if v > 1.0 else v)


def _observe_into(obs, i, s, trig, target, count, p):
    """Row i of obs from state s, trig[:, i] (cos/sin of theta and phi) and target[:, i]: the
    values of PennyEnv._obs in the same order of operations."""
    x, y = s[0], s[1]
    inv = p.inv_L
    ox, oy = x * inv, y * inv
    rx, ry = (target[0, i] - x) * inv, (target[1, i] - y) * inv
    if p.plane:
        ox, oy, rx, ry = math.tanh(ox), math.tanh(oy), math.tanh(rx), math.tanh(ry)
    obs[i, 0] = ox
    obs[i, 1] = oy
    for r in range(4):
        obs[i, 2 + r] = trig[r, i]
    obs[i, 6] = math.tanh(s[4] * p.s_W)
    obs[i, 7] = math.tanh(s[5] * p.s_w)
    obs[i, 8] = rx
    obs[i, 9] = ry
    if p.impacts:
        obs[i, 10] = min(count / p.goal, 1.0)


def _step_env(i, S, trig, actions, p, m, k, target, arc, count, dist, steps, time,
              S_out, obs, rew, term, trunc, n_imp, times, ends, ke, acc):
    """PennyEnv.step for env i (compiled only: its callees are the compiled copies)."""
    a0 = clip(actions[i, 0])  # noqa: F821  (names of the compiled namespace, see compiled_env_functions)
    if p.n_act == 2:
        a1 = clip(actions[i, 1])  # noqa: F821
        acc1, acc2 = a0 * p.gain1, a1 * p.gain2
        ctrl = (a0 * a0 + a1 * a1) / 2
    else:
        acc1, acc2 = (a0 * p.gain1, 0.0) if p.steer_only else (0.0, a0 * p.gain2)
        ctrl = (a0 * a0) / 1
    acc[0, i] = acc1
    acc[1, i] = acc2
    s = (S[0, i], S[1, i], S[2, i], S[3, i], S[4, i], S[5, i])
    n_arc = 0
    n = 0
    if p.plane or certified_free_trig(s, trig[2, i], trig[3, i], acc1, acc2, p.dt, m):  # noqa: F821
        s1 = flow1(s, acc1, acc2, p.dt, m.R)  # noqa: F821
    else:
        s1, impacts, _, _ = advance_through_m(s, acc1, acc2, p.dt, m)  # noqa: F821
        n = len(impacts)
        for j in range(n):
            t_j, end, post = impacts[j]
            sR = end * m.R
            if on_arc(post[0] + sR * math.cos(post[3]), post[1] + sR * math.sin(post[3]),  # noqa: F821
                      arc[0, i], arc[1, i], k, numba_math):  # noqa: F821
                n_arc += 1
            if j < times.shape[1]:
                times[i, j] = t_j
                ends[i, j] = end
    n_imp[i] = n
    count[i] += n_arc
    dx, dy = target[0, i] - s1[0], target[1, i] - s1[1]
    d = math.sqrt(dx * dx + dy * dy)
    r, success = step_reward(k, dist[i], d, s1[4], ctrl, n_arc, count[i], numba_math)  # noqa: F821
    dist[i] = d
    steps[i] += 1
    time[i] += p.dt
    rew[i] = r
    term[i] = success
    trunc[i] = steps[i] >= p.max_steps
    ke[i] = 0.5 * (p.Itot * s1[4] ** 2 + p.J * s1[5] ** 2)
    for row in range(6):
        S_out[row, i] = s1[row]
    trig[0, i] = math.cos(s1[2])
    trig[1, i] = math.sin(s1[2])
    trig[2, i] = math.cos(s1[3])
    trig[3, i] = math.sin(s1[3])
    observe_into(obs, i, s1, trig, target, count[i], p)  # noqa: F821


def _step_envs(S, trig, actions, skip, p, m, k, target, arc, count, dist, steps, time,
               S_out, obs, rew, term, trunc, n_imp, times, ends, ke, acc):
    """_step_env over every env not in skip, in parallel (compiled only)."""
    for i in prange(S.shape[1]):  # noqa: F821
        for j in range(times.shape[1]):
            times[i, j] = np.nan
            ends[i, j] = 0
        if skip[i]:  # reset at this step (NEXT_STEP): the caller fills its outputs
            for row in range(6):
                S_out[row, i] = S[row, i]
            rew[i] = 0.0
            term[i] = False
            trunc[i] = False
            n_imp[i] = 0
            acc[0, i] = acc[1, i] = 0.0
            continue
        step_env(i, S, trig, actions, p, m, k, target, arc, count, dist, steps, time,  # noqa: F821
                 S_out, obs, rew, term, trunc, n_imp, times, ends, ke, acc)


def _observe_rows(rows, S, trig, target, count, p, obs):
    """trig and obs of the envs in rows (after a reset; compiled only)."""
    for i in rows:
        s = (S[0, i], S[1, i], S[2, i], S[3, i], S[4, i], S[5, i])
        trig[0, i] = math.cos(s[2])
        trig[1, i] = math.sin(s[2])
        trig[2, i] = math.cos(s[3])
        trig[3, i] = math.sin(s[3])
        observe_into(obs, i, s, trig, target, count[i], p)  # noqa: F821


def compiled_env_functions() -> dict:
    """The compiled step and observation functions (compiled once per process, cached on disk).

    Like physics/compiled.py, the functions above are compiled as copies whose globals hold the
    compiled physics and task functions (closures over compiled functions would miss numba's
    on-disk cache in every new process)."""
    global _COMPILED
    if _COMPILED is not None:
        return _COMPILED
    import numba

    from ..physics import compiled, numba_math
    from . import compiled_step, tasks

    phys = compiled.compiled_functions()
    compiled.drop_stale_cache(Path(__file__).with_name("__pycache__"),
                              compiled.physics_modules() + (tasks, compiled_step))
    jit = numba.njit(cache=True)
    namespace = dict(vars(tasks), __builtins__=builtins, math=math, np=np, ARRAY=numba_math, numba_math=numba_math,
                     prange=numba.prange)
    for name in ("certified_free_trig", "flow1", "advance_through_m"):
        namespace[name] = phys[name]
    for f in (tasks.on_arc, tasks.step_reward):
        namespace[f.__name__] = compiled.jit_copy(f, namespace, jit)
    namespace["clip"] = compiled.jit_copy(_clip, namespace, jit)
    namespace["observe_into"] = compiled.jit_copy(_observe_into, namespace, jit)
    # inlined into the loop: called as a function, its two dozen array arguments cost more than its work
    namespace["step_env"] = compiled.jit_copy(_step_env, namespace, numba.njit(cache=True, inline="always"))
    _COMPILED = {"step_envs": compiled.jit_copy(_step_envs, namespace, numba.njit(parallel=True, cache=True)),
                 "observe_rows": compiled.jit_copy(_observe_rows, namespace, jit),
                 "advance_through_m": phys["advance_through_m"]}
    return _COMPILED


class CompiledStep:
    """The compiled step of a Core (``core.backend == "numba"``).

    ``step(...)`` advances every env not in ``skip`` and updates ``trig``, ``count``, ``dist``,
    ``steps`` and ``time`` in place; ``observe_rows`` fills trig and observations after resets."""

    IMPACT_CAPACITY = 8  # impacts per env stored by the parallel pass; more are collected by a rerun

    def __init__(self, core):
        from ..physics.scalar import scalar_model

        self.fns = compiled_env_functions()
        self.p = env_constants(core)
        self.m = scalar_model(core.params, core.table, core.law, core.settings)
        self.k = core.k  # tasks.TaskConstants
        self.obs_dim = core.obs_dim
        self._warm_up()

    def _warm_up(self):
        """Compile (or load from numba's cache) every path now rather than in the middle of a run:
        one env at rest at the table's centre, and the one-penny rerun for overflowing buffers."""
        S = np.zeros((6, 1))
        S[4] = 1e-3
        state = lambda: (np.zeros(1, dtype=np.int64), np.zeros(1), np.zeros(1, dtype=np.int64), np.zeros(1))
        trig = np.zeros((4, 1))
        obs = np.empty((1, self.obs_dim), dtype=np.float32)
        self.observe_rows(np.zeros(1, dtype=np.int64), S, trig, np.zeros((2, 1)), np.zeros(1, dtype=np.int64), obs)
        self.step(S, trig, np.zeros((1, self.p.n_act)), np.zeros(1, dtype=bool), np.zeros((2, 1)), np.zeros((2, 1)), *state())
        self.fns["advance_through_m"]((0.0, 0.0, 0.0, 0.0, 1e-3, 0.0), 0.0, 0.0, 1e-9, self.m)

    def step(self, S, trig, actions, skip, target, arc, count, dist, steps, time):
        """(new S, obs, reward, terminated, truncated, impacts, impact_times, impact_ends,
        kinetic_energy); impact_times (N, K) is NaN-padded, K the largest count (0 without impacts).
        The rows of skipped envs hold no step (the caller resets them)."""
        n = S.shape[1]
        cap = self.IMPACT_CAPACITY
        S_out = np.empty_like(S)
        obs = np.empty((n, self.obs_dim), dtype=np.float32)
        rew = np.empty(n)
        term = np.empty(n, dtype=bool)
        trunc = np.empty(n, dtype=bool)
        n_imp = np.empty(n, dtype=np.int64)
        times = np.empty((n, cap))
        ends = np.empty((n, cap), dtype=np.int8)
        ke = np.empty(n)
        acc = np.empty((2, n))
        self.fns["step_envs"](S, trig, actions, skip, self.p, self.m, self.k, target, arc, count, dist, steps, time,
                              S_out, obs, rew, term, trunc, n_imp, times, ends, ke, acc)
        K = int(n_imp.max()) if n else 0
        if K > cap:  # accumulations: rerun those pennies alone for their full impact lists
            times = np.concatenate([times, np.full((n, K - cap), np.nan)], axis=1)
            ends = np.concatenate([ends, np.zeros((n, K - cap), dtype=np.int8)], axis=1)
            for i in np.flatnonzero(n_imp > cap):
                s = tuple(float(v) for v in S[:, i])
                _, impacts, _, _ = self.fns["advance_through_m"](s, float(acc[0, i]), float(acc[1, i]), self.p.dt, self.m)
                times[i, : len(impacts)] = [imp[0] for imp in impacts]
                ends[i, : len(impacts)] = [imp[1] for imp in impacts]
        else:
            times, ends = times[:, :K], ends[:, :K]
        return S_out, obs, rew, term, trunc, n_imp, times, ends, ke

    def observe_rows(self, rows, S, trig, target, count, obs):
        self.fns["observe_rows"](np.asarray(rows, dtype=np.int64), S, trig, target, count, self.p, obs)
