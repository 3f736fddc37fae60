"""Physical parameters of the penny and numerical settings of the event solver.

Both are frozen dataclasses (gymnax/Brax style): the physics functions take them as
arguments and never mutate them.
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np

# Documented limits on the inputs (docs/physics.md, Limits): they bound the work of one call.
MAX_ANGULAR_SPEED = 1e5   # [rad/s] |theta_dot|, |phi_dot| a state may have or the controls may reach
MAX_STEERED_PHASE = 2e4   # [rad] heading swept in one interval under a steering torque (quadrature work)
MAX_CONTROL_DT = 10.0     # [s] an environment's control period (each step's work)
MIN_GAP = 1e-6            # tables need inradius >= R (1 + MIN_GAP): the search resolves the two ends' impacts


def _real(owner: str, name: str, value) -> float:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (numbers.Real, np.integer, np.floating)):
        raise TypeError(f"{owner}.{name} must be a real number, got {type(value).__name__}")
    return float(value)


def _check_positive_finite(owner: str, **fields: float) -> None:
    for name, value in fields.items():
        value = _real(owner, name, value)
        if not math.isfinite(value) or value <= 0:
            raise ValueError(f"{owner}.{name} must be positive and finite, got {value!r}")


@dataclass(frozen=True)
class PennyParams:
    """Radius R [m], mass m [kg], inertia I about the rolling axis and J about the vertical
    axis [kg m^2]. Defaults are the paper's US-penny values (I = m R^2 / 2, J = m R^2 / 4)."""

    R: float = 0.01
    m: float = 0.0025
    I: float = 1.25e-7
    J: float = 6.25e-8

    def __post_init__(self) -> None:
        _check_positive_finite("PennyParams", R=self.R, m=self.m, I=self.I, J=self.J)
        for name in ("R", "m", "I", "J"):
            object.__setattr__(self, name, float(getattr(self, name)))

    @property
    def rolling_inertia(self) -> float:
        """I + m R^2: the inertia that the rolling torque u2 acts against."""
        return self.I + self.m * self.R**2


@dataclass(frozen=True)
class SolverSettings:
    """Numerical settings of the event-driven solver. The defaults give round-off accuracy;
    they only change what happens in degenerate situations.

    contact_tol:    an end within contact_tol * (table size) of the wall, moving outward, is
                    an impact (a few ulps of the table's size; it also bounds any penetration).
    zeno_impacts:   this many consecutive impacts, each closer than zeno_window [s] to the
                    previous one, are an accumulation (Zeno) and the penny is brought to rest.
    max_search_steps: bound on certified search steps per impact search (bounded work).
    max_events_per_interval: bound on impacts processed by one call of the event loop (bounded
                    work per call); the call stops there and its caller resumes it, so it never
                    changes the motion.
    max_impacts:    bound on the impacts one simulate() call records (bounded memory, about
                    0.7 kB and 0.5 to 1 ms each in plain Python); a run that would record
                    more stops with a ValueError.
    """

    contact_tol: float = 16 * 2.220446049250313e-16
    zeno_impacts: int = 16
    zeno_window: float = 1e-9
    max_search_steps: int = 400
    max_events_per_interval: int = 10_000
    max_impacts: int = 100_000

    def __post_init__(self) -> None:
        _check_positive_finite("SolverSettings", contact_tol=self.contact_tol, zeno_window=self.zeno_window)
        for name in ("contact_tol", "zeno_window"):
            object.__setattr__(self, name, float(getattr(self, name)))
        for name in ("zeno_impacts", "max_search_steps", "max_events_per_interval", "max_impacts"):
            v = getattr(self, name)
            if isinstance(v, (bool, np.bool_)) or not isinstance(v, (numbers.Integral, np.integer)):
                raise TypeError(f"SolverSettings.{name} must be an integer, got {type(v).__name__}")
            if v < 1:
                raise ValueError(f"SolverSettings.{name} must be a positive integer, got {v!r}")
            if v > 2**63 - 1:  # (the compiled loop holds it in an int64)
                raise ValueError(f"SolverSettings.{name} must be <= 2**63 - 1 (an int64), got {v!r}")
            object.__setattr__(self, name, int(v))


DEFAULT_SETTINGS = SolverSettings()
