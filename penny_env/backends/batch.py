"""Batches of pennies on a backend: :class:`CompiledBatch` runs the per-penny event loop over one interval
for (6, N) batches (physics/batch_loops.py, built by backends/physics.py) on the CPU (numba, parallel over
pennies), on CUDA (one GPU thread per penny) or as plain Python (the readable reference)."""
from __future__ import annotations

import numpy as np

from .interrupts import load_numba
from .physics import physics_build

# capacity of the per-penny impact buffer of one batch call; a penny with more impacts in one
# interval (accumulations) is rerun alone to collect them all
IMPACT_CAPACITY = 8


class CompiledBatch:
    """The per-penny event loop over one interval for (6, N) batches, on one target (backends/builder.py):
    "cpu" (numba, parallel over pennies, the default), "cuda" (one GPU thread per penny) or "python" (the
    plain functions: the readable reference). :meth:`states_and_impacts`, :meth:`run_intervals`,
    :meth:`first_impacts`.

    ``CompiledBatch(params, table, law, settings, target="cpu")``; table None is the open plane. Raises
    ImportError without numba and ValueError for a table that does not compile (see :func:`compiles`;
    the "python" target runs any table)."""

    CAPACITY = IMPACT_CAPACITY

    def __init__(self, params, table, law, settings, target="cpu"):
        from ..physics.scalar import scalar_model
        from .builder import check_target
        from .choice import compiles

        self.target = check_target(target)
        if target != "python":
            load_numba()
        if target != "python" and not compiles(table):
            raise ValueError(f"table: only registered tables with compiled formulas compile, got {type(table).__name__}")
        self.model = scalar_model(params, table, law, settings)
        build = physics_build(target, self.model.kind, law=self.model.law if target != "python" else -1)
        from .checks import check_table_as_run
        check_table_as_run(table, build)  # (the formulas as the loops run them)
        self._fns = build.functions
        self.law = law
        self.R = params.R
        self.plane = table is None
        self.table = table
        if target == "cpu":
            self._warm_up()

    def _warm_up(self):
        """Compile (or load from numba's cache) every path now rather than in the middle of a run:
        a batch of one penny at rest, and the parallel loop (SERIAL_BELOW pennies)."""
        from .cache import announce_compile
        from .threads import SERIAL_BELOW, serial_now
        batch = self._fns["advance_batch"]
        announce_compile("compiled batch", "open plane" if self.plane else type(self.table).__name__, self.model.kind,
                         batch.__wrapped__)
        # both loops: one penny runs on the calling thread, SERIAL_BELOW in parallel (not in a forked child)
        for n in (1,) if serial_now() else (1, SERIAL_BELOW):
            S = np.zeros((6, n))
            S[4] = 1.0
            zero = np.zeros(n)
            self.states_and_impacts(S, zero, zero, 1e-9)

    def _call(self, name, *args, results=()):
        """Run loop ``name`` on numpy arguments: as they are on the CPU, as memoryviews in plain Python
        (indexing them gives Python floats, as the plain loop expects); on CUDA copied to the GPU, and the
        arguments at the indices ``results`` (arrays or records of arrays) copied back."""
        if self.target == "cpu":
            return self._fns[name](*args)
        if self.target == "python":
            return self._fns[name](*map_arrays(args, memoryview))
        from numba import cuda
        dev = map_arrays(args, cuda.to_device)
        self._fns[name](*dev)
        for j in results:
            for host, d in zip(flat_arrays((args[j],)), flat_arrays((dev[j],))):
                d.copy_to_host(host)

    def first_impacts(self, S, acc1, acc2, horizon, rounds=64):
        """(t_hit (N,), end (N,) int8) of scalar.first_impact_resumed for each penny, in parallel."""
        n = S.shape[1]
        t = np.empty(n)
        end = np.empty(n, dtype=np.int64)
        self._call("first_impact_batch", np.ascontiguousarray(S, dtype=np.float64),
                   np.ascontiguousarray(acc1, dtype=np.float64), np.ascontiguousarray(acc2, dtype=np.float64),
                   np.ascontiguousarray(horizon, dtype=np.float64), self.model, int(rounds), t, end, results=(6, 7))
        return t, end.astype(np.int8)

    def run_intervals(self, S, acc1, acc2, dt, stop_after=0, trig_out=None):
        """(new S (6, N), buffers, elapsed (N,)) after one interval per penny (dt scalar or (N,)), stopping
        a penny right after stop_after impacts (0: never). buffers: scalar.ImpactBuffers holding every
        impact (pennies whose impacts overflowed the capacity were rerun alone with room for all: the
        returned buffers' capacity is the largest count)."""
        from ..physics.scalar import impact_buffers
        S = np.ascontiguousarray(S, dtype=np.float64)
        n = S.shape[1]
        acc1 = np.ascontiguousarray(np.broadcast_to(acc1, (n,)), dtype=np.float64)
        acc2 = np.ascontiguousarray(np.broadcast_to(acc2, (n,)), dtype=np.float64)
        dts = np.ascontiguousarray(np.broadcast_to(np.asarray(dt, dtype=np.float64), (n,)))
        out = np.empty_like(S)
        trig = np.empty((4, 0)) if trig_out is None else trig_out
        if trig.shape[1] not in (0, n) or trig.shape[0] != 4 or trig.dtype != np.float64 or not trig.flags.c_contiguous:
            raise ValueError(f"trig_out must be a C-contiguous float64 array of shape (4, {n})")
        elapsed = np.empty(n)
        buf = impact_buffers(n, self.CAPACITY, empty=True)  # (run_interval clears every row it writes)
        self._call("advance_batch", S, acc1, acc2, dts, self.model, self.plane, int(stop_after), out, trig, elapsed, buf,
                   results=(7, 8, 9, 10))
        if buf.fault.any():  # the event loop's guard stopped a penny at an impact (physics/faults.py)
            from ..physics.faults import check_faults
            check_faults(buf, self.law, self.table, out, self.R, elapsed=elapsed)
        over = np.flatnonzero(buf.count > self.CAPACITY)
        if over.size:  # more impacts than a penny's slots hold: rerun those pennies alone, with room for all
            big = impact_buffers(n, int(buf.count.max()))
            for name in ("time", "end", "post", "rest"):
                getattr(big, name)[:self.CAPACITY] = getattr(buf, name)
            big.count[:] = buf.count
            big.arc_count[:] = buf.arc_count
            for i in over:
                one = impact_buffers(1, int(buf.count[i]))
                col = np.empty((6, 1))
                self._call("advance_batch", S[:, i:i + 1].copy(), acc1[i:i + 1].copy(), acc2[i:i + 1].copy(),
                           dts[i:i + 1].copy(), self.model, self.plane, int(stop_after), col, np.empty((4, 0)),
                           np.empty(1), one, results=(10,))
                k = int(buf.count[i])
                for name in ("time", "end", "post", "rest"):
                    getattr(big, name)[:k, ..., i] = getattr(one, name)[..., 0]
            buf = big
        return out, buf, elapsed

    def states_and_impacts(self, S, acc1, acc2, dt, trig_out=None):
        """(new S (6, N), log) after one interval dt: log None when no penny hit the wall, else
        (env, time, end, post (k, 6)) sorted by penny then time. trig_out: optional (4, N) array
        that receives cos theta, sin theta, cos phi, sin phi of the new states (math.cos/sin)."""
        out, buf, _ = self.run_intervals(S, acc1, acc2, dt, 0, trig_out)
        log = flat_log(buf)
        return out, (None if log is None else log[:4])


