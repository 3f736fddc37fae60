"""What ``penny_env.register_law`` tries before it accepts a law (physics.laws.law_record; the compiled trials:
backends/checks.compile_law).

A law is a plain function ``update(W, w, a, b, grad2, e, Itot, J, m) -> (W+, w+)`` that the event loop
calls at every impact, compiled by numba (backends/physics.py). A law that cannot run there, or that
runs and returns nonsense, used to surface far from its cause: a numba TypingError while an unrelated
env compiled, NaN observations, or speeds of 1e14 rad/s past MAX_ANGULAR_SPEED. So registration tries
it first, with a message naming the law:

* its signature binds the nine arguments (``inspect.signature``), and a trial call returns two real
  numbers (TypeError otherwise);
* on :func:`trial_arguments`, typical impacts (the end moving outward, as the event loop calls a
  law), it returns finite velocities, never adds kinetic energy ``(Itot W^2 + J w^2) / 2`` beyond
  round-off (ENERGY_RTOL) and leaves the end no longer moving outward (n+ = a W+ + b w+ at most OUTWARD_RTOL
  (|a W| + |b w|), round-off:
  the identity law would have the search find the same impact at once, forever); a law registered with
  ``conserves_energy=True`` must also not lose any;
* numba compiles it for float64 arguments, and the compiled function passes the same trials (numba's math
  differs from Python's on domain errors: ``math.sqrt(-1)`` is NaN there, an exception here):
  backends/checks.compile_law.

The checks are a first line, not a proof: a law that misbehaves only away from the trial points is
caught at run time by the event loop's guard (scalar.impact_fault), which ends the call with an
error naming the law (docs/extending.md).
"""
from __future__ import annotations

import inspect
import math

from .numbers import is_real
from .params import PennyParams

ENERGY_RTOL = 1e-12  # relative kinetic-energy change an impact may show from round-off (the built-in laws: < 1e-15)
# after an impact the end may move outward by at most this fraction of its normal speed before it (round-off of the
# plastic law's sticking rule, which leaves it exactly at 0): a law that leaves it moving outward would make the
# search find the same impact again at once, every call spinning through its event cap without advancing
OUTWARD_RTOL = 1e-9
ARGUMENTS = ("W", "w", "a", "b", "grad2", "e", "Itot", "J", "m")


def _pennies():
    """(R, Itot, J, m) of the paper's penny and of two others (a thick disk, for which the plastic law
    sticks, and a large light one): laws see the penny's inertias, so they are tried on several."""
    out = []
    for p in (PennyParams(), PennyParams(R=0.02, m=0.01, I=3 * 0.01 * 0.02 ** 2, J=2 * 0.01 * 0.02 ** 2),
              PennyParams(R=0.1, m=0.002, I=0.5 * 0.002 * 0.1 ** 2, J=0.25 * 0.002 * 0.1 ** 2)):
        out.append((p.R, p.rolling_inertia, p.J, p.m))
    return out


def trial_arguments(e: float) -> list:
    """Typical impacts as argument tuples (W, w, a, b, grad2, e, Itot, J, m): wall gradients of norm 0.5, 1
    and 2 in 16 directions against the heading, both ends, speeds from 0.05 to 200 rad/s of both signs,
    kept where the end moves outward (n = a W + b w > 0), as the event loop calls a law; for three
    pennies: 4320 tuples."""
    out = []
    speeds_W = (-200.0, -7.0, -0.3, 0.05, 2.0, 40.0)
    speeds_w = (-60.0, -1.5, 0.0, 0.2, 9.0)
    for R, Itot, J, m in _pennies():
        for g in (0.5, 1.0, 2.0):
            for k in range(16):
                beta = 2.0 * math.pi * (k + 0.25) / 16  # gradient direction against the heading (phi = 0)
                hx, hy = g * math.cos(beta), g * math.sin(beta)
                for sigma in (1.0, -1.0):
                    a, b = R * hx, sigma * R * hy
                    for W in speeds_W:
                        for w in speeds_w:
                            if a * W + b * w > 0.0:
                                out.append((W, w, a, b, g * g, e, Itot, J, m))
    return out


