"""Convex tables {h < 0} the penny rolls on.

The table protocol (what the solver needs from a table; a user table implements it or is
built with :class:`ConvexTable`):

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
on which the quadratic upper bound stays negative cannot contain an impact (events.py).
The built-in tables scale h to have |grad h| = 1 on (part of) the wall, so h is in metres.
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np


class Table:
    """Base class of the built-in tables; see the module docstring for the protocol."""

    name: str = "table"
    grad_bound: float
    hessian_bound: float
    inradius: float
    extent: tuple[float, float, float, float]

    def h(self, x, y):  # pragma: no cover - abstract
        raise NotImplementedError

    def grad(self, x, y):  # pragma: no cover - abstract
        raise NotImplementedError

    @property
    def size(self) -> float:
        """Largest |coordinate| of the extent: the length scale of tolerances."""
        return max(abs(v) for v in self.extent)

    def boundary(self, n: int = 256) -> np.ndarray:
        """(n, 2) points on the wall, for plotting and rendering."""
        raise NotImplementedError

    def __repr__(self) -> str:
        return f"{type(self).__name__}({', '.join(f'{k}={v!r}' for k, v in self._fields().items())})"

    def _fields(self) -> dict:
        return {}

    def __eq__(self, other) -> bool:
        return type(self) is type(other) and self._fields() == other._fields()

    def __hash__(self) -> int:
        return hash((type(self).__name__, tuple(self._fields().items())))


LENGTH_RANGE = (1e-100, 1e100)  # table numbers outside it overflow or underflow in 1/a^2, a^2, ... (no ZeroDivisionError)


def _length(owner: str, name: str, value, allow_zero: bool = False) -> float:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise TypeError(f"{owner}.{name} must be a real number, got {type(value).__name__}")
    value = float(value)
    if not math.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
        raise ValueError(f"{owner}.{name} must be {'non-negative' if allow_zero else 'positive'} and finite, got {value!r}")
    if value != 0 and not LENGTH_RANGE[0] <= value <= LENGTH_RANGE[1]:
        raise ValueError(f"{owner}.{name} must lie in [{LENGTH_RANGE[0]:g}, {LENGTH_RANGE[1]:g}], got {value!r}")
    return value


class Ellipse(Table):
    """Elliptic table x^2/a^2 + y^2/b^2 < 1 (semi-axes a along x, b along y), the paper's table.

    h = (x^2/a^2 + y^2/b^2 - 1) * min(a, b) / 2, the paper's h scaled to metres."""

    name = "ellipse"

    def __init__(self, a: float, b: float):
        self.a = _length(type(self).__name__, "a", a)
        self.b = _length(type(self).__name__, "b", b)
        c = min(self.a, self.b)
        self._half_c = 0.5 * c
        self._ia2 = 1.0 / self.a**2
        self._ib2 = 1.0 / self.b**2
        self.grad_bound = 1.0
        self.hessian_bound = 1.0 / c
        self.inradius = c
        self.extent = (-self.a, self.a, -self.b, self.b)

    def _fields(self):
        return {"a": self.a, "b": self.b}

    def h(self, x, y):
        return (x * x * self._ia2 + y * y * self._ib2 - 1.0) * self._half_c

    def grad(self, x, y):
        c2 = 2.0 * self._half_c
        return c2 * x * self._ia2, c2 * y * self._ib2

    third_derivative_bound = 0.0
    hessian_jump = 0.0

    def hessian(self, x, y):
        c2 = 2.0 * self._half_c
        return c2 * self._ia2 + 0.0 * x, 0.0 * x, c2 * self._ib2 + 0.0 * y

    def boundary(self, n: int = 256) -> np.ndarray:
        t = np.linspace(0.0, 2.0 * np.pi, n)
        return np.stack([self.a * np.cos(t), self.b * np.sin(t)], axis=1)


class Circle(Ellipse):
    """Circular table x^2 + y^2 < r^2 (the paper's circle, a = b = r)."""

    name = "circle"

    def __init__(self, r: float):
        r = _length("Circle", "r", r)
        super().__init__(r, r)
        self.r = r

    def _fields(self):
        return {"r": self.r}


