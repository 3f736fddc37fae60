"""The per-penny event loop (physics/scalar.py) run over the pennies of a (6, N) batch.

One event loop exists: scalar.advance_m (resumed by scalar.advance_through_m) for one penny in plain floats. Here it runs over a batch,
either compiled and in parallel over the pennies (backend "numba", physics/compiled.py) or as
plain Python (backend "python": the readable reference, for debugging and tests). Both give bitwise
the same results (tests/test_compiled.py)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .compiled import CompiledBatch, choose_backend
from .scalar import advance_through_m, first_impact_resumed, scalar_model

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
    "python" runs scalar.advance_m penny by penny; "numba" or "auto" run the compiled batch where a
    scalar dt and no stop_after allow it (rests are then not logged)."""
    S, n, acc1, acc2, dts = _columns(S, acc1, acc2, dt)
    if backend != "python" and stop_after is None and np.ndim(dt) == 0:
        if choose_backend(backend, params, table, law, settings, python="python") == "numba":
            out, log = CompiledBatch(params, table, law, settings).states_and_impacts(S, acc1, acc2, float(dt))
            if log is None:
                return out, EventLog.empty(), dts.copy()
            return out, EventLog(*log, np.zeros(0, np.int64), np.zeros(0), np.zeros(0, bool)), dts.copy()
    if table is None:
        from .flows import flow
        return flow(S, acc1, acc2, dts, params.R), EventLog.empty(), dts.copy()
    m = scalar_model(params, table, law, settings)
    stop = 0 if stop_after is None else int(stop_after)
    out = np.empty_like(S)
    elapsed = np.zeros(n)
    rows, rest_rows = [], []
    for i in range(n):
        s, impacts, rests, el = advance_through_m(tuple(float(v) for v in S[:, i]), float(acc1[i]), float(acc2[i]),
                                                  float(dts[i]), m, stop)
        out[:, i] = s
        elapsed[i] = el
        rows += [(i, t, e, post) for t, e, post in impacts]
        rest_rows += [(i, t, p) for t, p in rests]
    if not rows:
        log = EventLog.empty()
    else:
        log = EventLog(np.array([r[0] for r in rows], dtype=np.int64), np.array([r[1] for r in rows]),
                       np.array([r[2] for r in rows], dtype=np.int8), np.array([r[3] for r in rows], dtype=float).reshape(-1, 6),
                       np.array([r[0] for r in rest_rows], dtype=np.int64), np.array([r[1] for r in rest_rows], dtype=float),
                       np.array([r[2] for r in rest_rows], dtype=bool))
    return out, log, elapsed


def first_impacts(S, acc1, acc2, horizon, params, table, settings, backend="python"):
    """(t_hit (N,), end (N,) int8) of the first impact within horizon ((N,) array) for each column of
    S: scalar.first_impact_resumed (inf and 0 where none is found)."""
    from .laws import ImpactLaw
    S, n, acc1, acc2, horizon = _columns(S, acc1, acc2, horizon)
    law = ImpactLaw("elastic", 1.0)  # the search does not depend on the law
    if choose_backend(backend, params, table, law, settings, python="python") == "numba":
        return CompiledBatch(params, table, law, settings).first_impacts(S, acc1, acc2, horizon, FIRST_IMPACT_ROUNDS)
    m = scalar_model(params, table, law, settings)
    t = np.empty(n)
    end = np.empty(n, dtype=np.int8)
    for i in range(n):
        t[i], end[i] = first_impact_resumed(tuple(float(v) for v in S[:, i]), float(acc1[i]), float(acc2[i]),
                                            float(horizon[i]), m, FIRST_IMPACT_ROUNDS)
    return t, end
