"""The per-penny event loop (physics/scalar.py) run over the pennies of a (6, N) batch, on a backend.

One event loop exists: scalar.run_interval (scalar.advance_into, resumed by
scalar.advance_through_into) for one penny in plain floats, writing into fixed-capacity buffers. Here
it runs over a batch through batch_loops.advance_batch, built by the backends (penny_env/backends/):
compiled and in parallel over the pennies (backend "numba") or as plain Python (backend "python": the
readable reference, for debugging and tests). Both give bitwise the same results (tests/backends/test_compiled.py)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..physics.scalar import PINNED
from .batch import CompiledBatch, flat_log
from .choice import choose_backend

# rounds of a first-impact search resumed after its step budget (settings.max_search_steps) is spent
FIRST_IMPACT_ROUNDS = 64


@dataclass
class EventLog:
    """Impacts of a batch over one interval, sorted by penny then time.

    env: penny index; time: time since the interval start; end: +1 front / -1 back;
    state: (k, 6) states right after each impact; rest_env / rest_time / rest_pinned: pennies brought
    to rest (and held by the controls).
    """

    env: np.ndarray
    time: np.ndarray
    end: np.ndarray
    state: np.ndarray
    rest_env: np.ndarray
    rest_time: np.ndarray
    rest_pinned: np.ndarray

    @staticmethod
    def empty() -> "EventLog":
        return EventLog(np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int8), np.zeros((0, 6)),
                        np.zeros(0, np.int64), np.zeros(0), np.zeros(0, bool))

    def counts(self, n: int) -> np.ndarray:
        return np.bincount(self.env, minlength=n)


def _columns(S, acc1, acc2, dt):
    S = np.array(S, dtype=float)
    n = S.shape[1]
    acc1 = np.broadcast_to(np.asarray(acc1, dtype=float), (n,))
    acc2 = np.broadcast_to(np.asarray(acc2, dtype=float), (n,))
    dt = np.broadcast_to(np.asarray(dt, dtype=float), (n,))
    return S, n, acc1, acc2, dt


def advance_pennies(S, acc1, acc2, dt, params, table, law, settings, stop_after=None, backend="python"):
    """Advance (6, N) states by dt (scalar or (N,)) with constant angular accelerations, walls included.

    Returns (new_states, log, elapsed): elapsed equals dt except for pennies stopped early by
    stop_after (a per-call impact count at which a penny stops right after its impact). backend
    "python" runs the plain-Python loop penny by penny; "numba" or "auto" the compiled batch (the same
    functions, backends/builder.py)."""
    S, n, acc1, acc2, dts = _columns(S, acc1, acc2, dt)
    target = "python"
    if backend != "python" and choose_backend(backend, table, python="python") == "numba":
        target = "cpu"
    out, buf, elapsed = CompiledBatch(params, table, law, settings, target=target).run_intervals(
        S, acc1, acc2, dts, 0 if stop_after is None else int(stop_after))
    log = flat_log(buf)
    if log is None:
        return out, EventLog.empty(), elapsed
    env, t, end, post, rest = log
    r = rest != 0
    return out, EventLog(env, t, end, post, env[r], t[r], rest[r] == PINNED), elapsed


def first_impacts(S, acc1, acc2, horizon, params, table, settings, backend="python"):
    """(t_hit (N,), end (N,) int8) of the first impact within horizon ((N,) array) for each column of
    S: scalar.first_impact_resumed (inf and 0 where none is found)."""
    from ..physics.laws import ImpactLaw
    S, n, acc1, acc2, horizon = _columns(S, acc1, acc2, horizon)
    law = ImpactLaw("elastic", 1.0)  # the search does not depend on the law
    target = "cpu" if choose_backend(backend, table, python="python") == "numba" else "python"
    return CompiledBatch(params, table, law, settings, target=target).first_impacts(S, acc1, acc2, horizon,
                                                                                   FIRST_IMPACT_ROUNDS)