def kinetic(W, w, Itot, J):
    """Twice the kinetic energy, Itot W^2 + J w^2 (products, as the event loop computes it)."""
    return Itot * (W * W) + J * (w * w)


def _where(args) -> str:
    return ", ".join(f"{k}={v:.6g}" for k, v in zip(ARGUMENTS, args))


def check_signature(name: str, update) -> None:
    """TypeError naming the law unless update takes the nine positional arguments."""
    try:
        sig = inspect.signature(update)
    except (TypeError, ValueError):  # a builtin or a C function without a signature: the trial call decides
        return
    try:
        sig.bind(*ARGUMENTS)
    except TypeError:
        raise TypeError(f"register_law({name!r}): update must take the nine arguments "
                        f"({', '.join(ARGUMENTS)}) and return (W+, w+); its signature is {sig}") from None


def try_law(name: str, update, e: float, conserves_energy: bool, label: str = "update") -> None:
    """Call update on every trial_arguments(e): TypeError for a result that is not two real numbers;
    ValueError naming the law and the first offending impact for an exception, a non-finite result, an
    energy gain beyond ENERGY_RTOL, or (conserves_energy) a loss beyond it."""
    for args in trial_arguments(e):
        try:
            out = update(*args)
        except Exception as exc:  # noqa: BLE001 (any failure of the user's function is reported as such)
            raise ValueError(f"register_law({name!r}): {label} raised {type(exc).__name__}: {exc} on the impact "
                             f"{_where(args)}") from exc
        try:
            W1, w1 = out
        except (TypeError, ValueError):
            raise TypeError(f"register_law({name!r}): {label} must return two numbers (W+, w+), got {out!r}") from None
        if not (is_real(W1) and is_real(w1)):
            raise TypeError(f"register_law({name!r}): {label} must return two real numbers (W+, w+), got {out!r}")
        W1, w1 = float(W1), float(w1)
        if not (math.isfinite(W1) and math.isfinite(w1)):
            raise ValueError(f"register_law({name!r}): {label} returned a non-finite velocity ({W1!r}, {w1!r}) on the "
                             f"impact {_where(args)}; a law must return finite (W+, w+) at every impact")
        W, w, Itot, J = args[0], args[1], args[6], args[7]
        before, after = kinetic(W, w, Itot, J), kinetic(W1, w1, Itot, J)
        if after > before * (1.0 + ENERGY_RTOL):
            raise ValueError(f"register_law({name!r}): {label} adds kinetic energy at the impact {_where(args)}: "
                             f"{before / 2:.6g} J before, {after / 2:.6g} J after (a relative gain of "
                             f"{after / before - 1:.3g}, beyond round-off {ENERGY_RTOL:g}); impact laws must not "
                             "increase the kinetic energy")
        a, b = args[2], args[3]
        n_before, n_after = a * W + b * w, a * W1 + b * w1
        if n_after > OUTWARD_RTOL * (abs(a * W) + abs(b * w)):
            raise ValueError(f"register_law({name!r}): {label} leaves the end moving outward at the impact {_where(args)}: "
                             f"its normal speed n = a W + b w is {n_before:.6g} before and {n_after:.6g} after; a law "
                             "must send the end back inside (n+ <= 0), or the penny would cross the wall")
        if conserves_energy and after < before * (1.0 - ENERGY_RTOL):
            raise ValueError(f"register_law({name!r}): conserves_energy=True, but {label} loses kinetic energy at the "
                             f"impact {_where(args)}: {before / 2:.6g} J before, {after / 2:.6g} J after; register it "
                             "with conserves_energy=False (the default)")


def check_law(name: str, update, e: float, conserves_energy: bool) -> None:
    """The plain-Python checks of the module docstring, in order (signature, trials); the compiled trials are
    backends/checks.compile_law's."""
    check_signature(name, update)
    try_law(name, update, e, conserves_energy)
