"""Batched physics for analysis code: many pennies at once, states as (N, 6) rows.

Rows are (x, y, theta, phi, theta_dot, phi_dot) (the user-facing layout; the physics core works
on (6, N) columns). Controls are torques (u1, u2) [N m]: ``J phi'' = u1``, ``(I + m R^2) theta'' = u2``.
Tables are Table objects, spec dicts ({"kind": "ellipse", "a": .., "b": ..}) or None (open plane);
laws "elastic", "plastic" or a restitution coefficient. Every input is checked and errors name the
field and the row (``states[3] has a non-finite phi``).

>>> import numpy as np, penny_env.batch as pb
>>> res = pb.simulate(np.array([[0, 0, 0, 1.57, 10, 0.2]] * 4), table={"kind": "circle", "radius": 0.2},
...                   law="elastic", t_final=2.0)
>>> res.final_states.shape
(4, 6)
"""
from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from .physics import SolverSettings, make_law, make_table  # noqa: F401 (make_table re-exported)
from .backends.pennies import advance_pennies, first_impacts
from .physics import apply_law, end_kinematics
from .physics import flow as _flow
from .physics.faults import blame, check_mapped
from .physics.simulation import FREE_INTERVAL, MAX_INTERVALS, interval_grid
from .physics.tables.registered import audited, check_impacts, sample
from .physics.validation import (as_states, check_inside, check_params, check_settings, check_speed_bound, check_table,
                                 positive_time, real_array)

BATCH_IMPACTS_PER_LIMIT = 10  # a batch records its impacts in arrays (about 70 B each): 10 x SolverSettings.max_impacts

__all__ = ["flow", "first_impact", "impact_map", "simulate", "BatchResult"]

_UNCONTROLLED_CHUNK = FREE_INTERVAL  # [s] interval length without controls, simulate()'s (bounds the work per call)


def _table(table, params):
    try:
        t = make_table(table)
    except (TypeError, ValueError) as exc:
        raise type(exc)(f"table: {exc}") from None
    return check_table(t, params)


def _controls(controls, n, params, name="controls"):
    """(acc1, acc2) arrays of length n from (2,) or (N, 2) torques."""
    u = real_array(controls, name, "(u1, u2) torques, shape (2,) or (N, 2)")
    if u.shape == (2,):
        u = np.broadcast_to(u, (n, 2))
    if u.shape != (n, 2):
        raise ValueError(f"{name} must have shape (2,) or ({n}, 2), got {u.shape}")
    bad = ~np.isfinite(u).all(axis=1)
    if bad.any():
        raise ValueError(f"{name}[{int(np.flatnonzero(bad)[0])}] is not finite")
    return u[:, 0] / params.J, u[:, 1] / params.rolling_inertia


def _times(t, n, name):
    arr = real_array(t, name, "a number or an (N,) array")
    arr = np.broadcast_to(arr, (n,)) if arr.ndim == 0 else arr
    if arr.shape != (n,):
        raise ValueError(f"{name} must be a scalar or have shape ({n},), got {arr.shape}")
    bad = ~np.isfinite(arr) | (arr < 0)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise ValueError(f"{name}[{k}] must be finite and >= 0, got {arr[k]!r}")
    return np.ascontiguousarray(arr, dtype=float)


def flow(states, controls, t, *, params=None) -> np.ndarray:
    """(N, 6) states after time t (scalar or (N,)) with constant torques, ignoring walls."""
    params = check_params(params)
    S = as_states(states)
    n = S.shape[1]
    acc1, acc2 = _controls(controls, n, params)
    return _flow(S, acc1, acc2, _times(t, n, "t"), params.R).T.copy()


def first_impact(states, controls, horizon, *, params=None, table, settings=None, backend="auto"):
    """(t_hit, end) of the first impact within horizon (scalar or (N,)) under constant torques:
    t_hit (N,) [s] (inf where none), end (N,) int8: +1 front, -1 back, 0 none. backend as for
    :func:`simulate` (the physics' per-penny search, physics.scalar.first_impact_resumed)."""
    params = check_params(params)
    if table is None:
        raise ValueError("table: first_impact needs a table (the open plane has no walls)")
    tab = _table(table, params)
    S = as_states(states)
    n = S.shape[1]
    check_inside(S, params, tab, "states")
    acc1, acc2 = _controls(controls, n, params)
    h = _times(horizon, n, "horizon")
    settings = check_settings(settings)
    if _backend(backend) == "cuda":
        from .backends.batch import CompiledBatch
        from .physics.laws import ImpactLaw
        from .backends.pennies import FIRST_IMPACT_ROUNDS
        return CompiledBatch(params, tab, ImpactLaw("elastic", 1.0), settings, target=_cuda_target()).first_impacts(
            S, acc1, acc2, h, FIRST_IMPACT_ROUNDS)
    with _named(None, tab, "first_impact"):
        return first_impacts(S, acc1, acc2, h, params, tab, settings, backend=backend)


