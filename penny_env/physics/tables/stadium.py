"""The Bunimovich stadium."""
from __future__ import annotations

import math

import numpy as np

from .base import Table, length as _length, add_table


def stadium_terms(c, x, y):
    """(h, hx, hy); c = (length/2, radius, radius^2, 2 radius, 1/radius)."""
    half, r, r2, two_r = c[0], c[1], c[2], c[3]
    dx = x - min(max(x, -half), half)
    return (dx * dx + y * y - r2) / two_r, dx / r, y / r


def stadium_hess(c, x, y):
    half, inv = c[0], c[4]
    return (inv if x - min(max(x, -half), half) != 0.0 else 0.0), 0.0, inv


def stadium_ray(c, cs, sn):
    """Distance from the centre to the wall along the unit direction (cs, sn) (Stadium.wall_distance's
    arithmetic, for one direction): a straight side where that one is hit, else a cap."""
    half, r = c[0], c[1]
    side = r / abs(sn) if sn != 0.0 else math.inf
    if side * abs(cs) <= half:
        return side
    return abs(cs) * half + math.sqrt(r * r - half * half * sn * sn)


class Stadium(Table):
    """Bunimovich stadium: two half-discs of the given radius joined by straight sides of the
    given length, parallel to the x axis and centred on the origin (length 0 is a circle).

    h = (d^2 - radius^2) / (2 radius), d the distance to the segment [-length/2, length/2] x {0};
    h is C^1 with a Lipschitz gradient (the curvature jumps where the sides meet the caps)."""

    name = "stadium"
    terms = staticmethod(stadium_terms)
    hess = staticmethod(stadium_hess)
    ray = staticmethod(stadium_ray)
    third_derivative_bound = 0.0

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

    def constants(self):
        r = self.radius
        return (self._half, r, r ** 2, 2.0 * r, 1.0 / r)

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

    @property
    def hessian_jump(self) -> float:
        return 1.0 / self.radius  # the x-curvature switches on where a side meets a cap

    def hessian(self, x, y):
        dx, _ = self._offset(x, y)
        inv = 1.0 / self.radius
        return (dx != 0.0) * inv, 0.0 * x, inv + 0.0 * y

    def spawn_axes(self):
        return self._half + self.radius, self.radius

    def wall_distance(self, c, s):
        r, half = self.radius, self._half
        with np.errstate(divide="ignore"):
            side = r / np.abs(s)
        cap = np.abs(c) * half + np.sqrt(r * r - half * half * s * s)
        return np.where(side * np.abs(c) <= half, side, cap)

    def boundary(self, n: int = 256) -> np.ndarray:
        k = max(n // 2, 2)
        t = np.linspace(-np.pi / 2, np.pi / 2, k)
        right = np.stack([self._half + self.radius * np.cos(t), self.radius * np.sin(t)], axis=1)
        left = np.stack([-self._half - self.radius * np.cos(t), -self.radius * np.sin(t)], axis=1)
        return np.concatenate([right, left, right[:1]], axis=0)


add_table("stadium", Stadium)
