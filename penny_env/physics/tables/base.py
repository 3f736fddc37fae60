"""The table protocol, the base class of the built-in tables and the table registry.

The table protocol (what the solver needs from a table; a user table implements it or is
built with :class:`~penny_env.physics.tables.convex.ConvexTable`):

============== ==============================================================================
``h(x, y)``    wall function, vectorised over numpy arrays: < 0 inside, 0 on the wall, > 0
               outside. It must be C^1 with a Lipschitz gradient on the table.
``grad(x, y)`` the gradient (hx, hy) of h, vectorised.
``grad_bound`` G >= sup |grad h| over the closed table.
``hessian_bound`` L >= Lipschitz constant of grad h over the closed table (sup of the
               Hessian's spectral norm where h is C^2).
``inradius``   radius of a disk that fits inside the table (a lower bound is fine).
``hessian(x, y)`` optional: (hxx, hxy, hyy), vectorised. With it the search also uses a
               third-order certificate (fast past near-tangencies), which needs:
``third_derivative_bound`` sup |D^3 h[u, u, u]| over unit u where h is C^3 (0 if omitted);
``hessian_jump`` sup of the jump of u^T (Hess h) u, unit u, across the lines where h is only
               C^1,1 (0 if omitted).
``extent``     (xmin, xmax, ymin, ymax), a box containing the table.
============== ==============================================================================

G and L are what make the impact search certain: along a flow the wall function of an end,
g(t) = h(end(t)), obeys g'' <= L |end'|^2 + G |end''| while the end is on the table, so a step
on which the quadratic upper bound stays negative cannot contain an impact (kernels.search_step).
The built-in tables scale h to have |grad h| = 1 on (part of) the wall, so h is in metres.

A built-in table shape is one module of this package: its class (a :class:`Table`) with the
formulas the compiled event loop calls, ``terms(c, x, y) -> (h, hx, hy)`` and
``hess(c, x, y) -> (hxx, hxy, hyy)`` (plain-math static functions that numba compiles; ``c`` is
the tuple :meth:`Table.constants`), and one ``penny_env.register_table`` call (see docs/extending.md).
"""
from __future__ import annotations

import math

import numpy as np

N_CONSTANTS = 5  # the constants a compiled table formula receives (Table.constants, zero-padded)


class Table:
    """Base class of the tables; see the module docstring for the protocol.

    Subclasses that compile define the static functions ``terms`` and ``hess`` and
    :meth:`constants`; :meth:`spawn_axes` and :meth:`wall_distance` have generic versions."""

    name: str = "table"
    grad_bound: float
    hessian_bound: float
    inradius: float
    extent: tuple[float, float, float, float]
    terms = None  # numba-compatible (c, x, y) -> (h, hx, hy), or None (the table's methods are called)
    hess = None   # numba-compatible (c, x, y) -> (hxx, hxy, hyy)
    ray = None    # numba-compatible (c, cos, sin) -> distance from the centre to the wall (optional)

    def h(self, x, y):  # pragma: no cover - abstract
        raise NotImplementedError

    def grad(self, x, y):  # pragma: no cover - abstract
        raise NotImplementedError

    def constants(self) -> tuple:
        """The numbers ``terms`` and ``hess`` read (at most N_CONSTANTS floats)."""
        return ()

    @property
    def size(self) -> float:
        """Largest |coordinate| of the extent: the length scale of tolerances."""
        return max(abs(v) for v in self.extent)

    def spawn_axes(self) -> tuple[float, float]:
        """Semi-axes (ax, ay) of an ellipse centred on the origin, inside the table and containing
        its inscribed disk: the environments draw initial positions and targets in it."""
        return self.inradius, self.inradius

    def wall_distance(self, c, s):
        """Distance from the origin to the wall along the unit directions (c, s), vectorised
        (generic version: bisection on h along the ray; the origin must be inside)."""
        c, s = np.asarray(c, dtype=float), np.asarray(s, dtype=float)
        lo, hi = np.zeros_like(c), np.full_like(c, 2.0 * self.size)  # 2 size > the extent's half-diagonal
        for _ in range(64):
            mid = 0.5 * (lo + hi)
            inside = np.asarray(self.h(mid * c, mid * s)) < 0
            lo, hi = np.where(inside, mid, lo), np.where(inside, hi, mid)
        return lo

    def boundary(self, n: int = 256) -> np.ndarray:
        """(n, 2) points on the wall, for plotting and rendering (generic: along rays)."""
        ang = np.linspace(0.0, 2 * np.pi, n)
        rho = self.wall_distance(np.cos(ang), np.sin(ang))
        return np.stack([rho * np.cos(ang), rho * np.sin(ang)], axis=1)

    def __repr__(self) -> str:
        return f"{type(self).__name__}({', '.join(f'{k}={v!r}' for k, v in self._fields().items())})"

    def _fields(self) -> dict:
        """The numbers that define the table (its repr, equality and hash). By default every public
        instance attribute, so that two tables of a class that does not name its parameters are equal
        only when everything they hold is; the built-in tables name their constructor's arguments."""
        return {k: _plain(v) for k, v in sorted(vars(self).items()) if not k.startswith("_")}

    def _key(self) -> tuple:
        """What tells two tables apart: the type, _fields(), and the numbers the event loop reads (constants()
        and the protocol's bounds), so that a subclass whose _fields() leaves a number out is still told apart
        by what the physics reads."""
        numbers = tuple(_plain(getattr(self, k, None)) for k in ("grad_bound", "hessian_bound", "inradius",
                                                                   "third_derivative_bound", "hessian_jump", "extent"))
        return (type(self), tuple(self._fields().items()), _plain(self.constants()), numbers)

    def __eq__(self, other) -> bool:
        return type(self) is type(other) and self._key() == other._key()

    def __hash__(self) -> int:
        return hash(self._key())


