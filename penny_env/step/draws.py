"""Counter-based random draws of the episodes, per env, the same on every target.

The initial state and target of episode ``e`` of an env whose seed key is ``key`` are functions of
(key, e, draw index j): ``draw_uniform(draw_stream(key, e), j)`` is a SplitMix64 hash, so any env, on any backend
(plain Python, numba on the CPU, a CUDA thread), draws exactly the same numbers for the same seed, and an
env's draws never depend on the other envs. Draws 0 to 5 are the scene's (position, angles, speeds), 6 and
7 the task's target, 8 and on the task's redraws (reach's heading offset).

The hash is integer arithmetic modulo 2**64: the math namespace ``xp`` supplies the integer type (Python
ints masked to 64 bits in plain Python, numpy's uint64 compiled: kernels.SCALAR, numba_math, cuda_math),
so the one source gives the same bits everywhere. Seeds become keys on the host (:func:`seed_keys`).
"""
from __future__ import annotations

import numpy as np

N_DRAWS = 8          # draws 0..7: the scene's six and the task's two; task redraws start here
GOLDEN = 0x9E3779B97F4A7C15
M1 = 0xBF58476D1CE4E5B9
M2 = 0x94D049BB133111EB
MASK = (1 << 64) - 1
TO_UNIT = 1.0 / 9007199254740992.0  # 2**-53


def draw_mix(z, xp):
    """SplitMix64's finaliser of a 64-bit integer (xp's integer type)."""
    z = ((z ^ (z >> xp.U30)) * xp.M1) & xp.MASK
    z = ((z ^ (z >> xp.U27)) * xp.M2) & xp.MASK
    return z ^ (z >> xp.U31)


def draw_stream(key, episode, xp):
    """The base of episode ``episode``'s draws for the env with seed key ``key`` (both 64-bit integers)."""
    return draw_mix((xp.u64(key) + xp.GOLDEN * (xp.u64(episode) + xp.ONE)) & xp.MASK, xp)


def draw_uniform(base, j, xp):
    """Draw j (j >= 0) of the stream ``base``: a float64 uniform in [0, 1) (53 random bits)."""
    z = draw_mix((base + xp.GOLDEN * xp.u64(j + 1)) & xp.MASK, xp)
    return xp.to_float(z >> xp.U11) * TO_UNIT


def _mix_array(z):
    """draw_mix() on uint64 numpy arrays (wrapping arithmetic), for seed_keys."""
    z = (z ^ (z >> np.uint64(30))) * np.uint64(M1)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(M2)
    return z ^ (z >> np.uint64(31))


def seed_keys(seeds) -> np.ndarray:
    """uint64 keys from integer seeds in [0, 2**64) (envs.core.check_seed checks them)."""
    # the seeds as Python ints: numpy would turn a list holding 2**64 - 1 into float64 (2**64, the key of 0)
    items = seeds.tolist() if isinstance(seeds, np.ndarray) else list(seeds) if isinstance(seeds, (list, tuple, range)) \
        else [seeds]
    arr = np.array([int(s) % (1 << 64) for s in np.ravel(np.array(items, dtype=object))], dtype=np.uint64)
    with np.errstate(over="ignore"):
        return _mix_array(arr + np.uint64(GOLDEN))
