"""The rounded rectangle: a width x height rectangle whose corners are quarter circles of a radius."""
from __future__ import annotations

import math

import numpy as np

from .base import Table, length, add_table


def rounded_rectangle_terms(c, x, y):
    """(h, hx, hy); c = (ax, ay, radius, 2 radius, 1/radius), (ax, ay) the half-sizes of the inner
    rectangle (the corners' centres)."""
    ax, ay, r, two_r = c[0], c[1], c[2], c[3]
    dx = x - min(max(x, -ax), ax)
    dy = y - min(max(y, -ay), ay)
    return (dx * dx + dy * dy - r * r) / two_r, dx / r, dy / r


def rounded_rectangle_hess(c, x, y):
    ax, ay, inv = c[0], c[1], c[4]
    return ((inv if x - min(max(x, -ax), ax) != 0.0 else 0.0), 0.0,
            (inv if y - min(max(y, -ay), ay) != 0.0 else 0.0))


def rounded_rectangle_ray(c, cs, sn):
    """Distance from the centre to the wall along the unit direction (cs, sn) (RoundedRectangle.wall_distance's
    arithmetic, for one direction): a vertical side, a horizontal side, or a corner."""
    ax, ay, r = c[0], c[1], c[2]
    ac, as_ = abs(cs), abs(sn)
    side_x = (ax + r) / ac if ac != 0.0 else math.inf
    if side_x * as_ <= ay:
        return side_x
    side_y = (ay + r) / as_ if as_ != 0.0 else math.inf
    if side_y * ac <= ax:
        return side_y
    cross = ax * as_ - ay * ac
    return ax * ac + ay * as_ + math.sqrt(max(r * r - cross * cross, 0.0))


class RoundedRectangle(Table):
    """Rectangle |x| < width/2, |y| < height/2 with its corners rounded to quarter circles of the
    given radius (0 < radius <= min(width, height)/2; the largest radius is a stadium).

    h = (d^2 - radius^2) / (2 radius), d the distance to the inner rectangle
    [-width/2 + radius, width/2 - radius] x [-height/2 + radius, height/2 - radius]: convex and C^1,
    |grad h| = d / radius <= 1 on the table (1 on the wall), Hessian diag([dx != 0], [dy != 0]) / radius,
    bounded by 1/radius, with jumps of at most 1/radius across the lines |x| = width/2 - radius and
    |y| = height/2 - radius (where the straight sides meet the corners); h is piecewise quadratic,
    so its third derivative is 0 where it exists."""

    name = "rounded_rectangle"
    terms = staticmethod(rounded_rectangle_terms)
    hess = staticmethod(rounded_rectangle_hess)
    ray = staticmethod(rounded_rectangle_ray)
    third_derivative_bound = 0.0

    def __init__(self, width: float, height: float, radius: float):
        o = "RoundedRectangle"
        self.width = length(o, "width", width)
        self.height = length(o, "height", height)
        self.radius = length(o, "radius", radius)
        if self.radius > 0.5 * min(self.width, self.height):
            raise ValueError(f"{o}.radius must be <= min(width, height) / 2 = {0.5 * min(self.width, self.height)!r}, "
                             f"got {self.radius!r}")
        self._ax = max(0.5 * self.width - self.radius, 0.0)
        self._ay = max(0.5 * self.height - self.radius, 0.0)
        self.grad_bound = 1.0
        self.hessian_bound = 1.0 / self.radius
        self.hessian_jump = 1.0 / self.radius
        self.inradius = 0.5 * min(self.width, self.height)
        self.extent = (-0.5 * self.width, 0.5 * self.width, -0.5 * self.height, 0.5 * self.height)

    def _fields(self):
        return {"width": self.width, "height": self.height, "radius": self.radius}

    def constants(self):
        r = self.radius
        return (self._ax, self._ay, r, 2.0 * r, 1.0 / r)

    def _offset(self, x, y):
        # vector from the nearest point of the inner rectangle
        if isinstance(x, float) and isinstance(y, float):
            return x - min(max(x, -self._ax), self._ax), y - min(max(y, -self._ay), self._ay)
        return x - np.clip(x, -self._ax, self._ax), y - np.clip(y, -self._ay, self._ay)

    def h(self, x, y):
        dx, dy = self._offset(x, y)
        return (dx * dx + dy * dy - self.radius * self.radius) / (2.0 * self.radius)

    def grad(self, x, y):
        dx, dy = self._offset(x, y)
        return dx / self.radius, dy / self.radius

    def hessian(self, x, y):
        dx, dy = self._offset(x, y)
        inv = 1.0 / self.radius
        return (dx != 0.0) * inv + 0.0 * x, 0.0 * x, (dy != 0.0) * inv + 0.0 * y

    def spawn_axes(self):
        # the inscribed ellipse of the rectangle lies in the stadium of radius min(w, h)/2, which
        # lies in every rounded rectangle of the same width and height
        return 0.5 * self.width, 0.5 * self.height

    def wall_distance(self, c, s):
        ac, as_ = np.abs(np.asarray(c, dtype=float)), np.abs(np.asarray(s, dtype=float))
        ax, ay, r = self._ax, self._ay, self.radius
        with np.errstate(divide="ignore", invalid="ignore"):
            side_x = (ax + r) / ac   # hits the side x = width/2
            side_y = (ay + r) / as_  # hits the side y = height/2
            cross = ax * as_ - ay * ac
            corner = ax * ac + ay * as_ + np.sqrt(np.maximum(r * r - cross * cross, 0.0))
        return np.where(side_x * as_ <= ay, side_x, np.where(side_y * ac <= ax, side_y, corner))

    def boundary(self, n: int = 256) -> np.ndarray:
        k = max(n // 4, 2)
        pts = []
        for cx, cy, a0 in ((self._ax, self._ay, 0.0), (-self._ax, self._ay, 0.5 * np.pi),
                           (-self._ax, -self._ay, np.pi), (self._ax, -self._ay, 1.5 * np.pi)):
            t = np.linspace(a0, a0 + 0.5 * np.pi, k)
            pts.append(np.stack([cx + self.radius * np.cos(t), cy + self.radius * np.sin(t)], axis=1))
        pts.append(pts[0][:1])
        return np.concatenate(pts, axis=0)


add_table("rounded_rectangle", RoundedRectangle)
