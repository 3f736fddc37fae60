"""Users' tables: :class:`ConvexTable` (a wall function given as callables) and :class:`ProtocolTable`
(any object following the table protocol, see tables/base.py). Both are checked on a grid by
:func:`check_on_grid` before any penny rolls on them: a table whose gradient, bounds or shape
contradict the grid is refused with a ValueError naming the table and the check, since the
impact search is only as certain as the bounds it is given."""
from __future__ import annotations

import math
from typing import Callable

import numpy as np

from .base import Table, length

PROTOCOL = ("h", "grad", "grad_bound", "hessian_bound", "inradius", "extent")


def _extent(owner: str, extent) -> tuple:
    try:
        ext = tuple(float(v) for v in extent)
    except (TypeError, ValueError):
        raise TypeError(f"{owner}.extent must be (xmin, xmax, ymin, ymax)") from None
    if len(ext) != 4 or not all(map(math.isfinite, ext)) or ext[0] >= ext[1] or ext[2] >= ext[3]:
        raise ValueError(f"{owner}.extent must be finite (xmin, xmax, ymin, ymax) with min < max, got {extent!r}")
    return ext


def _ray_boundary(h, extent, n: int) -> np.ndarray:
    """(n, 2) wall points along rays from the deepest point of a 65 x 65 grid (convex: one crossing a ray)."""
    xmin, xmax, ymin, ymax = extent
    X, Y = np.meshgrid(np.linspace(xmin, xmax, 65), np.linspace(ymin, ymax, 65))
    H = np.asarray(h(X, Y))
    k = np.argmin(H)
    cx, cy = X.flat[k], Y.flat[k]
    ang = np.linspace(0.0, 2 * np.pi, n)
    lo = np.zeros(n)
    hi = np.full(n, 2 * max(xmax - xmin, ymax - ymin))
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        inside = np.asarray(h(cx + mid * np.cos(ang), cy + mid * np.sin(ang))) < 0
        lo = np.where(inside, mid, lo)
        hi = np.where(inside, hi, mid)
    return np.stack([cx + lo * np.cos(ang), cy + lo * np.sin(ang)], axis=1)


def _origin_inradius(h, extent, size: float, n: int = 720) -> float:
    """A tight lower bound of the radius of the largest disk centred on the origin inside the table
    (0 when the origin is outside): the distance from the origin to the polygon of wall points of
    _ray_boundary. Those points lie inside the table (the bisection keeps its inside end), so on a
    convex table their polygon does too, and a disk inside the polygon is inside the table. The
    polygon's edges cut the wall's curve by their sagitta (about (edge length)^2 / (8 radius of
    curvature)), so the bound is tight where the grid's Lipschitz bound (-h / grad_bound at the
    deepest grid point) is not: 0.025 m for a 0.2 x 0.14 m quartic table whose inradius is 0.14 m.
    The environments' spawn ellipse is centred on the origin (Table.spawn_axes), hence this disk."""
    if not float(np.asarray(h(0.0, 0.0))) < 0:
        return 0.0
    wall = _ray_boundary(h, extent, n + 1)[:-1]  # (the first and last rays coincide)
    a, b = wall, np.roll(wall, -1, axis=0)
    ab = b - a
    cross = a[:, 0] * ab[:, 1] - a[:, 1] * ab[:, 0]  # the origin on the inner side of every edge (CCW order)
    if not np.all(cross > 0):
        return 0.0
    t = np.clip(-(a * ab).sum(1) / np.maximum((ab * ab).sum(1), 1e-300), 0.0, 1.0)
    closest = a + t[:, None] * ab
    return float(np.sqrt((closest ** 2).sum(1)).min() * (1.0 - 1e-12))


WALL_DISTANCE_CHUNK = 1024  # grid points per block of (points x wall samples) distances: 1024 x 720 x 16 B = 12 MB


def _largest_wall_distance(pts, wall) -> float:
    """The largest distance from any of the points ``pts`` (k, 2) to the nearest of the wall samples ``wall``
    (m, 2), computed over every point, in blocks of WALL_DISTANCE_CHUNK (bounded memory).

    It bounds the radius of any disk inside the table: the samples lie on the wall, so a point's distance to the
    nearest sample is at least its distance to the wall, and the centre of an inscribed disk of radius r is within
    half a grid cell of a grid point whose distance to the wall is at least r - cell / 2. Every inside point is
    taken, not the deepest few by h: h's depth is not the distance to the wall (a flat-bottomed h ties at
    thousands of points, and which of them a sort returns first depends on the CPU's sort kernel), so the verdict
    depends on neither the order of equal values nor the machine."""
    best = 0.0
    wx, wy = wall[None, :, 0], wall[None, :, 1]
    for start in range(0, len(pts), WALL_DISTANCE_CHUNK):
        block = pts[start:start + WALL_DISTANCE_CHUNK]
        dx, dy = block[:, 0, None] - wx, block[:, 1, None] - wy  # (by component: a sum over a last axis of 2 is slow)
        best = max(best, float(np.sqrt((dx * dx + dy * dy).min(axis=1).max())))
    return best


