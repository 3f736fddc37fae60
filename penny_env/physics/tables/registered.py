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
    from .convex import check_on_grid
    cls = type(table)
    if table is None or cls.terms is None or compiled_kind(cls) < 0 or cls.__module__.startswith("penny_env."):
        return
    try:
        if _CHECKED.get(table):
            return
    except TypeError:  # an unhashable table: checked every time
        pass
    owner = owner_of(table)
    xmin, xmax, ymin, ymax = (float(v) for v in table.extent)
    check_formulas_on_grid(table, cls.terms, cls.hess, "")
    hessian = getattr(table, "hessian", None)
    check_on_grid(owner, table.h, table.grad, float(table.grad_bound), float(table.hessian_bound), (xmin, xmax, ymin, ymax),
                  inradius=float(table.inradius), hessian=hessian if callable(hessian) else None, edge_may_touch=True)
    if not math.isfinite(float(getattr(table, "third_derivative_bound", 0.0))):
        raise ValueError(f"{owner}.third_derivative_bound must be finite")
    try:
        _CHECKED[table] = True
    except TypeError:
        pass
