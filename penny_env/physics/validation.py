"""Input checks shared by the public physics API: clear errors that name the field."""
from __future__ import annotations

import numpy as np

from .flows import end_kinematics
from .params import PennyParams
from .tables import as_table

STATE_FIELDS = ("x", "y", "theta", "phi", "theta_dot", "phi_dot")


def as_state(state, name: str = "state") -> np.ndarray:
    """A length-6 float64 copy of state, or a ValueError/TypeError naming what is wrong."""
    try:
        arr = np.array(state, dtype=float)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a length-6 array of floats {STATE_FIELDS}") from None
    if arr.shape != (6,):
        raise ValueError(f"{name} must have shape (6,) = {STATE_FIELDS}, got shape {arr.shape}")
    bad = ~np.isfinite(arr)
    if bad.any():
        fields = [STATE_FIELDS[i] for i in np.flatnonzero(bad)]
        raise ValueError(f"{name} has non-finite entries: {', '.join(fields)}")
    return arr


def as_states(states, name: str = "states") -> np.ndarray:
    """(N, 6) float64 copy of a batch of states, checked; returned as (6, N)."""
    try:
        arr = np.array(states, dtype=float)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be an (N, 6) array of floats") from None
    if arr.ndim != 2 or arr.shape[1] != 6:
        raise ValueError(f"{name} must have shape (N, 6), got {arr.shape}")
    bad = ~np.isfinite(arr)
    if bad.any():
        rows, cols = np.nonzero(bad)
        raise ValueError(f"{name}[{rows[0]}] has a non-finite {STATE_FIELDS[cols[0]]}")
    return np.ascontiguousarray(arr.T)


def check_params(params) -> PennyParams:
    if params is None:
        return PennyParams()
    if not isinstance(params, PennyParams):
        raise TypeError(f"params must be a PennyParams, got {type(params).__name__}")
    return params


def check_table(table, params: PennyParams):
    table = as_table(table)
    if table is None:
        return None
    if not table.inradius > params.R:
        raise ValueError(f"table: too small for the penny, its inradius {table.inradius:.6g} m is not larger than R = {params.R:.6g} m")
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
    try:
        u = np.array(controls, dtype=float)
    except (TypeError, ValueError):
        raise TypeError("controls must be an array of (u1, u2) rows") from None
    if u.ndim != 2 or u.shape[1] != n_controls or u.shape[0] == 0:
        raise ValueError(f"controls must have shape (K, 2) with K >= 1 rows of (u1, u2), got {u.shape}")
    if not np.all(np.isfinite(u)):
        raise ValueError(f"controls has non-finite entries (row {int(np.flatnonzero(~np.isfinite(u).all(axis=1))[0])})")
    if control_dt is None:
        raise ValueError("control_dt is required when controls are given")
    dt = _positive(control_dt, "control_dt")
    return u, dt


def _positive(value, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__}")
    value = float(value)
    if not np.isfinite(value) or value <= 0:
        raise ValueError(f"{name} must be positive and finite, got {value!r}")
    return value


def positive_time(value, name: str) -> float:
    return _positive(value, name)


def positive_count(value, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be an integer, got {type(value).__name__}")
    if value < 1:
        raise ValueError(f"{name} must be >= 1, got {value}")
    return int(value)
