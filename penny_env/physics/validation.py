"""Input checks shared by the public physics API: clear errors that name the field.

A wrong type (a string, a complex number, a boolean, None, a non-numeric object) is a TypeError
naming the field; a value of the right type that is out of range (NaN, inf, negative, beyond a
documented limit) is a ValueError naming the field. numpy's own conversions are not trusted for
this: ``np.array("1.5", dtype=float)`` parses strings and ``float(True)`` is 1.0, so every numeric
input goes through :func:`real` or :func:`real_array`, which check the type first.
"""
from __future__ import annotations


import numpy as np

from .flows import end_kinematics
from .params import (DEFAULT_SETTINGS, MAX_ANGULAR_SPEED, MAX_CONTROL_DT, MAX_STEERED_PHASE, MIN_GAP,
                     PennyParams, SolverSettings)
from .numbers import _positive, is_real, positive_count, positive_time, real, real_array  # noqa: F401 (re-exported)
from .tables import as_table
from .tables.registered import check_registered

STATE_FIELDS = ("x", "y", "theta", "phi", "theta_dot", "phi_dot")


def as_state(state, name: str = "state") -> np.ndarray:
    """A length-6 float64 copy of state, or a ValueError/TypeError naming what is wrong."""
    arr = real_array(state, name, f"a length-6 array {STATE_FIELDS}")
    if arr.shape != (6,):
        raise ValueError(f"{name} must have shape (6,) = {STATE_FIELDS}, got shape {arr.shape}")
    bad = ~np.isfinite(arr)
    if bad.any():
        fields = [STATE_FIELDS[i] for i in np.flatnonzero(bad)]
        raise ValueError(f"{name} has non-finite entries: {', '.join(fields)}")
    check_speeds(arr[None, :], name)
    return arr


def as_states(states, name: str = "states") -> np.ndarray:
    """(N, 6) float64 copy of a batch of states, checked; returned as (6, N)."""
    arr = real_array(states, name, "an (N, 6) array")
    if arr.ndim != 2 or arr.shape[1] != 6:
        raise ValueError(f"{name} must have shape (N, 6), got {arr.shape}")
    bad = ~np.isfinite(arr)
    if bad.any():
        rows, cols = np.nonzero(bad)
        raise ValueError(f"{name}[{rows[0]}] has a non-finite {STATE_FIELDS[cols[0]]}")
    check_speeds(arr, name)
    return np.ascontiguousarray(arr.T)


def check_speeds(rows: np.ndarray, name: str) -> None:
    """|theta_dot| and |phi_dot| of (N, 6) rows within MAX_ANGULAR_SPEED (bounded work per call)."""
    fast = np.abs(rows[:, 4:6]) > MAX_ANGULAR_SPEED
    if fast.any():
        i, j = np.argwhere(fast)[0]
        where = f"{name}[{i}]" if rows.shape[0] > 1 or name.endswith("s") else name
        raise ValueError(f"{where}: |{STATE_FIELDS[4 + j]}| = {abs(rows[i, 4 + j]):.6g} rad/s is beyond the limit "
                         f"MAX_ANGULAR_SPEED = {MAX_ANGULAR_SPEED:g} rad/s (docs/physics.md, Limits)")


