"""What a fault of the event loop's run-time guard means, in words (physics/scalar.py records the codes).

The event loop checks every impact, and only the impacts (scalar.advance_into): an end found more than
``Model.outside_tol`` outside the wall (scalar.OUTSIDE_TOL of the table's size: the impact search
stepped past the wall, so the table's declared bounds or its compiled formulas are false), a law that
returns a non-finite velocity, or a law that adds kinetic energy beyond round-off (law_checks.ENERGY_RTOL).
It stops that penny's call there and records the fault; compiled code (CPU and CUDA) never raises.
Then the callers:

* simulate() and the batch API raise the ValueError of :func:`fault_error`, naming the law or the table
  and the bound to fix;
* the environments end the episode, truncated, with ``info["limit"]`` the fault's LIMIT_* code
  (step/functional.py) and a warning with the same words (:func:`warn_episode_fault`).

Motion without faults is not changed by the guard.
"""
from __future__ import annotations

import math

from .law_checks import ENERGY_RTOL, OUTWARD_RTOL

# the codes the event loop records in ImpactBuffers.fault (scalar.advance_into) rather than raising in compiled code
FAULT_NONE, FAULT_NONFINITE, FAULT_ENERGY, FAULT_OUTSIDE, FAULT_OUTWARD = 0, 1, 2, 3, 4
OUTSIDE_TOL = 1e-8  # [table sizes] an end found farther outside the wall at an impact is a fault (FAULT_OUTSIDE):
# 10 times what validation.check_inside lets a given state have, about 10^6 times the search's own penetration

FAULT_NAMES = {FAULT_NONE: "", FAULT_NONFINITE: "law_nonfinite", FAULT_ENERGY: "law_energy", FAULT_OUTSIDE: "outside_wall",
               FAULT_OUTWARD: "law_outward"}


def _law_name(law) -> str:
    return f"law {getattr(law, 'kind', law)!r}" if law is not None else "the impact law"


def _table_name(table) -> str:
    if table is None:
        return "the table"
    return f"table {getattr(table, 'name', type(table).__name__)!s} ({type(table).__name__})"


def outside_depth(state, table, R) -> float:
    """How far outside the wall (the table's h) the farther end of ``state`` lies [m], or NaN."""
    if table is None or state is None:
        return math.nan
    x, y, ph = float(state[0]), float(state[1]), float(state[3])
    c, s = math.cos(ph), math.sin(ph)
    try:
        return max(float(table.h(x + R * c, y + R * s)), float(table.h(x - R * c, y - R * s)))
    except Exception:  # noqa: BLE001 (only for the message)
        return math.nan


def describe(code, law=None, table=None, depth=math.nan) -> str:
    """The fault's cause and what to fix, in one sentence or two."""
    code = int(code)
    if code == FAULT_NONFINITE:
        return (f"{_law_name(law)} returned a non-finite velocity at an impact; a law must return finite "
                "(theta_dot, phi_dot) at every impact: fix its update function and register it again (register_law)")
    if code == FAULT_ENERGY:
        return (f"{_law_name(law)} added kinetic energy at an impact, beyond round-off (relative "
                f"{ENERGY_RTOL:g}); impact laws must not increase the kinetic energy: fix its update function and "
                "register it again (register_law)")
    if code == FAULT_OUTWARD:
        return (f"{_law_name(law)} left the end of the penny moving outward after an impact (its normal speed "
                f"beyond {OUTWARD_RTOL:g} of the one before): the search would find the same impact again at once, "
                "forever; a law must send the end back inside (n+ = a W+ + b w+ <= 0): fix its update function and "
                "register it again (register_law)")
    if code == FAULT_OUTSIDE:
        found = f" {depth:.3g} m" if math.isfinite(depth) and depth > 0 else ""
        bounds = ""
        if table is not None:
            bounds = (f" (grad_bound = {getattr(table, 'grad_bound', float('nan')):g}, hessian_bound = "
                      f"{getattr(table, 'hessian_bound', float('nan')):g})")
        return (f"an end of the penny was found{found} outside the wall of {_table_name(table)} at an impact, "
                f"beyond the tolerance {OUTSIDE_TOL:g} of the table's size: the impact search stepped past the wall, "
                f"so the table's declared bounds{bounds} are below the true sup |grad h| and Lipschitz constant of "
                "grad h between the points of its grid check (or its compiled formulas terms/hess differ from h and "
                "grad): give true bounds")
    raise ValueError(f"unknown fault code {code}")


def fault_error(code, law=None, table=None, state=None, R=None, where="") -> ValueError:
    """The ValueError for fault ``code`` (simulate, the batch API); where: "penny 3, t = 0.2 s" or ""."""
    depth = outside_depth(state, table, R) if code == FAULT_OUTSIDE and R is not None else math.nan
    prefix = f"{where}: " if where else ""
    return ValueError(prefix + describe(code, law, table, depth))


