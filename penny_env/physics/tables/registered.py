"""Checks of a table shape registered from outside the package (penny_env.register_table): its formulas are
what the event loop runs, so they are held to what a ConvexTable is held to.

* At registration (tables/base.check_table_class): ``terms`` and ``hess`` take ``(c, x, y)``; numba compiles
  them (backends/checks.py, called by penny_env.register_table).
* Per instance, before a penny rolls on it (:func:`check_registered`, called by validation.check_table, once
  per distinct table): on a grid over its extent, ``terms`` against its own ``h`` and ``grad``, ``hess``
  against its ``hessian`` where it has one (:func:`check_formulas_on_grid`; the compiled copies are compared
  too where a compiled backend runs the table, backends/checks.py); then the bounds, the extent, the convexity
  and the inradius by tables.convex.check_on_grid, as a ConvexTable's. One wrong factor in a formula let
  pennies leave the table by 1.3 to 33 mm before this check.

A grid cannot prove a bound: bounds that hold on the grid but not between its points are caught at run
time by the event loop's guard (an end found outside the wall, physics/faults.py).
"""
from __future__ import annotations

import math
import weakref

import numpy as np

from .base import N_CONSTANTS

GRID = 41          # points per axis of the formulas' comparison (check_on_grid then uses its own 97)
FORMULA_RTOL = 1e-9  # formulas vs methods, relative to the largest |h|, |grad h|, |Hessian| on the grid
_CHECKED = weakref.WeakKeyDictionary()  # table -> True: the tables already checked (tables hash by value)


def _pointwise(f, c, X, Y):
    """(3, ...) array of f(c, x, y) at every grid point (the formulas are scalar code)."""
    out = np.empty((3,) + X.shape)
    for idx in np.ndindex(X.shape):
        out[(slice(None),) + idx] = f(c, float(X[idx]), float(Y[idx]))
    return out


def _compare(owner, label, got, want, names, groups, X, Y) -> None:
    """got against want row by row; the tolerance of a row is FORMULA_RTOL times the largest value of its group
    (h alone; the gradient's two components together; the Hessian's three)."""
    for group in groups:
        scale = max(float(np.max(np.abs(want[list(group)]))), 1e-300)
        for k in group:
            _compare_row(owner, label, got[k], want[k], names[k], scale, X, Y)


def _compare_row(owner, label, got, want, name, scale, X, Y) -> None:
    err = np.abs(got - want)
    if np.all(np.isfinite(got)) and err.max() <= FORMULA_RTOL * scale:
        return
    i = np.unravel_index(np.argmax(np.where(np.isfinite(err), err, np.inf)), err.shape)
    raise ValueError(f"{owner}: the compiled formula {label} gives {name} = {got[i]:.9g} where the table's own method "
                     f"gives {want[i]:.9g} at (x, y) = ({X[i]:.6g}, {Y[i]:.6g}); "
                     "the event loop runs the formula, so it must equal the methods "
                     "(the table's h, grad, hessian), which the checks and the renderer use")


def grid(table):
    """(c, X, Y): the table's constants padded to N_CONSTANTS, and the GRID x GRID comparison grid over its extent."""
    c = tuple(float(v) for v in table.constants())
    c = c + (0.0,) * (N_CONSTANTS - len(c))
    xmin, xmax, ymin, ymax = (float(v) for v in table.extent)
    X, Y = np.meshgrid(np.linspace(xmin, xmax, GRID), np.linspace(ymin, ymax, GRID))
    return c, X, Y


def owner_of(table) -> str:
    return f"table {getattr(table, 'name', type(table).__name__)!s} ({type(table).__name__})"


def check_formulas_on_grid(table, terms, hess, how: str) -> None:
    """``terms`` (and ``hess`` where the table has a ``hessian``) against the table's own h, grad (and hessian)
    on the comparison grid; ValueError naming the table and the first point where they differ. ``how``: how the
    formulas were made (" (compiled by numba)", for backends/checks.py), in the message."""
    owner = owner_of(table)
    c, X, Y = grid(table)
    with np.errstate(all="ignore"):
        H = np.asarray(table.h(X, Y), dtype=float) * np.ones_like(X)
        gx, gy = (np.asarray(g, dtype=float) * np.ones_like(X) for g in table.grad(X, Y))
    _compare(owner, "terms" + how, _pointwise(terms, c, X, Y), np.stack([H, gx, gy]), ("h", "dh/dx", "dh/dy"),
             ((0,), (1, 2)), X, Y)
    hessian = getattr(table, "hessian", None)
    if callable(hessian):
        with np.errstate(all="ignore"):
            want_h = np.stack([np.asarray(v, dtype=float) * np.ones_like(X) for v in hessian(X, Y)])
        _compare(owner, "hess" + how, _pointwise(hess, c, X, Y), want_h, ("hxx", "hxy", "hyy"), ((0, 1, 2),), X, Y)


def check_registered(table) -> None:
    """The per-instance checks of the module docstring; ValueError naming the table and the check. Only for a
    registered class from outside penny_env with formulas (penny_env's own shapes are tested in the suite),
    once per distinct table."""
    from .base import compiled_kind
    cls = type(table)
    if table is None or cls.terms is None or compiled_kind(cls) < 0 or cls.__module__.startswith("penny_env."):
        return
    once(_CHECKED, table, _check_instance)


def once(checked, table, check) -> None:
    """``check(table)`` once per distinct table (``checked``: a WeakKeyDictionary of the tables done; tables hash by
    value; an unhashable table is checked every time)."""
    try:
        if checked.get(table):
            return
    except TypeError:
        check(table)
        return
    check(table)
    checked[table] = True