def check_speed_bound(state, acc1, acc2, dt, params: PennyParams, name: str, k=None) -> None:
    """Refuse (ValueError naming name and the limit) a controlled interval that would take the penny
    beyond MAX_ANGULAR_SPEED (|theta_dot| + |acc2| dt or |phi_dot| + |acc1| dt from the interval's
    start state), or whose steering torque would sweep more than MAX_STEERED_PHASE radians of
    heading (the work of the flow's quadrature grows with it). Free intervals (no torque) are not
    limited: their flow is in closed form and impacts never add energy. state: a 6-tuple with float
    accelerations, or a (6, N) array with (N,) accelerations (dt a float)."""
    if isinstance(state, tuple):  # one penny, plain floats (simulate's loop: no numpy overhead)
        if acc1 == 0.0 and acc2 == 0.0:
            return
        w_end = abs(state[5]) + abs(acc1) * dt
        if (abs(state[4]) + abs(acc2) * dt <= MAX_ANGULAR_SPEED and w_end <= MAX_ANGULAR_SPEED
                and (acc1 == 0.0 or w_end * dt <= MAX_STEERED_PHASE)):
            return
    acc1, acc2 = np.asarray(acc1, dtype=float), np.asarray(acc2, dtype=float)
    W_end = np.abs(np.asarray(state[4])) + np.abs(acc2) * dt
    w_end = np.abs(np.asarray(state[5])) + np.abs(acc1) * dt
    controlled = (acc1 != 0.0) | (acc2 != 0.0)
    too_fast = controlled & ((W_end > MAX_ANGULAR_SPEED) | (w_end > MAX_ANGULAR_SPEED))
    steered = (acc1 != 0.0) & (w_end * dt > MAX_STEERED_PHASE)
    bad = np.atleast_1d(too_fast | steered)
    if not bad.any():
        return
    i = int(np.flatnonzero(bad)[0])
    where = name if k is None else f"{name}[{k}]"
    if bad.size > 1:
        where += f" (penny {i})"
    Wm, wm = float(np.atleast_1d(W_end)[i]), float(np.atleast_1d(w_end)[i])
    if np.atleast_1d(too_fast)[i]:
        raise ValueError(f"{where}: over this interval ({dt:.6g} s) the torques would take the penny to |theta_dot| = "
                         f"{Wm:.3g} or |phi_dot| = {wm:.3g} rad/s, beyond the limit MAX_ANGULAR_SPEED = "
                         f"{MAX_ANGULAR_SPEED:g} rad/s (bounded work per call; docs/physics.md, Limits)")
    raise ValueError(f"{where}: under a steering torque the heading could sweep {wm * dt:.3g} rad in one interval "
                     f"({dt:.6g} s), beyond the limit MAX_STEERED_PHASE = {MAX_STEERED_PHASE:g} rad (bounded work per "
                     "call; use shorter control intervals; docs/physics.md, Limits)")


def check_actuation(params: PennyParams, u1_max: float, u2_max: float, control_dt: float) -> None:
    """An environment's actuation within the documented limits (bounded work per step): control_dt
    <= MAX_CONTROL_DT, and one step at the torque limits adds at most MAX_ANGULAR_SPEED to
    |phi_dot| or |theta_dot| and sweeps at most MAX_STEERED_PHASE of heading. ValueError naming the
    field and the limit."""
    if control_dt > MAX_CONTROL_DT:
        raise ValueError(f"control_dt = {control_dt!r} s is beyond the limit MAX_CONTROL_DT = {MAX_CONTROL_DT:g} s")
    for name, gain in (("u1", u1_max * control_dt / params.J), ("u2", u2_max * control_dt / params.rolling_inertia)):
        if gain > MAX_ANGULAR_SPEED:
            raise ValueError(f"torque_limits.{name} = {u1_max if name == 'u1' else u2_max!r} N m adds {gain:.3g} rad/s in "
                             f"one control_dt, beyond the limit MAX_ANGULAR_SPEED = {MAX_ANGULAR_SPEED:g} rad/s")
    sweep = u1_max * control_dt ** 2 / params.J
    # (decided by step_speed_limits' own arithmetic: a torque at the limit, whose sweep rounds to just below it,
    # left a bound of -2e-13 rad/s that the next check then blamed on scene.init.phi_dot)
    if sweep > MAX_STEERED_PHASE or step_speed_limits(params, u1_max, u2_max, control_dt)[1] < 0.0:
        raise ValueError(f"torque_limits.u1 = {u1_max!r} N m sweeps {sweep:.6g} rad of heading in one control_dt, at or "
                         f"beyond the limit MAX_STEERED_PHASE = {MAX_STEERED_PHASE:g} rad: a step from any turning speed "
                         "could pass it")