def check_faults(buf, law=None, table=None, states=None, R=None, t0=0.0, elapsed=None) -> None:
    """Raise :func:`fault_error` for the first penny whose row of ImpactBuffers ``buf`` holds a fault
    (states: (6, N) states the call returned, elapsed (N,) the times it reached)."""
    fault = buf.fault
    bad = [i for i in range(len(fault)) if fault[i] != FAULT_NONE]
    if not bad:
        return
    i = bad[0]
    state = None if states is None else [states[r][i] for r in range(6)]
    when = "" if elapsed is None else f", {t0 + float(elapsed[i]):.6g} s into its interval"
    raise fault_error(int(fault[i]), law, table, state, R, f"penny {i}{when}")


def check_mapped(S, post, sigma, params, table, law, name: str = "states") -> None:
    """The run-time guard's law checks for impact_map (which applies the law outside the event loop): a non-finite
    velocity, an energy gain beyond ENERGY_RTOL or an end left moving outward where it moved outward before (as the
    event loop applies a law), is a ValueError naming the law and the row. S, post: (6, N) states before and
    after; sigma: the ends."""
    import numpy as np

    from .laws import normal_form
    bad = ~(np.isfinite(post[4]) & np.isfinite(post[5]))
    code = FAULT_NONFINITE
    if not bad.any():
        a, b, _ = normal_form(S, sigma, params, table)
        outward = np.broadcast_to(a * S[4] + b * S[5] > 0.0, bad.shape)
        Itot, J = params.rolling_inertia, params.J
        before = Itot * (S[4] * S[4]) + J * (S[5] * S[5])
        after = Itot * (post[4] * post[4]) + J * (post[5] * post[5])
        bad = outward & (after > before * (1.0 + ENERGY_RTOL))
        code = FAULT_ENERGY
        if not bad.any():
            n_after = a * post[4] + b * post[5]
            bad = outward & np.broadcast_to(n_after > OUTWARD_RTOL * (np.abs(a * S[4]) + np.abs(b * S[5])), bad.shape)
            code = FAULT_OUTWARD
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        where = name if S.shape[1] == 1 else f"{name}[{i}]"
        raise ValueError(f"{where}: " + describe(code, law))


def warn_episode_fault(limit_name: str, code, law=None, table=None) -> None:
    """A warning that an episode ended on a fault (the env's info["limit"] also says so)."""
    import warnings
    warnings.warn(f"penny_env: an episode ended, truncated with info['limit'] = {limit_name!r}: "
                  + describe(code, law, table), RuntimeWarning, stacklevel=3)


def _code(f):
    """The code object of a plain function or a bound method, else None."""
    f = getattr(f, "__func__", f)
    return getattr(f, "__code__", None)


def user_functions(law=None, table=None) -> dict:
    """{code object: what it is, in words} of the user's functions the event loop calls in plain Python: a
    registered law's update, a registered table's formulas and methods, a ConvexTable's or a protocol object's
    h, grad and hessian. penny_env's own are left out (they are tested in the suite)."""
    out = {}
    update = getattr(law, "update", None)
    if update is not None and not getattr(update, "__module__", "").startswith("penny_env."):
        out[_code(update)] = f"{_law_name(law)} (its update function)"
    if table is not None:
        obj = getattr(table, "_obj", None)  # a ProtocolTable: the user's object
        owner = obj if obj is not None else table
        cls = type(owner)
        fns = {"terms": getattr(cls, "terms", None), "hess": getattr(cls, "hess", None),
               "h": getattr(table, "_h", None) or getattr(owner, "h", None),
               "grad": getattr(table, "_grad", None) or getattr(owner, "grad", None),
               "hessian": getattr(owner, "hessian", None)}
        for label, f in fns.items():
            module = getattr(getattr(f, "__func__", f), "__module__", None) or ""
            if f is not None and not module.startswith("penny_env."):
                out[_code(f)] = f"{_table_name(table)} (its {label})"
    out.pop(None, None)
    return out


def blame(exc, law=None, table=None, where="") -> ValueError | None:
    """A ValueError naming the user's law or table when ``exc`` was raised inside one of their functions (its
    traceback passes through it: the innermost such frame), else None: a law's ``math.sqrt`` of a negative number
    at an impact used to surface as a bare "math domain error" from simulate()."""
    codes = user_functions(law, table)
    culprit = None
    tb = exc.__traceback__
    while tb is not None:
        culprit = codes.get(tb.tb_frame.f_code, culprit)
        tb = tb.tb_next
    if culprit is None:
        return None
    prefix = f"{where}: " if where else ""
    fix = ("a law must return two finite numbers for every impact: fix its update function and register it again "
           "(register_law)" if culprit.startswith("law") else
           "a table's functions must give finite numbers everywhere on its extent: fix them")
    return ValueError(f"{prefix}{culprit} raised {type(exc).__name__}: {exc}, called by the event loop; {fix}")