def check_on_grid(owner: str, h, grad, grad_bound: float, hessian_bound: float, extent, grid: int = 97,
                  inradius=None, hessian=None, edge_may_touch=False) -> float:
    """Check a table's callables and numbers on a grid x grid sampling of its extent; returns the
    inradius (the given one, checked, or a lower-bound estimate). ValueError names ``owner`` and the
    failed check: not vectorised or not finite, extent not containing the table, gradient not the
    derivative of h (central differences), a bound below what the grid shows, a non-convex region,
    an inradius no disk of the table reaches. edge_may_touch: the extent may touch the wall (h = 0 on
    its edge, to round-off) rather than lie strictly outside the table."""
    xmin, xmax, ymin, ymax = extent
    X, Y = np.meshgrid(np.linspace(xmin, xmax, grid), np.linspace(ymin, ymax, grid))
    try:
        with np.errstate(all="ignore"):
            H = np.asarray(h(X, Y), dtype=float)
            gx, gy = (np.asarray(g, dtype=float) for g in grad(X, Y))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{owner}: h and grad must be vectorised over numpy arrays ({exc})") from None
    if H.shape != X.shape or gx.shape != X.shape or gy.shape != X.shape:
        raise ValueError(f"{owner}.h and grad must be vectorised: same shape out as in")
    if not (np.all(np.isfinite(H)) and np.all(np.isfinite(gx)) and np.all(np.isfinite(gy))):
        raise ValueError(f"{owner}.h or grad is not finite on the extent")
    inside = H < 0
    if not inside.any():
        raise ValueError(f"{owner}.h: no point of the extent is inside the table (h < 0)")
    edge = np.concatenate([H[0], H[-1], H[:, 0], H[:, -1]])
    floor = -1e-12 * (np.max(np.abs(H)) + 1e-300) if edge_may_touch else 0.0
    if np.any(edge < floor) or (not edge_may_touch and np.any(edge == 0)):
        raise ValueError(f"{owner}.extent must contain the table: h {'<' if edge_may_touch else '<='} 0 on the extent's edge")
    # gradient against central differences of h
    step = 1e-6 * max(xmax - xmin, ymax - ymin)
    fdx = (np.asarray(h(X + step, Y)) - np.asarray(h(X - step, Y))) / (2 * step)
    fdy = (np.asarray(h(X, Y + step)) - np.asarray(h(X, Y - step))) / (2 * step)
    scale = np.max(np.hypot(gx, gy)) + 1e-300
    if np.max(np.hypot(fdx - gx, fdy - gy)) > 1e-4 * scale:
        raise ValueError(f"{owner}.grad does not match the derivative of {owner}.h")
    gnorm = np.hypot(gx, gy)[inside | (H <= 0)]
    if gnorm.max() > grad_bound * (1 + 1e-9):
        raise ValueError(f"{owner}.grad_bound={grad_bound} is below |grad h| = {gnorm.max():.6g} found on the table")
    # Lipschitz constant of the gradient between grid neighbours inside the table
    hx = (xmax - xmin) / (grid - 1)
    hy = (ymax - ymin) / (grid - 1)
    both_x = inside[:, 1:] & inside[:, :-1]
    both_y = inside[1:, :] & inside[:-1, :]
    lip_x = np.hypot(np.diff(gx, axis=1), np.diff(gy, axis=1))[both_x] / hx
    lip_y = np.hypot(np.diff(gx, axis=0), np.diff(gy, axis=0))[both_y] / hy
    lip = max(lip_x.max(initial=0.0), lip_y.max(initial=0.0))
    if lip > hessian_bound * (1 + 1e-6):
        raise ValueError(f"{owner}.hessian_bound={hessian_bound} is below the gradient's Lipschitz constant "
                         f"{lip:.6g} found on the table")
    if hessian is not None:
        hxx, hxy, hyy = (np.asarray(v, dtype=float) * np.ones_like(X) for v in hessian(X, Y))
        # spectral norm of the symmetric 2 x 2 Hessian
        norm = (np.abs(0.5 * (hxx + hyy)) + np.hypot(0.5 * (hxx - hyy), hxy))[inside]
        if not np.all(np.isfinite(norm)) or norm.max(initial=0.0) > hessian_bound * (1 + 1e-6):
            raise ValueError(f"{owner}.hessian_bound={hessian_bound} is below the norm of {owner}.hessian "
                             f"{norm.max(initial=0.0):.6g} found on the table")
    # convexity of the region: midpoints of inside points are inside
    pts = np.stack([X[inside], Y[inside]], axis=1)
    rng = np.random.default_rng(0)
    i, j = rng.integers(0, len(pts), size=(2, 2000))
    mid = 0.5 * (pts[i] + pts[j])
    size = max(abs(v) for v in extent)
    if np.any(np.asarray(h(mid[:, 0], mid[:, 1])) > 1e-12 * scale * size):
        raise ValueError(f"{owner}: the region {{h < 0}} is not convex")
    estimate = float(np.max(-H[inside]) / grad_bound)
    if inradius is None:
        return max(estimate, _origin_inradius(h, extent, size))
    reach = _largest_wall_distance(pts, _ray_boundary(h, extent, 720))
    cell = math.hypot(hx, hy)
    if inradius > reach + cell:
        raise ValueError(f"{owner}.inradius={inradius} is larger than any disk inside the table "
                         f"(at most {reach + cell:.6g} found on the grid)")
    return inradius