def impact_map(states, ends, *, params=None, table, law="elastic") -> np.ndarray:
    """(N, 6) post-impact states for states whose end ends[i] (+1 front, -1 back) is on the wall. A law that
    returns a non-finite velocity, or adds kinetic energy where the end moves outward, raises a ValueError
    naming it and the row."""
    params = check_params(params)
    if table is None:
        raise ValueError("table: impact_map needs a table")
    tab = _table(table, params)
    law = make_law(law)
    S = as_states(states)
    n = S.shape[1]
    e = real_array(ends, "ends", "+-1 or an (N,) array of +-1")
    e = e.reshape(-1) if e.ndim else np.full(n, e)
    if e.shape != (n,):
        raise ValueError(f"ends must be +-1 or have shape ({n},), got {np.shape(ends)}")
    badend = ~np.isin(e, (1, -1))
    if badend.any():
        k = int(np.flatnonzero(badend)[0])
        raise ValueError(f"ends[{k}] must be +1 (front) or -1 (back), got {e[k]!r}")
    e = e.astype(float)
    px, py, _, _ = end_kinematics(S, e, params.R)
    g = tab.h(px, py)
    off = np.abs(g) > 1e-8 * tab.size
    if off.any():
        k = int(np.flatnonzero(off)[0])
        raise ValueError(f"states[{k}]: the {'front' if e[k] > 0 else 'back'} end is not on the wall (h = {g[k]:.3g})")
    with _named(law, tab, "impact_map"):
        post = apply_law(S, e, params, tab, law)
    check_mapped(S, post, e, params, tab, law)  # (the event loop's guard, for the map: physics/faults.py)
    return post.T.copy()


@dataclass
class BatchResult:
    """Result of :func:`simulate`: final_states (N, 6); impact_counts (N,); the impacts of all
    pennies sorted by penny then time: impact_env, impact_times [s since the start], impact_ends
    (+1/-1), impact_states (k, 6) right after each impact."""

    final_states: np.ndarray
    impact_counts: np.ndarray
    impact_env: np.ndarray
    impact_times: np.ndarray
    impact_ends: np.ndarray
    impact_states: np.ndarray

    def times_of(self, i: int) -> np.ndarray:
        """Impact times of penny i."""
        return self.impact_times[self.impact_env == i]


@contextmanager
def _named(law, table, where):
    """An exception raised inside a user's law or table (plain Python) as a ValueError naming it (faults.blame)."""
    try:
        yield
    except Exception as exc:
        named = blame(exc, law, table, where)
        if named is None:
            raise
        raise named from exc


def _backend(backend):
    if backend not in ("auto", "numba", "python", "cuda"):
        raise ValueError(f"backend must be 'auto', 'numba', 'python' or 'cuda', got {backend!r}")
    return backend


def _cuda_target():
    """'cuda', checked: numba-cuda installed and a GPU (or its simulator) usable, else ValueError."""
    import importlib.util

    from .backends.builder import cuda_available
    if importlib.util.find_spec("numba_cuda") is None:
        raise ValueError("backend='cuda' needs numba-cuda, the cuda extra: in a clone of penny_env, "
                         "pip install -e \".[cuda]\" (docs/gpu.md)")
    if not cuda_available():
        raise ValueError("backend='cuda': numba-cuda finds no CUDA GPU here (nor its simulator, NUMBA_ENABLE_CUDASIM=1)")
    return "cuda"


def _stepper(params, table, law, settings, backend):
    """The event loop over one interval for (6, N) states: (new S, None or (env, time, end, post))."""
    from .backends.batch import CompiledBatch
    from .backends.choice import choose_backend, compiles

    if _backend(backend) == "cuda":
        if not compiles(table):
            raise ValueError(f"backend='cuda': table {type(table).__name__} has no compiled formulas")
        return CompiledBatch(params, table, law, settings, target=_cuda_target()).states_and_impacts
    if choose_backend(backend, table, python="python") == "numba":
        return CompiledBatch(params, table, law, settings).states_and_impacts

    def step(S, acc1, acc2, dt):
        S, log, _ = advance_pennies(S, acc1, acc2, dt, params, table, law, settings, backend="python")
        return S, (None if log.env.size == 0 else (log.env, log.time, log.end, log.state))
    return step