def _plain(value):
    """value with numpy scalars and arrays as Python floats and tuples (hashable, compared by value)."""
    if isinstance(value, (tuple, list, np.ndarray)):
        return tuple(_plain(v) for v in value)
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    return value


LENGTH_RANGE = (1e-100, 1e100)  # table numbers outside it overflow or underflow in 1/a^2, a^2, ... (no ZeroDivisionError)


def length(owner: str, name: str, value, allow_zero: bool = False) -> float:
    """A positive (or non-negative) finite real number in LENGTH_RANGE, else TypeError / ValueError naming the field."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise TypeError(f"{owner}.{name} must be a real number, got {type(value).__name__}")
    value = float(value)
    if not math.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
        raise ValueError(f"{owner}.{name} must be {'non-negative' if allow_zero else 'positive'} and finite, got {value!r}")
    # a length that may be zero never divides (a stadium's straight side): only the upper bound applies to it
    if value > LENGTH_RANGE[1] or (0 < value < LENGTH_RANGE[0] and not allow_zero):
        raise ValueError(f"{owner}.{name} must lie in [{LENGTH_RANGE[0]:g}, {LENGTH_RANGE[1]:g}], got {value!r}")
    return value


# -- the registry ------------------------------------------------------------------------------------
TABLE_KINDS: dict = {}      # name -> class (the "kind" of a table spec)
COMPILED_FORMULAS: list = []  # (terms, hess, ray or None) of the compiled tables; Model.kind indexes it


def check_table_class(name: str, cls) -> None:
    """The checks of a table class before it is registered (plain Python; penny_env.register_table adds the
    compiled ones, backends/checks.py): a name that is an identifier and not the plane's; a class; not one of
    penny_env's own names for another class; ``terms`` with ``hess``, both taking ``(c, x, y)``
    (tables/registered.check_formula_signatures). TypeError / ValueError naming the class otherwise."""
    if not isinstance(name, str) or not name.isidentifier():
        raise ValueError(f"register_table: name must be an identifier, got {name!r}")
    if name in ("none", "plane"):
        raise ValueError(f"register_table: {name!r} is reserved for the open plane")
    if not isinstance(cls, type):
        raise TypeError(f"register_table: cls must be a class, got {type(cls).__name__}")
    old = TABLE_KINDS.get(name)
    if old is not None and is_own(old) and not is_own(cls):
        raise ValueError(f"register_table: {name!r} is one of penny_env's own table shapes and cannot be replaced "
                         "(environment ids use it); register yours under another name")
    if cls.terms is not None:
        if cls.hess is None:
            raise ValueError(f"register_table: {cls.__name__} defines terms but not hess")
        check_formula_signatures(cls)


def check_formula_signatures(cls) -> None:
    """TypeError unless cls.terms and cls.hess are functions taking (c, x, y)."""
    import inspect
    for label in ("terms", "hess"):
        f = getattr(cls, label)
        if not callable(f):
            raise TypeError(f"register_table: {cls.__name__}.{label} must be a function (a staticmethod of (c, x, y)), "
                            f"got {type(f).__name__}")
        try:
            sig = inspect.signature(f)
        except (TypeError, ValueError):
            continue
        try:
            sig.bind("c", "x", "y")
        except TypeError:
            raise TypeError(f"register_table: {cls.__name__}.{label} must take (c, x, y) (a staticmethod: c the table's "
                            f"constants()); its signature is {sig}") from None


def is_own(cls) -> bool:
    """cls is one of penny_env's own shapes (tested in the suite; compiled in the package's namespace)."""
    return cls.__module__.startswith("penny_env.")


def add_table(name: str, cls) -> None:
    """Make ``make_table({"kind": name, ...})`` (and scene YAML ``table: {kind: name, ...}``) build ``cls(...)``
    once :func:`check_table_class` accepts it; a class with static ``terms`` and ``hess`` also runs in the
    compiled event loop (and ``ray(c, cos, sin)``, optional, gives the distance from the centre to the wall
    along a direction; without it the compiled code bisects on terms' h). Users register shapes with
    ``penny_env.register_table``, which also tries the compiled formulas (backends/checks.py). Registering a name
    again replaces the class for every table built afterwards, with a UserWarning."""
    check_table_class(name, cls)
    old = TABLE_KINDS.get(name)
    TABLE_KINDS[name] = cls
    if cls.terms is not None and compiled_kind(cls) < 0:
        COMPILED_FORMULAS.append((cls.terms, cls.hess, getattr(cls, "ray", None)))
    if old is not None and old is not cls:
        import warnings
        warnings.warn(f"register_table: {name!r} now builds {cls.__name__}; tables, environments and batches built "
                      "before keep the class they were built with", UserWarning, stacklevel=3)


def compiled_kind(table_or_cls) -> int:
    """Index of the table's formulas in COMPILED_FORMULAS, or -1 (not compiled: called through its methods)."""
    terms = getattr(table_or_cls, "terms", None)
    for k, (t, *_) in enumerate(COMPILED_FORMULAS):
        if t is terms:
            return k
    return -1
