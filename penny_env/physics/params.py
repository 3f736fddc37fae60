"""Physical parameters of the penny and numerical settings of the event solver.

Both are frozen dataclasses (gymnax/Brax style): the physics functions take them as
arguments and never mutate them.
"""
from __future__ import annotations

import math
from dataclasses import dataclass


def _check_positive_finite(owner: str, **fields: float) -> None:
    for name, value in fields.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            try:
                value = float(value)  # numpy scalars
            except (TypeError, ValueError):
                raise TypeError(f"{owner}.{name} must be a real number, got {type(value).__name__}") from None
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
    max_events_per_interval: bound on impacts inside one control interval (bounded work);
                    reaching it also brings the penny to rest.
    """

    contact_tol: float = 16 * 2.220446049250313e-16
    zeno_impacts: int = 16
    zeno_window: float = 1e-9
    max_search_steps: int = 400
    max_events_per_interval: int = 10_000

    def __post_init__(self) -> None:
        _check_positive_finite("SolverSettings", contact_tol=self.contact_tol, zeno_window=self.zeno_window)
        for name in ("zeno_impacts", "max_search_steps", "max_events_per_interval"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"SolverSettings.{name} must be a positive integer, got {v!r}")


DEFAULT_PARAMS = PennyParams()
DEFAULT_SETTINGS = SolverSettings()