def simulate(states, *, params=None, table, law="elastic", t_final, controls=None, control_dt=None,
             settings=None, backend="auto") -> BatchResult:
    """Simulate N pennies to t_final with every impact, batched (a loop over control intervals,
    never over pennies). controls: None (free motion), (K, 2) torques shared by all pennies or
    (K, N, 2) per penny, row k held on [k, k+1) control_dt; K control_dt must cover t_final.
    backend: "numba" runs the physics' per-penny event loop compiled and in parallel over the pennies
    (backends/physics.py), "cuda" the same functions on a GPU, one thread per penny (numpy in and out,
    copied each interval; docs/gpu.md), "python" the same loop in plain Python (slow: for debugging and tests);
    "auto" (default) takes numba where it is installed and the table compiles (with a one-time
    warning otherwise). Both give bitwise the same results (tests/backends/test_compiled.py). A law or a table that
    breaks its contract at an impact raises a ValueError naming it and the penny (physics/faults.py)."""
    params = check_params(params)
    tab = _table(table, params)
    law = make_law(law)
    settings = check_settings(settings)
    S = as_states(states)
    n = S.shape[1]
    if tab is not None:
        check_inside(S, params, tab, "states")
    t_final = positive_time(t_final, "t_final")
    if controls is None:
        if control_dt is not None:
            raise ValueError("control_dt is given but controls is None")
        dt_grid = _UNCONTROLLED_CHUNK
        k_steps, last_dt = interval_grid(t_final, dt_grid)
        if k_steps > MAX_INTERVALS:
            raise ValueError(f"t_final={t_final!r} needs {k_steps} intervals of {_UNCONTROLLED_CHUNK} s, beyond the "
                             f"limit MAX_INTERVALS = {MAX_INTERVALS} per call (bounded work); split the run")
        zero = np.zeros(n)
        accel = lambda k: (zero, zero)  # noqa: E731
    else:
        if control_dt is None:
            raise ValueError("control_dt is required when controls are given")
        dt_grid = control_dt = positive_time(control_dt, "control_dt")
        u = real_array(controls, "controls", "a (K, 2) or (K, N, 2) array of torques")
        if u.ndim == 2 and u.shape[1] == 2:
            u = np.broadcast_to(u[:, None, :], (u.shape[0], n, 2))
        if u.ndim != 3 or u.shape[1:] != (n, 2) or u.shape[0] == 0:
            raise ValueError(f"controls must have shape (K, 2) or (K, {n}, 2), got {np.shape(controls)}")
        bad = ~np.isfinite(u)
        if bad.any():
            k, i, _ = np.argwhere(bad)[0]
            raise ValueError(f"controls[{k}] for penny {i} is not finite")
        k_steps, last_dt = interval_grid(t_final, control_dt)
        if k_steps > u.shape[0]:
            raise ValueError(f"t_final={t_final} is beyond the controls' horizon {u.shape[0] * control_dt} (K * control_dt)")
        accel = lambda k: (u[k, :, 0] / params.J, u[k, :, 1] / params.rolling_inertia)  # noqa: E731
    step = _stepper(params, tab, law, settings, backend)
    envs, times, ends, posts = [], [], [], []
    t0 = 0.0
    recorded = 0
    for k in range(k_steps):
        dt = dt_grid if k < k_steps - 1 else last_dt
        acc1, acc2 = accel(k)
        check_speed_bound(S, acc1, acc2, dt, params, "controls" if controls is not None else "states",
                          k if controls is not None else None)
        with _named(law, tab, f"interval {k} (t = {t0:.6g} s)"):
            S, log = step(S, acc1, acc2, dt)
        if log is not None:
            envs.append(log[0])
            times.append(t0 + log[1])
            ends.append(log[2])
            posts.append(log[3])
            recorded += log[0].size
            if recorded > BATCH_IMPACTS_PER_LIMIT * settings.max_impacts:
                raise ValueError(f"t_final={t_final!r}: the batch recorded more than {BATCH_IMPACTS_PER_LIMIT} x "
                                 f"SolverSettings.max_impacts = {BATCH_IMPACTS_PER_LIMIT * settings.max_impacts} impacts "
                                 f"by t = {t0 + dt:.6g} s (bounded memory); ask for less or raise SolverSettings.max_impacts")
        t0 += dt
    if envs:
        env = np.concatenate(envs)
        order = np.argsort(env, kind="stable")
        res = (env[order], np.concatenate(times)[order], np.concatenate(ends)[order], np.concatenate(posts)[order])
    else:
        res = (np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int8), np.zeros((0, 6)))
    if audited(tab):  # a user's registered shape: its formulas against its own h where the pennies hit
        pick = sample(len(res[0]))
        check_impacts(tab, res[3][pick], res[2][pick], params.R,
                      row_names=[f"penny {i}, t = {t:.6g} s" for i, t in zip(res[0][pick], res[1][pick])])
    return BatchResult(S.T.copy(), np.bincount(res[0], minlength=n), *res)