def _check_instance(table) -> None:
    from .convex import check_on_grid
    cls = type(table)
    owner = owner_of(table)
    xmin, xmax, ymin, ymax = (float(v) for v in table.extent)
    check_formulas_on_grid(table, cls.terms, cls.hess, "")
    hessian = getattr(table, "hessian", None)
    check_on_grid(owner, table.h, table.grad, float(table.grad_bound), float(table.hessian_bound), (xmin, xmax, ymin, ymax),
                  inradius=float(table.inradius), hessian=hessian if callable(hessian) else None, edge_may_touch=True)
    if not math.isfinite(float(getattr(table, "third_derivative_bound", 0.0))):
        raise ValueError(f"{owner}.third_derivative_bound must be finite")


# -- at impacts: the formulas against the table's own h where the penny hits ----------------
AUDIT_SAMPLE = 64     # impacts of one simulate() / batch call compared (evenly spaced over its impacts)
AUDIT_FIRST = 256     # an environment compares every impact of its first AUDIT_FIRST...
AUDIT_EVERY = 64      # ...then one impact in AUDIT_EVERY
GRAD_RTOL = 1e-8      # the formula's gradient against grad, relative to the largest |grad h| of the sample


def audited(table) -> bool:
    """The table is a registered shape from outside penny_env whose formulas (terms) the event loop runs: its
    impacts are compared with its own h (penny_env's own shapes are tested in the suite and cost nothing here)."""
    if table is None:
        return False
    cls = type(table)
    if cls.__module__.startswith("penny_env.") or cls.terms is None:
        return False
    from .base import compiled_kind
    return compiled_kind(cls) >= 0


def check_impacts(table, states, ends, R: float, where: str = "", row_names=None) -> None:
    """ValueError naming the table when, at an impact, its formula ``terms`` and its own ``h`` and ``grad`` disagree
    at the end that hit the wall. states: (k, 6) post-impact states (the end's position is the impact's), ends:
    (k,) +1 / -1; where: what ran (the message's prefix), or row_names[i] for row i. Only for :func:`audited`
    tables; the callers pass a sample of their impacts.

    The grid check (check_formulas_on_grid) compares them on 41 x 41 points; formulas that agree there and differ
    between the points (a term that vanishes on every grid line) passed it, and the run-time guard, which measures
    depth with the same formulas, could not see it: pennies left the table's own wall by 3 mm. At an impact the
    formula's h is 0 by construction, so the table's own h there says how far the wall the penny hit lies from the
    table's wall."""
    if not audited(table):
        return
    S = np.asarray(states, dtype=float).reshape(-1, 6)
    if S.shape[0] == 0:
        return
    e = np.asarray(ends, dtype=float).reshape(-1)
    px = S[:, 0] + e * R * np.cos(S[:, 3])
    py = S[:, 1] + e * R * np.sin(S[:, 3])
    with np.errstate(all="ignore"):
        h = np.asarray(table.h(px, py), dtype=float) * np.ones_like(px)
        gx, gy = (np.asarray(g, dtype=float) * np.ones_like(px) for g in table.grad(px, py))
    c, _, _ = grid(table)
    terms = type(table).terms
    got = np.array([terms(c, float(x), float(y)) for x, y in zip(px, py)], dtype=float).reshape(-1, 3)
    tol_h = 1e-8 * float(table.size)  # the run-time guard's tolerance for an end outside the wall (faults.OUTSIDE_TOL)
    tol_g = GRAD_RTOL * max(float(np.max(np.hypot(gx, gy))), 1e-300)
    err_h = np.abs(got[:, 0] - h)
    err_g = np.hypot(got[:, 1] - gx, got[:, 2] - gy)
    bad = ~(np.isfinite(got).all(axis=1) & (err_h <= tol_h) & (err_g <= tol_g))
    if not bad.any():
        return
    i = int(np.flatnonzero(bad)[0])
    where = row_names[i] if row_names is not None else where
    prefix = f"{where}: " if where else ""
    raise ValueError(f"{prefix}{owner_of(table)}: at an impact at (x, y) = ({px[i]:.6g}, {py[i]:.6g}) its formula terms "
                     f"gives h = {got[i, 0]:.3g}, grad = ({got[i, 1]:.6g}, {got[i, 2]:.6g}) where the table's own h and "
                     f"grad give h = {h[i]:.3g}, grad = ({gx[i]:.6g}, {gy[i]:.6g}): the formulas the event loop runs "
                     f"differ from the table between the points of the {GRID} x {GRID} grid they were checked on, so "
                     "the penny bounced off another wall than the table's (h is what the checks, the resets and the "
                     "renderer use); make terms and hess compute exactly h, grad and hessian")


def sample(n: int, k: int = AUDIT_SAMPLE) -> np.ndarray:
    """k evenly spaced indices of n impacts (all of them when n <= k), first and last included."""
    if n <= k:
        return np.arange(n)
    return np.unique(np.linspace(0, n - 1, k).round().astype(np.int64))


class ImpactAudit:
    """The environments' sample of impacts for :func:`check_impacts`: every impact of the first AUDIT_FIRST, then
    one in AUDIT_EVERY, counted over the environment's life."""

    def __init__(self, table, R: float):
        self.table, self.R, self.seen = table, float(R), 0

    def check(self, states, ends, where: str = "") -> None:
        """states (k, 6) post-impact states and ends (k,) of a step's impacts, in order."""
        k = len(ends)
        idx = np.arange(self.seen, self.seen + k)
        take = (idx < AUDIT_FIRST) | (idx % AUDIT_EVERY == 0)
        self.seen += k
        if take.any():
            check_impacts(self.table, np.asarray(states, dtype=float).reshape(-1, 6)[take],
                          np.asarray(ends)[take], self.R, where)