class Stadium(Table):
    """Bunimovich stadium: two half-discs of the given radius joined by straight sides of the
    given length, parallel to the x axis and centred on the origin (length 0 is a circle).

    h = (d^2 - radius^2) / (2 radius), d the distance to the segment [-length/2, length/2] x {0};
    h is C^1 with a Lipschitz gradient (the curvature jumps where the sides meet the caps)."""

    name = "stadium"

    def __init__(self, radius: float, length: float):
        self.radius = _length("Stadium", "radius", radius)
        self.length = _length("Stadium", "length", length, allow_zero=True)
        self._half = 0.5 * self.length
        self.grad_bound = 1.0
        self.hessian_bound = 1.0 / self.radius
        self.inradius = self.radius
        self.extent = (-self._half - self.radius, self._half + self.radius, -self.radius, self.radius)

    def _fields(self):
        return {"radius": self.radius, "length": self.length}

    def _offset(self, x, y):
        # vector from the nearest point of the central segment
        if isinstance(x, float):
            return x - min(max(x, -self._half), self._half), y
        return x - np.clip(x, -self._half, self._half), y

    def h(self, x, y):
        dx, dy = self._offset(x, y)
        return (dx * dx + dy * dy - self.radius**2) / (2.0 * self.radius)

    def grad(self, x, y):
        dx, dy = self._offset(x, y)
        return dx / self.radius, dy / self.radius

    third_derivative_bound = 0.0

    @property
    def hessian_jump(self) -> float:
        return 1.0 / self.radius  # the x-curvature switches on where a side meets a cap

    def hessian(self, x, y):
        dx, _ = self._offset(x, y)
        inv = 1.0 / self.radius
        return (dx != 0.0) * inv, 0.0 * x, inv + 0.0 * y

    def boundary(self, n: int = 256) -> np.ndarray:
        k = max(n // 2, 2)
        t = np.linspace(-np.pi / 2, np.pi / 2, k)
        right = np.stack([self._half + self.radius * np.cos(t), self.radius * np.sin(t)], axis=1)
        left = np.stack([-self._half - self.radius * np.cos(t), -self.radius * np.sin(t)], axis=1)
        return np.concatenate([right, left, right[:1]], axis=0)


class ConvexTable(Table):
    """A convex table given by the user as a wall function with its gradient and bounds.

    Parameters
    ----------
    h, grad : vectorised callables of (x, y); see the module docstring.
    grad_bound, hessian_bound : the bounds G and L over the table. They are what guarantees
        that no impact is missed, so give true upper bounds; they are checked on a grid and a
        bound that the grid already contradicts is refused.
    extent : (xmin, xmax, ymin, ymax), a box containing the table (h > 0 on its edge).
    inradius : radius of an inscribed disk; estimated from the grid (a lower bound) if omitted.

    Example: a rounded square ``h = (x**4 + y**4 - s**4) / (4 s**3)`` with
    ``grad = (x**3/s**3, y**3/s**3)``, ``grad_bound = 2**0.25``... (see tests/test_tables.py).
    """

    name = "custom"

    def __init__(self, h: Callable, grad: Callable, *, grad_bound: float, hessian_bound: float,
                 extent, inradius: float | None = None, name: str = "custom", grid: int = 97):
        if not callable(h):
            raise TypeError("ConvexTable.h must be callable")
        if not callable(grad):
            raise TypeError("ConvexTable.grad must be callable")
        self._h, self._grad = h, grad
        self.grad_bound = _length("ConvexTable", "grad_bound", grad_bound)
        self.hessian_bound = _length("ConvexTable", "hessian_bound", hessian_bound, allow_zero=True)
        try:
            ext = tuple(float(v) for v in extent)
        except (TypeError, ValueError):
            raise TypeError("ConvexTable.extent must be (xmin, xmax, ymin, ymax)") from None
        if len(ext) != 4 or not all(map(math.isfinite, ext)) or ext[0] >= ext[1] or ext[2] >= ext[3]:
            raise ValueError(f"ConvexTable.extent must be finite (xmin, xmax, ymin, ymax) with min < max, got {extent!r}")
        self.extent = ext
        self.name = str(name)
        self._validate(grid, inradius)

    def _fields(self):
        return {"h": self._h, "grad": self._grad, "extent": self.extent}

    def h(self, x, y):
        return self._h(x, y)

    def grad(self, x, y):
        return self._grad(x, y)

    def _validate(self, grid: int, inradius) -> None:
        xmin, xmax, ymin, ymax = self.extent
        X, Y = np.meshgrid(np.linspace(xmin, xmax, grid), np.linspace(ymin, ymax, grid))
        with np.errstate(all="ignore"):
            H = np.asarray(self._h(X, Y), dtype=float)
            gx, gy = (np.asarray(g, dtype=float) for g in self._grad(X, Y))
        if H.shape != X.shape or gx.shape != X.shape or gy.shape != X.shape:
            raise ValueError("ConvexTable.h and grad must be vectorised: same shape out as in")
        if not (np.all(np.isfinite(H)) and np.all(np.isfinite(gx)) and np.all(np.isfinite(gy))):
            raise ValueError("ConvexTable.h or grad is not finite on the extent")
        inside = H < 0
        if not inside.any():
            raise ValueError("ConvexTable.h: no point of the extent is inside the table (h < 0)")
        edge = np.concatenate([H[0], H[-1], H[:, 0], H[:, -1]])
        if np.any(edge <= 0):
            raise ValueError("ConvexTable.extent must contain the table: h <= 0 on the extent's edge")
        # gradient against central differences of h
        step = 1e-6 * max(xmax - xmin, ymax - ymin)
        fdx = (self._h(X + step, Y) - self._h(X - step, Y)) / (2 * step)
        fdy = (self._h(X, Y + step) - self._h(X, Y - step)) / (2 * step)
        scale = np.max(np.hypot(gx, gy)) + 1e-300
        if np.max(np.hypot(fdx - gx, fdy - gy)) > 1e-4 * scale:
            raise ValueError("ConvexTable.grad does not match the derivative of ConvexTable.h")
        gnorm = np.hypot(gx, gy)[inside | (H <= 0)]
        if gnorm.max() > self.grad_bound * (1 + 1e-9):
            raise ValueError(f"ConvexTable.grad_bound={self.grad_bound} is below |grad h| = {gnorm.max():.6g} found on the table")
        # Lipschitz constant of the gradient between grid neighbours inside the table
        hx = (xmax - xmin) / (grid - 1)
        hy = (ymax - ymin) / (grid - 1)
        both_x = inside[:, 1:] & inside[:, :-1]
        both_y = inside[1:, :] & inside[:-1, :]
        lip_x = np.hypot(np.diff(gx, axis=1), np.diff(gy, axis=1))[both_x] / hx
        lip_y = np.hypot(np.diff(gx, axis=0), np.diff(gy, axis=0))[both_y] / hy
        lip = max(lip_x.max(initial=0.0), lip_y.max(initial=0.0))
        if lip > self.hessian_bound * (1 + 1e-6):
            raise ValueError(f"ConvexTable.hessian_bound={self.hessian_bound} is below the gradient's Lipschitz constant {lip:.6g} found on the table")
        # convexity of the region: midpoints of inside points are inside
        pts = np.stack([X[inside], Y[inside]], axis=1)
        rng = np.random.default_rng(0)
        i, j = rng.integers(0, len(pts), size=(2, 2000))
        mid = 0.5 * (pts[i] + pts[j])
        if np.any(np.asarray(self._h(mid[:, 0], mid[:, 1])) > 1e-12 * scale * self.size):
            raise ValueError("ConvexTable: the region {h < 0} is not convex")
        estimate = float(np.max(-H[inside]) / self.grad_bound)
        if inradius is None:
            self.inradius = estimate
        else:
            self.inradius = _length("ConvexTable", "inradius", inradius)

    def boundary(self, n: int = 256) -> np.ndarray:
        # march along rays from the deepest grid point (convex: each ray crosses the wall once)
        xmin, xmax, ymin, ymax = self.extent
        X, Y = np.meshgrid(np.linspace(xmin, xmax, 65), np.linspace(ymin, ymax, 65))
        H = np.asarray(self._h(X, Y))
        k = np.argmin(H)
        cx, cy = X.flat[k], Y.flat[k]
        ang = np.linspace(0.0, 2 * np.pi, n)
        lo = np.zeros(n)
        hi = np.full(n, 2 * max(xmax - xmin, ymax - ymin))
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            inside = np.asarray(self._h(cx + mid * np.cos(ang), cy + mid * np.sin(ang))) < 0
            lo = np.where(inside, mid, lo)
            hi = np.where(inside, hi, mid)
        return np.stack([cx + lo * np.cos(ang), cy + lo * np.sin(ang)], axis=1)


PROTOCOL = ("h", "grad", "grad_bound", "hessian_bound", "inradius", "extent")


class ProtocolTable(Table):
    """A user object that follows the table protocol (module docstring), seen as a Table: its
    methods are delegated, its numbers checked, and the length scale derived from its extent."""

    def __init__(self, obj):
        missing = [k for k in PROTOCOL if not hasattr(obj, k)]
        if missing:
            raise TypeError(f"table: {type(obj).__name__} lacks {missing} of the table protocol {PROTOCOL}")
        self._obj = obj
        self.name = getattr(obj, "name", type(obj).__name__)
        self.grad_bound = _length("table", "grad_bound", obj.grad_bound)
        self.hessian_bound = _length("table", "hessian_bound", obj.hessian_bound, allow_zero=True)
        self.inradius = _length("table", "inradius", obj.inradius)
        try:
            ext = tuple(float(v) for v in obj.extent)
        except (TypeError, ValueError):
            raise TypeError("table.extent must be (xmin, xmax, ymin, ymax)") from None
        if len(ext) != 4 or not all(map(math.isfinite, ext)) or ext[0] >= ext[1] or ext[2] >= ext[3]:
            raise ValueError(f"table.extent must be finite (xmin, xmax, ymin, ymax) with min < max, got {obj.extent!r}")
        self.extent = ext
        if callable(getattr(obj, "hessian", None)):
            self.hessian = obj.hessian
            self.third_derivative_bound = _length("table", "third_derivative_bound",
                                                  getattr(obj, "third_derivative_bound", 0.0), allow_zero=True)
            self.hessian_jump = _length("table", "hessian_jump", getattr(obj, "hessian_jump", 0.0), allow_zero=True)

    def _fields(self):
        return {"obj": self._obj}

    def h(self, x, y):
        return self._obj.h(x, y)

    def grad(self, x, y):
        return self._obj.grad(x, y)

    def boundary(self, n: int = 256) -> np.ndarray:
        if hasattr(self._obj, "boundary"):
            return self._obj.boundary(n)
        return ConvexTable.boundary(self, n)

    _h = property(lambda self: self._obj.h)


def as_table(table) -> Table | None:
    """None, a Table, or any object following the table protocol (wrapped in ProtocolTable)."""
    if table is None or isinstance(table, Table):
        return table
    if isinstance(table, (dict, str, int, float)):
        raise TypeError(f"table must be a penny_env table (Ellipse, Circle, Stadium, ConvexTable), an object "
                        f"following the table protocol, or None; got {type(table).__name__}")
    return ProtocolTable(table)


def make_table(spec) -> Table | None:
    """A table from a spec: a Table, an object following the table protocol, None (open plane), or
    a dict such as {"kind": "ellipse", "a": 0.15, "b": 0.2}; kinds: ellipse, circle, stadium, none."""
    if spec is None or isinstance(spec, Table):
        return spec
    if not isinstance(spec, dict) and all(hasattr(spec, k) for k in PROTOCOL):
        return ProtocolTable(spec)
    if not isinstance(spec, dict):
        raise TypeError(f"table must be a Table, None or a dict, got {type(spec).__name__}")
    spec = dict(spec)
    kind = spec.pop("kind", None)
    kinds = {"ellipse": Ellipse, "circle": Circle, "stadium": Stadium}
    if kind in (None, "none", "plane"):
        if spec:
            raise ValueError(f"table: unknown field(s) {sorted(spec)} for kind 'none'")
        return None
    if kind not in kinds:
        raise ValueError(f"table.kind must be one of {sorted(kinds) + ['none']}, got {kind!r}")
    try:
        return kinds[kind](**spec)
    except TypeError as exc:
        raise ValueError(f"table ({kind}): {exc}") from None
