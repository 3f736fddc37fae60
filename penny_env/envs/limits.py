"""Sizes an environment is built with, refused up front with the field's name (issue 31).

Integer fields end up in int64 arrays and in the packed constants of the compiled step (functional.pack):
beyond INT64_MAX they failed later with an OverflowError naming no field. A vector env's arrays grow
with num_envs (and max_impacts_in_info): a num_envs the machine cannot hold used to allocate gigabytes
and die in step() with a MemoryError a minute later. :func:`check_memory` compares the estimate of
:func:`vector_env_bytes` (the env's own arrays, counted from their shapes and dtypes below; checked
against tracemalloc's measure in tests/test_limits.py) with the memory available now.
"""
from __future__ import annotations

import os

import numpy as np

INT64_MAX = int(np.iinfo(np.int64).max)


def check_int64(name: str, value) -> int:
    """value (an integer, checked by the caller) within int64, else ValueError naming the field."""
    if int(value) > INT64_MAX:
        raise ValueError(f"{name} must be <= 2**63 - 1 = {INT64_MAX} (it is stored as an int64), got {value}")
    return int(value)


def available_memory() -> int | None:
    """Bytes of memory available now: MemAvailable of /proc/meminfo (Linux), else the free physical pages
    (os.sysconf), else None (unknown: nothing is refused)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def vector_env_bytes(obs_dim: int, K: int) -> int:
    """Bytes per env a PennyVectorEnv holds at its peak (K: max_impacts_in_info), from its arrays:

    * state (vector_env.reset): S (6) and trig (4), target, arc (2 each), dist, time float64; steps, count
      int64; seed keys and episodes uint64; two bool masks;
    * the step's reused buffers (_scratch): post-impact states (K, 6) float64, rest flags (K) int8, arc
      count int64, fault int8;
    * one step's new arrays, kept by the caller: obs (obs_dim) float32; reward, kinetic energy float64;
      terminated, truncated, limit 1 byte; impact counts int64, times (K) float64, ends (K) int8; the checked
      actions (2) float64; the info's copies (time, distance, arc count: float64/int64) and its 10 bool masks;
    * the reset's draws (core.sample): 8 uniforms per env in float64 with their uint64 hashes and two
      temporaries, the drawn S, target, arc, and about ten float64 temporaries of the spawn formulas;

    counted twice for the step's arrays (the previous step's outputs are still referenced while the next
    step allocates)."""
    f8, i8, u8, f4, b1 = 8, 8, 8, 4, 1
    state = (6 + 4 + 2 + 2 + 1 + 1) * f8 + 2 * i8 + 2 * u8 + 2 * b1
    scratch = K * 6 * f8 + K * b1 + i8 + b1
    step = obs_dim * f4 + 2 * f8 + 3 * b1 + i8 + K * f8 + K * b1 + 2 * f8 + 3 * f8 + 10 * b1
    reset = 8 * (f8 + 3 * u8) + (6 + 2 + 2) * f8 + 10 * f8 + obs_dim * f4 + K * (f8 + b1)
    return state + scratch + max(2 * step, step + reset)


def single_env_bytes(K: int) -> int:
    """Bytes a PennyEnv's impact buffers take (one row of max(16, K) slots: time, end, post state, rest)."""
    return max(16, K) * (8 + 1 + 6 * 8 + 1) + 8 + 8 + 1


def check_memory(field: str, value, need: int, what: str) -> None:
    """ValueError naming ``field`` (= value) when ``need`` bytes exceed the memory available now."""
    have = available_memory()
    if have is not None and need > have:
        raise ValueError(f"{field} = {value}: {what} needs about {_gib(need)}, more than the {_gib(have)} of memory "
                         "available on this machine (MemAvailable)")


def _gib(n: int) -> str:
    return f"{n / 2**30:.3g} GiB" if n >= 2**30 else f"{n / 2**20:.3g} MiB"
