"""A table shape defined outside the package (docs/extending.md shows this file; tests/repo/test_doc_blocks.py runs
it and rolls a penny on it): the disc, a circle written out as the table protocol asks."""
from penny_env import register_table
from penny_env.physics.tables.base import Table, length


def my_terms(c, x, y):          # (h, dh/dx, dh/dy); plain math on floats: numba compiles it
    r2, inv = c[0], c[1]        # c = the table's constants() (up to 5 floats)
    return (x * x + y * y - r2) * 0.5 * inv, x * inv, y * inv


def my_hess(c, x, y):           # (hxx, hxy, hyy)
    return c[1], 0.0, c[1]


class Disc(Table):
    name = "disc"
    terms = staticmethod(my_terms)
    hess = staticmethod(my_hess)
    third_derivative_bound = 0.0
    hessian_jump = 0.0

    def __init__(self, r):
        self.r = length("Disc", "r", r)              # TypeError / ValueError naming the field
        self.grad_bound, self.hessian_bound = 1.0, 1.0 / self.r
        self.inradius, self.extent = self.r, (-self.r, self.r, -self.r, self.r)

    def _fields(self):                  # optional: the numbers that define the table (repr, equality, hash);
        return {"r": self.r}            # by default every public attribute, so instances never compare equal wrongly

    def constants(self):                # what terms/hess receive as c
        return (self.r * self.r, 1.0 / self.r)

    def h(self, x, y):                  # vectorised (numpy) versions: checks, rendering, dense output
        return my_terms(self.constants(), x, y)[0]

    def grad(self, x, y):
        return my_terms(self.constants(), x, y)[1:]

    def hessian(self, x, y):            # optional: enables the third-order certificate
        import numpy as np
        hxx, hxy, hyy = my_hess(self.constants(), x, y)
        return hxx + 0.0 * np.asarray(x), 0.0 * np.asarray(x), hyy + 0.0 * np.asarray(y)

    def spawn_axes(self):               # an ellipse inside the table holding its inscribed disk
        return self.r, self.r

    def wall_distance(self, c, s):      # origin to wall along unit (c, s), vectorised (targets on the wall)
        return self.r + 0.0 * c


register_table("disc", Disc)
