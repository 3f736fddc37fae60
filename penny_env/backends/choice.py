"""Which backend runs a table: numba where it is installed and the table has compiled formulas, else the
plain-Python functions, with a warning naming the slower path."""
from __future__ import annotations

import importlib.util

from .checks import check_compiled_formulas


def available() -> bool:
    """numba is installed, so compiled batches can run (numba itself is imported at first use)."""
    return importlib.util.find_spec("numba") is not None


_WARNED = set()


def compiles(table) -> bool:
    """The table runs in the compiled loop: the open plane (None) or a registered table with formulas."""
    from ..physics.tables import compiled_kind
    return table is None or compiled_kind(type(table)) >= 0


def choose_backend(backend, table, table_field="table", python="numpy") -> str:
    """'numba' or the plain-Python name ``python`` for ``backend`` in 'auto', 'numba', ``python``:
    'auto' takes numba where it is installed and the table compiles (:func:`compiles`), and warns once
    per table type naming the slower plain-Python path where it does not; an explicit 'numba' that
    cannot run raises ValueError naming the cause. Where numba is chosen for a user's table, its compiled
    formulas are first compared with its own methods (checks.check_compiled_formulas)."""
    chosen = _choose(backend, table, table_field, python)
    if chosen == "numba":
        check_compiled_formulas(table)
    return chosen


def _choose(backend, table, table_field, python) -> str:
    if backend not in ("auto", python, "numba"):
        raise ValueError(f"backend must be 'auto', {python!r} or 'numba', got {backend!r}")
    ok = compiles(table)
    if backend == "numba":
        if not available():
            raise ValueError("backend='numba' needs numba: pip install numba")
        if not ok:
            raise ValueError(f"backend='numba': {table_field} {type(table).__name__} does not compile "
                             f"(registered tables with formulas and the open plane do); use backend={python!r}")
    if backend == "auto":
        if not ok and type(table) not in _WARNED:
            import warnings
            _WARNED.add(type(table))
            warnings.warn(f"{table_field} {getattr(table, 'name', type(table).__name__)!s} ({type(table).__name__}) has no "
                          "compiled formulas: it runs the plain-Python event loop, much slower (register its "
                          "formulas to compile it, see docs/extending.md)", RuntimeWarning, stacklevel=3)
        return "numba" if available() and ok else python
    return backend
