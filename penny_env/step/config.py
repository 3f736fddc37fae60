"""The checks of configuration fields, shared by scenes (envs/scene.py) and tasks (step/tasks/): every error
names the field, a ConfigError (a ValueError) for a bad value, a ConfigTypeError (also a TypeError) for a
wrong type."""
from __future__ import annotations

import math


class ConfigError(ValueError):
    """An invalid scene/task configuration; the message names the field."""


class ConfigTypeError(ConfigError, TypeError):
    """A configuration field of the wrong type (a string for a number, a list for a mapping): a
    ConfigError, and a TypeError as the rest of the package raises for a wrong type."""


class UnknownFieldError(ConfigError, TypeError):
    """A field (or keyword argument) that the scene and task do not have: a ConfigError, and a
    TypeError as Python raises for an unexpected keyword argument (tools such as TorchRL probe
    keywords that way)."""


def number(owner: str, name: str, value, *, positive=False, nonneg=False, lo=None, hi=None) -> float:
    """A finite real number (ints and numpy scalars too; not a bool, not a string), with its bounds."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        import numpy as np
        if not isinstance(value, (np.integer, np.floating)) or isinstance(value, np.bool_):
            hint = ""
            if isinstance(value, str):
                try:
                    float(value)
                    hint = " (a string: write the number unquoted, e.g. 0.01 or 1.0e-2)"
                except ValueError:
                    pass
            raise ConfigTypeError(f"{owner}.{name} must be a number, got {value!r}{hint}")
    value = float(value)
    if not math.isfinite(value):
        raise ConfigError(f"{owner}.{name} must be finite, got {value!r}")
    if positive and value <= 0:
        raise ConfigError(f"{owner}.{name} must be positive, got {value!r}")
    if nonneg and value < 0:
        raise ConfigError(f"{owner}.{name} must be non-negative, got {value!r}")
    if lo is not None and value < lo:
        raise ConfigError(f"{owner}.{name} must be >= {lo}, got {value!r}")
    if hi is not None and value > hi:
        raise ConfigError(f"{owner}.{name} must be <= {hi}, got {value!r}")
    return value


INT64_MAX = (1 << 63) - 1


def count(owner: str, name: str, value) -> int:
    """A positive integer that fits an int64 (the compiled step holds it as one)."""
    import numbers
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise ConfigTypeError(f"{owner}.{name} must be a positive integer, got {value!r}")
    value = int(value)
    if value < 1:
        raise ConfigError(f"{owner}.{name} must be a positive integer, got {value!r}")
    if value > INT64_MAX:
        raise ConfigError(f"{owner}.{name} must be <= 2**63 - 1 (an int64), got {value!r}")
    return value
