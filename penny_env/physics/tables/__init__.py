"""Convex tables {h < 0} the penny rolls on: the table protocol and registry (base.py) and one
module per shape. See docs/extending.md to add one."""
from __future__ import annotations

from .base import TABLE_KINDS, Table, add_table, check_table_class
# not in __all__, still imported from here: the compiled builds' formulas and dispatch (backends/physics.py,
# backends/choice.py, the tests) and N_CONSTANTS (how many constants a compiled formula receives)
from .base import COMPILED_FORMULAS, N_CONSTANTS, compiled_kind  # noqa: F401
from .convex import PROTOCOL, ConvexTable, ProtocolTable, check_on_grid
from .ellipse import Circle, Ellipse
from .stadium import Stadium
from .rounded_rectangle import RoundedRectangle

__all__ = ["Table", "Ellipse", "Circle", "Stadium", "RoundedRectangle", "ConvexTable", "ProtocolTable",
           "add_table", "check_table_class", "make_table", "as_table", "TABLE_KINDS", "PROTOCOL", "check_on_grid"]


def as_table(table) -> Table | None:
    """None, a Table, or any object following the table protocol (checked and wrapped in ProtocolTable)."""
    if table is None or isinstance(table, Table):
        return table
    if isinstance(table, (dict, str, int, float)):
        raise TypeError(f"table must be a penny_env table ({', '.join(c.__name__ for c in TABLE_KINDS.values())}, "
                        f"ConvexTable), an object following the table protocol, or None; got {type(table).__name__}")
    return ProtocolTable(table)


def make_table(spec) -> Table | None:
    """A table from a spec: a Table, an object following the table protocol, None (open plane), or
    a dict such as {"kind": "ellipse", "a": 0.15, "b": 0.2}; kinds: the registered ones (TABLE_KINDS:
    ellipse, circle, stadium, rounded_rectangle, ...) and none."""
    if spec is None or isinstance(spec, Table):
        return spec
    if not isinstance(spec, dict) and all(hasattr(spec, k) for k in PROTOCOL):
        return ProtocolTable(spec)
    if not isinstance(spec, dict):
        raise TypeError(f"table must be a Table, None or a dict, got {type(spec).__name__}")
    spec = dict(spec)
    kind = spec.pop("kind", None)
    if kind in (None, "none", "plane"):
        if spec:
            raise ValueError(f"table: unknown field(s) {sorted(spec)} for kind 'none'")
        return None
    if kind not in TABLE_KINDS:
        raise ValueError(f"table.kind must be one of {sorted(TABLE_KINDS) + ['none']}, got {kind!r}")
    try:
        return TABLE_KINDS[kind](**spec)
    except TypeError as exc:
        if "keyword argument" in str(exc) or "required positional argument" in str(exc):
            raise ValueError(f"table ({kind}): {exc}") from None  # an unknown or missing field: a bad spec
        raise TypeError(f"table ({kind}): {exc}") from None       # a field of the wrong type
