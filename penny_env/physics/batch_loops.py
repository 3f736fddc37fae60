"""The per-penny work of a batch and its loops over pennies, plain Python: one call of the event loop's
driver (scalar.run_interval, resumed after the event cap) or of the first-impact search per penny. The
backends (penny_env/backends/) compile the loops for the CPU (numba, parallel over pennies) and CUDA (one
thread per penny); backends/batch.py's CompiledBatch runs them on (6, N) batches."""
from __future__ import annotations

import math

from .scalar import NO_ARC, first_impact_resumed, run_interval

prange = range  # numba.prange in the CPU copies; one penny per thread on CUDA


def angle_trig_into(s, trig, i):
    """cos theta, sin theta, cos phi, sin phi of state s into column i of trig (4, N) (nothing when
    trig has no columns)."""
    if trig.shape[1] > i:
        trig[0, i] = math.cos(s[2])
        trig[1, i] = math.sin(s[2])
        trig[2, i] = math.cos(s[3])
        trig[3, i] = math.sin(s[3])


def advance_penny(i, S, acc1, acc2, dt, m, plane, stop_after, out, trig, elapsed, buf):
    """Penny i of the batch over its interval dt[i] (scalar.run_interval, resumed after the event cap),
    stopping after stop_after impacts (0: none): new state into column i of out (and its angles' cos
    and sin into trig), the time run into elapsed[i], the impacts into row i of buf."""
    s = (S[0, i], S[1, i], S[2, i], S[3, i], S[4, i], S[5, i])
    s1, el = run_interval(s, math.cos(s[3]), math.sin(s[3]), acc1[i], acc2[i], dt[i], m, plane, True,
                          stop_after, buf, i, NO_ARC)
    for r in range(6):
        out[r, i] = s1[r]
    elapsed[i] = el
    angle_trig_into(s1, trig, i)


def advance_batch(S, acc1, acc2, dt, m, plane, stop_after, out, trig, elapsed, buf):
    for i in prange(S.shape[1]):
        advance_penny(i, S, acc1, acc2, dt, m, plane, stop_after, out, trig, elapsed, buf)


def first_impact_penny(i, S, acc1, acc2, horizon, m, rounds, t_out, end_out):
    """(t_hit, end) of scalar.first_impact_resumed for penny i into t_out[i], end_out[i]."""
    s = (S[0, i], S[1, i], S[2, i], S[3, i], S[4, i], S[5, i])
    t_out[i], end_out[i] = first_impact_resumed(s, acc1[i], acc2[i], horizon[i], m, rounds)


def first_impact_batch(S, acc1, acc2, horizon, m, rounds, t_out, end_out):
    for i in prange(S.shape[1]):
        first_impact_penny(i, S, acc1, acc2, horizon, m, rounds, t_out, end_out)
