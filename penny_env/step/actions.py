"""The actions as the step takes them, checked on the host before any state changes."""
from __future__ import annotations

import numpy as np

from ..physics.numbers import real_array


def check_actions(actions, shape, name="action"):
    """float64 array of the given shape from actions: a TypeError for a wrong type (strings,
    None, bools, complex numbers, objects), a ValueError naming the sub-env(s) for a wrong shape
    or non-finite entries. Nothing is clipped here (the step clips)."""
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
