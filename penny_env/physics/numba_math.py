"""The math namespace ``xp`` of the compiled kernels (physics/compiled.py): kernels.SCALAR's
functions, for numba. A real module (not one built at run time) so that numba's on-disk cache
recognises it from one process to the next. Imported only where numba is installed."""
import math

from numba import njit

scalar = True
sin, cos, sqrt, inf = math.sin, math.cos, math.sqrt, math.inf
abs, minimum, maximum = abs, min, max


def where(cond, a, b):
    return a if cond else b


try:
    where = njit(cache=True)(where)
except RuntimeError:  # no writable cache location (a read-only install without a writable home)
    where = njit(where)
