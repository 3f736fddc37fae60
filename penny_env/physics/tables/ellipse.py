"""The elliptic table (the paper's) and the circle."""
from __future__ import annotations

import math
import warnings

import numpy as np

from .base import Table, length, add_table


def ellipse_terms(c, x, y):
    """(h, hx, hy); c = (1/a^2, 1/b^2, min(a, b)/2)."""
    ia2, ib2, hc = c[0], c[1], c[2]
    c2 = 2.0 * hc
    return (x * x * ia2 + y * y * ib2 - 1.0) * hc, c2 * x * ia2, c2 * y * ib2


def ellipse_hess(c, x, y):
    c2 = 2.0 * c[2]
    return c2 * c[0], 0.0, c2 * c[1]


def ellipse_ray(c, cs, sn):
    """Distance from the centre to the wall along the unit direction (cs, sn) (Ellipse.wall_distance's
    arithmetic, for one direction)."""
    return 1.0 / math.sqrt(cs * cs * c[0] + sn * sn * c[1])


class Ellipse(Table):
    """Elliptic table x^2/a^2 + y^2/b^2 < 1 (semi-axes a along x, b along y), the paper's table.

    h = (x^2/a^2 + y^2/b^2 - 1) * min(a, b) / 2, the paper's h scaled to metres."""

    name = "ellipse"
    terms = staticmethod(ellipse_terms)
    hess = staticmethod(ellipse_hess)
    ray = staticmethod(ellipse_ray)
    third_derivative_bound = 0.0
    hessian_jump = 0.0

    def __init__(self, a: float, b: float):
        self.a = length(type(self).__name__, "a", a)
        self.b = length(type(self).__name__, "b", b)
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

    def constants(self):
        return (self._ia2, self._ib2, self._half_c)

    def h(self, x, y):
        return (x * x * self._ia2 + y * y * self._ib2 - 1.0) * self._half_c

    def grad(self, x, y):
        c2 = 2.0 * self._half_c
        return c2 * x * self._ia2, c2 * y * self._ib2

    def hessian(self, x, y):
        c2 = 2.0 * self._half_c
        return c2 * self._ia2 + 0.0 * x, 0.0 * x, c2 * self._ib2 + 0.0 * y

    def spawn_axes(self):
        return self.a, self.b

    def wall_distance(self, c, s):
        return 1.0 / np.sqrt(c * c * self._ia2 + s * s * self._ib2)

    def boundary(self, n: int = 256) -> np.ndarray:
        t = np.linspace(0.0, 2.0 * np.pi, n)
        return np.stack([self.a * np.cos(t), self.b * np.sin(t)], axis=1)


class Circle(Ellipse):
    """Circular table x^2 + y^2 < radius^2 (the paper's circle, a = b = radius).

    ``radius`` is the name every round table uses (``Stadium(radius, length)``,
    ``RoundedRectangle(width, height, radius)``); ``r`` (``Circle(r=0.2)``, ``{"kind": "circle", "r": 0.2}``,
    ``circle.r``) is its deprecated alias and warns (DeprecationWarning)."""

    name = "circle"
    field_aliases = {"r": "radius"}  # deprecated name -> name (a scene's partial table override honours it)

    def __init__(self, radius: float | None = None, *, r: float | None = None):
        if r is not None:
            if radius is not None:
                raise ValueError("Circle: got both radius and r (r is the deprecated alias of radius): give radius only")
            warnings.warn("Circle(r=...) is deprecated: use Circle(radius=...)", DeprecationWarning, stacklevel=2)
            radius = r
        elif radius is None:
            raise TypeError("Circle.__init__() missing 1 required positional argument: 'radius'")
        radius = length("Circle", "radius", radius)
        super().__init__(radius, radius)
        self.radius = radius

    @property
    def r(self) -> float:
        """Deprecated alias of :attr:`radius`."""
        warnings.warn("Circle.r is deprecated: use Circle.radius", DeprecationWarning, stacklevel=2)
        return self.radius

    def _fields(self):
        return {"radius": self.radius}


add_table("ellipse", Ellipse)
add_table("circle", Circle)
