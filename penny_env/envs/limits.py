"""Sizes an environment is built with, refused up front with the field's name.

Integer fields end up in int64 arrays and in the packed constants of the compiled step (functional.pack):
beyond INT64_MAX they failed later with an OverflowError naming no field. A vector env's arrays grow
with num_envs (and max_impacts_in_info): a num_envs the machine cannot hold used to allocate gigabytes
and die in step() with a MemoryError a minute later. :func:`check_memory` compares the estimate of
:func:`vector_env_bytes` (the env's own arrays, counted from their shapes and dtypes below; checked
against tracemalloc's measure in tests/envs/test_limits.py) with the memory this process may still allocate
(backends/memory.py: MemAvailable, ulimit -v and the cgroup's limit).
"""
from __future__ import annotations

import numpy as np

from ..backends.stepping import memory_left

INT64_MAX = int(np.iinfo(np.int64).max)


def check_int64(name: str, value) -> int:
    """value (an integer, checked by the caller) within int64, else ValueError naming the field."""
    if int(value) > INT64_MAX:
        raise ValueError(f"{name} must be <= 2**63 - 1 = {INT64_MAX} (it is stored as an int64), got {value}")
    return int(value)


def available_memory() -> int | None:
    """Bytes this process may still allocate: the least of MemAvailable, the address-space limit (ulimit -v) and
    the cgroup's memory limit (backends/memory.py), or None (unknown: nothing is refused)."""
    return memory_left()[0]


def vector_env_bytes(obs_dim: int, K: int) -> int:
    """Bytes per env a PennyVectorEnv holds at its peak (K: max_impacts_in_info), from its arrays:

    * spaces: the batched observation and action Boxes' low and high (float32) and their two bool masks;
    * state (functional.EnvState): S (6), trig (4), target, arc (2 each), time, dist float64; steps, count,
      episode int64; key uint64; pending bool; the step's reused arc counts (int64) and guard faults (int8),
      and the info's all-true mask;
    * one step's new arrays, kept by the caller: obs (obs_dim) float32; reward, kinetic energy, time,
      distance float64; terminated, truncated, done bool; limit int8; arc count and impact counts int64;
      impact times (K) float64 and ends (K) int8; the info's ten bool masks; counted twice (the previous
      step's outputs are still referenced while the next step allocates), with the actions (2 float64, the
      caller's and the checked copy);
    * the reset's arrays (not kept with two steps' outputs): obs, the info's impact slots, scalars and masks,
      the keys and episodes and the seeds' Python ints;

    tests/envs/test_limits.py checks it against tracemalloc."""
    f8, i8, u8, f4, b1 = 8, 8, 8, 4, 1
    spaces = (obs_dim + 2) * (2 * f4 + 2 * b1)
    state = (6 + 4 + 2 + 2 + 1 + 1) * f8 + 3 * i8 + u8 + b1 + (i8 + b1) + b1
    impact_slots = K * (f8 + b1)
    step = obs_dim * f4 + 4 * f8 + 3 * b1 + b1 + 2 * i8 + impact_slots + 10 * b1
    actions = 2 * 2 * f8
    reset = obs_dim * f4 + impact_slots + 116
    return spaces + state + max(2 * step + actions, reset)


def single_env_bytes(K: int) -> int:
    """Bytes a PennyEnv's impact buffers take (one row of max(16, K) slots: time, end, post state, rest)."""
    return max(16, K) * (8 + 1 + 6 * 8 + 1) + 8 + 8 + 1


def check_memory(field: str, value, need: int, what: str) -> None:
    """ValueError naming ``field`` (= value) when ``need`` bytes exceed the memory available now."""
    have = available_memory()
    if have is not None and need > have:
        raise ValueError(f"{field} = {value}: {what} needs about {_gib(need)}, more than the {_gib(have)} of memory "
                         "available to this process (the least of MemAvailable, the address-space limit of ulimit -v "
                         "and the cgroup's memory limit)")


def _gib(n: int) -> str:
    return f"{n / 2**30:.3g} GiB" if n >= 2**30 else f"{n / 2**20:.3g} MiB"