class ConvexTable(Table):
    """A convex table given by the user as a wall function with its gradient and bounds.

    Parameters
    ----------
    h, grad : vectorised callables of (x, y); see the table protocol (penny_env/physics/tables/base.py).
    grad_bound, hessian_bound : the bounds G and L over the table. They are what guarantees
        that no impact is missed, so give true upper bounds; they are checked on a grid and a
        bound that the grid already contradicts is refused.
    extent : (xmin, xmax, ymin, ymax), a box containing the table (h > 0 on its edge).
    inradius : radius of an inscribed disk; estimated from the grid (a lower bound) if omitted.

    Example: a rounded square ``h = (x**4 + y**4 - s**4) / (4 s**3)`` with
    ``grad = (x**3/s**3, y**3/s**3)`` (tests/physics/test_tables.py builds and checks it).
    """

    name = "custom"

    def __init__(self, h: Callable, grad: Callable, *, grad_bound: float, hessian_bound: float,
                 extent, inradius: float | None = None, name: str = "custom", grid: int = 97):
        if not callable(h):
            raise TypeError("ConvexTable.h must be callable")
        if not callable(grad):
            raise TypeError("ConvexTable.grad must be callable")
        self._h, self._grad = h, grad
        self.grad_bound = length("ConvexTable", "grad_bound", grad_bound)
        self.hessian_bound = length("ConvexTable", "hessian_bound", hessian_bound, allow_zero=True)
        self.extent = _extent("ConvexTable", extent)
        self.name = str(name)
        if inradius is not None:
            inradius = length("ConvexTable", "inradius", inradius)
        self.inradius = check_on_grid("ConvexTable", h, grad, self.grad_bound, self.hessian_bound, self.extent,
                                      grid, inradius)

    def _fields(self):
        return {"h": self._h, "grad": self._grad, "extent": self.extent}

    def h(self, x, y):
        return self._h(x, y)

    def grad(self, x, y):
        return self._grad(x, y)

    def boundary(self, n: int = 256) -> np.ndarray:
        return _ray_boundary(self._h, self.extent, n)


class ProtocolTable(Table):
    """A user object that follows the table protocol, seen as a Table: its methods are delegated,
    its numbers and callables checked on a grid as ConvexTable's are (:func:`check_on_grid`)."""

    def __init__(self, obj):
        missing = [k for k in PROTOCOL if not hasattr(obj, k)]
        if missing:
            raise TypeError(f"table: {type(obj).__name__} lacks {missing} of the table protocol {PROTOCOL}")
        self._obj = obj
        self.name = str(getattr(obj, "name", type(obj).__name__))
        owner = f"table {self.name}"
        self.grad_bound = length(owner, "grad_bound", obj.grad_bound)
        self.hessian_bound = length(owner, "hessian_bound", obj.hessian_bound, allow_zero=True)
        inradius = length(owner, "inradius", obj.inradius)
        self.extent = _extent(owner, obj.extent)
        hessian = getattr(obj, "hessian", None)
        if callable(hessian):
            self.hessian = hessian
            self.third_derivative_bound = length(owner, "third_derivative_bound",
                                                 getattr(obj, "third_derivative_bound", 0.0), allow_zero=True)
            self.hessian_jump = length(owner, "hessian_jump", getattr(obj, "hessian_jump", 0.0), allow_zero=True)
        self.inradius = check_on_grid(owner, obj.h, obj.grad, self.grad_bound, self.hessian_bound, self.extent,
                                      inradius=inradius, hessian=hessian if callable(hessian) else None,
                                      edge_may_touch=True)

    def _fields(self):
        return {"obj": self._obj}

    def h(self, x, y):
        return self._obj.h(x, y)

    def grad(self, x, y):
        return self._obj.grad(x, y)

    def spawn_axes(self):
        f = getattr(self._obj, "spawn_axes", None)
        return tuple(float(v) for v in f()) if callable(f) else super().spawn_axes()

    def boundary(self, n: int = 256) -> np.ndarray:
        if hasattr(self._obj, "boundary"):
            return self._obj.boundary(n)
        return _ray_boundary(self._obj.h, self.extent, n)
