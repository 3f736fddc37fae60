"""The math namespace ``xp`` of the CPU copies (backends/builder.py, target "cpu"): kernels.SCALAR's
functions and constants, for numba. A real module (not one built at run time) so that numba's on-disk
cache recognises it from one process to the next. Imported only where numba is installed."""
import math

import numpy as np
from numba import njit

scalar = True
sin, cos, sqrt, inf, pi = math.sin, math.cos, math.sqrt, math.inf, math.pi
abs, minimum, maximum = abs, min, max

# 64-bit integers of the counter-based draws (step/draws.py): numpy's uint64, whose arithmetic wraps
u64, to_float = np.uint64, float
ONE = np.uint64(1)
GOLDEN, M1, M2 = np.uint64(0x9E3779B97F4A7C15), np.uint64(0xBF58476D1CE4E5B9), np.uint64(0x94D049BB133111EB)
MASK = np.uint64((1 << 64) - 1)
U11, U27, U30, U31 = np.uint64(11), np.uint64(27), np.uint64(30), np.uint64(31)


def where(cond, a, b):
    return a if cond else b


try:
    where = njit(cache=True)(where)
except RuntimeError:  # no writable cache location (a read-only install without a writable home)
    where = njit(where)