def flat_log(buf):
    """The impacts of ImpactBuffers holding all of them, flattened and sorted by penny then time:
    (env, time, end (int8), post (k, 6), rest flag (int8)), or None when there are none."""
    counts = buf.count
    total = int(counts.sum())
    if total == 0:
        return None
    n = counts.shape[0]
    env = np.repeat(np.arange(n), counts)
    rank = np.arange(total) - np.repeat(np.cumsum(counts) - counts, counts)
    return (env, buf.time[rank, env], buf.end[rank, env].astype(np.int8), buf.post[rank, :, env],
            buf.rest[rank, env].astype(np.int8))


def map_arrays(args, f):
    """args with every numpy array, also inside tuples and NamedTuples (ImpactBuffers), replaced by f(array)."""
    def one(a):
        if isinstance(a, np.ndarray):
            return f(a)
        if isinstance(a, tuple) and any(isinstance(v, np.ndarray) for v in a):
            items = [one(v) for v in a]
            return type(a)(*items) if hasattr(a, "_fields") else tuple(items)
        return a
    return tuple(one(a) for a in args)


def flat_arrays(args):
    """The arrays of args (and of their tuples), in order (for copying results back)."""
    out = []
    for a in args:
        if isinstance(a, tuple):
            out += flat_arrays(a)
        elif not isinstance(a, (int, float, bool, np.generic)) and hasattr(a, "shape"):
            out.append(a)
    return out
