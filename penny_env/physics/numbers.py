"""Numbers as the public API takes them: a clear TypeError naming the field for a wrong type, a ValueError for a
bad value. numpy's own conversions are not trusted for this: ``np.array("1.5", dtype=float)`` parses strings
and ``float(True)`` is 1.0, so every numeric input goes through :func:`real` or :func:`real_array`, which
check the type first."""
from __future__ import annotations

import math
import numbers

import numpy as np


def is_real(value) -> bool:
    """A real number of a numeric type: int, float or a numpy integer/float scalar (not bool)."""
    return (isinstance(value, (numbers.Real, np.integer, np.floating))
            and not isinstance(value, (bool, np.bool_)))


def real(value, name: str) -> float:
    """value as a finite float, or TypeError (not a real number) / ValueError (not finite) naming name."""
    if not is_real(value):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__}")
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return value


def real_array(value, name: str, what: str) -> np.ndarray:
    """A float64 copy of an array-like of real numbers (ints or floats, not bools, strings,
    complex numbers or None), or a TypeError naming name; what describes the expected shape."""
    if isinstance(value, (str, bytes)) or value is None:
        raise TypeError(f"{name} must be {what}, got {type(value).__name__}")
    if not isinstance(value, np.ndarray):
        # nested sequences: numpy would turn [True, 0] into ints and ["1.5"] into floats, so look at each entry
        try:
            entries = np.asarray(value, dtype=object)
        except (TypeError, ValueError):
            raise ValueError(f"{name} must be {what} (ragged or unreadable input)") from None
        for v in entries.flat:
            if not is_real(v):
                raise TypeError(f"{name} must be {what} of real numbers, got an entry of type {type(v).__name__}")
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be {what} (ragged or unreadable input)") from None
    if arr.dtype.kind not in "iuf":
        kind = {"b": "booleans", "c": "complex numbers", "U": "strings", "S": "strings", "O": "non-numeric entries"}
        raise TypeError(f"{name} must be {what} of real numbers, got {kind.get(arr.dtype.kind, arr.dtype.name)}")
    return np.array(arr, dtype=float)


def _positive(value, name: str) -> float:
    if not is_real(value):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__}")
    value = float(value)
    if not np.isfinite(value) or value <= 0:
        raise ValueError(f"{name} must be positive and finite, got {value!r}")
    return value


def positive_time(value, name: str) -> float:
    return _positive(value, name)


def positive_count(value, name: str) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (numbers.Integral, np.integer)):
        raise TypeError(f"{name} must be an integer, got {type(value).__name__}")
    if value < 1:
        raise ValueError(f"{name} must be >= 1, got {value}")
    return int(value)