def step_speed_limits(params: PennyParams, u1_max: float, u2_max: float, control_dt: float) -> tuple[float, float]:
    """(W_max, w_max): the largest |theta_dot| and |phi_dot| from which one environment step at the
    torque limits stays within the documented limits (MAX_ANGULAR_SPEED for both speeds, and
    MAX_STEERED_PHASE of heading swept when there is a steering torque). The environments check a
    scene's initial speeds against them and end an episode, truncated, once a state passes them
    (step/functional.py), so every step they run is one the physics accepts. u1_max = 0: no steering
    torque (the heading's phase is then not limited: the flow is in closed form)."""
    W_max = MAX_ANGULAR_SPEED - u2_max * control_dt / params.rolling_inertia
    w_reach = MAX_ANGULAR_SPEED if u1_max == 0.0 else min(MAX_ANGULAR_SPEED, MAX_STEERED_PHASE / control_dt)
    w_max = w_reach - u1_max * control_dt / params.J
    return W_max, w_max


def check_settings(settings) -> SolverSettings:
    if settings is None:
        return DEFAULT_SETTINGS
    if not isinstance(settings, SolverSettings):
        raise TypeError(f"settings must be a SolverSettings, got {type(settings).__name__}")
    return settings


def check_params(params) -> PennyParams:
    if params is None:
        return PennyParams()
    if not isinstance(params, PennyParams):
        raise TypeError(f"params must be a PennyParams, got {type(params).__name__}")
    return params


def check_table(table, params: PennyParams):
    """The table (as_table) checked for the penny: a registered shape from outside penny_env has its formulas and
    bounds checked on a grid (tables/registered.py, once per table), and the table must fit the penny."""
    table = as_table(table)
    if table is None:
        return None
    check_registered(table)
    if not table.inradius > params.R:
        raise ValueError(f"table: too small for the penny, its inradius {table.inradius:.6g} m "
                         f"is not larger than R = {params.R:.6g} m")
    if table.inradius < params.R * (1.0 + MIN_GAP):
        # impacts of the two ends would follow each other within the search's time resolution
        raise ValueError(f"table: too small for the penny, its inradius {table.inradius!r} m exceeds R = {params.R!r} m "
                         f"by less than the limit MIN_GAP = {MIN_GAP:g} R that the impact search resolves "
                         "(docs/physics.md, Limits)")
    return table


def check_inside(s, params: PennyParams, table, name: str = "state", tol: float = 1e-9) -> None:
    """Both ends on or inside the wall (within tol * table size); s is (6, N)."""
    if table is None:
        return
    for sigma, label in ((1.0, "front"), (-1.0, "back")):
        px, py, _, _ = end_kinematics(s, sigma, params.R)
        g = table.h(px, py)
        bad = g > tol * table.size
        if np.any(bad):
            k = int(np.flatnonzero(bad)[0])
            where = f"{name}[{k}]" if s.shape[1] > 1 else name
            raise ValueError(f"{where}: the penny's {label} end is outside the table (h = {float(g[k]):.3g})")


def check_controls(controls, control_dt, n_controls: int = 2):
    if controls is None:
        if control_dt is not None:
            raise ValueError("control_dt is given but controls is None")
        return None, None
    u = real_array(controls, "controls", "a (K, 2) array of (u1, u2) rows")
    if u.ndim != 2 or u.shape[1] != n_controls or u.shape[0] == 0:
        raise ValueError(f"controls must have shape (K, 2) with K >= 1 rows of (u1, u2), got {u.shape}")
    if not np.all(np.isfinite(u)):
        raise ValueError(f"controls has non-finite entries (row {int(np.flatnonzero(~np.isfinite(u).all(axis=1))[0])})")
    if control_dt is None:
        raise ValueError("control_dt is required when controls are given")
    dt = _positive(control_dt, "control_dt")
    return u, dt
