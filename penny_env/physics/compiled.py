"""Compiled batches (optional, numba): physics/scalar.py's own functions, compiled, run over the
pennies of a batch in parallel.

Nothing here restates the physics. :func:`compiled_functions` takes the functions of kernels.py,
flow.py and scalar.py as they are and compiles copies of them with numba, in which the math
namespace ``SCALAR`` is physics/numba_math.py (the same ``math`` functions, for numba). The only
new code is the loop over pennies (``_advance_batch``, ``_flow_batch``) and the unpacking of their
impacts into arrays. A penny therefore takes the same operations as in the plain-Python loop
(single environment) and in the numpy batch (physics.advance); tests/test_compiled.py checks that
the three agree.

numba is an optional dependency (``pip install "penny_env[fast]"``, included in ``[all]``); without
it :func:`available` is False and the environments use the numpy batch. Only the built-in tables
(Ellipse, Circle, Stadium) compile; other tables use the numpy batch. The first use in a fresh
install compiles for some seconds and numba caches the machine code on disk (``cache=True``).
"""
from __future__ import annotations

import builtins
import importlib
import importlib.util
import math
import types
from pathlib import Path

import numpy as np

# capacity of the per-penny impact buffer of one batch call; a penny with more impacts in one
# interval (accumulations) is rerun alone to collect them all
IMPACT_CAPACITY = 8

_COMPILED = None


def available() -> bool:
    """numba is installed, so compiled batches can run (numba itself is imported at first use)."""
    return importlib.util.find_spec("numba") is not None


def choose_backend(backend, params, table, law, settings, table_field="table") -> str:
    """'numba' or 'numpy' for ``backend`` in 'auto', 'numba', 'numpy': 'auto' takes numba where it is
    installed and the table compiles (the built-in tables and the open plane, table None); an
    explicit 'numba' that cannot run raises ValueError naming the cause."""
    from .scalar import OTHER, scalar_model

    if backend not in ("auto", "numpy", "numba"):
        raise ValueError(f"backend must be 'auto', 'numpy' or 'numba', got {backend!r}")
    compiles = table is None or scalar_model(params, table, law, settings).kind != OTHER
    if backend == "numba":
        if not available():
            raise ValueError("backend='numba' needs numba: pip install \"penny_env[fast]\"")
        if not compiles:
            raise ValueError(f"backend='numba': {table_field} {type(table).__name__} does not compile "
                             "(only ellipse, circle, stadium and the open plane do); use backend='numpy'")
    if backend == "auto":
        return "numba" if available() and compiles else "numpy"
    return backend


def _other_table(m, x, y):
    """Stands in for scalar.other_terms / other_hess, which call Python objects: compiled models
    only ever have the built-in kinds (CompiledBatch refuses other tables)."""
    return np.nan, np.nan, np.nan


def drop_stale_cache(folder, modules) -> None:
    """numba checks a cached function against its own file only, while these functions also
    freeze constants and functions of other modules (quadrature rules, table kinds, the physics
    called by the environment's kernel): drop the cached machine code in ``folder`` when any of
    ``modules`` changed since it was written."""
    import hashlib

    folder = Path(folder)
    digest = hashlib.sha256(b"".join(Path(m.__file__).read_bytes() for m in modules)).hexdigest()
    stamp = folder / "penny_env_numba.stamp"
    try:
        if stamp.exists() and stamp.read_text() == digest:
            return
        for f in list(folder.glob("*.nbi")) + list(folder.glob("*.nbc")):
            f.unlink(missing_ok=True)
        folder.mkdir(exist_ok=True)
        stamp.write_text(digest)
    except OSError:  # read-only install: numba caches elsewhere (or not at all)
        pass


def physics_modules() -> tuple:
    """The modules whose functions compiled code copies (see :func:`compiled_functions`)."""
    from . import kernels, numba_math, scalar
    return (kernels, importlib.import_module(".flow", __package__), scalar, numba_math, importlib.import_module(__name__))


def jit_copy(f, namespace, jit):
    """``jit`` of a copy of function f whose globals are ``namespace`` (where the math namespaces
    are physics/numba_math.py); default arguments that are modules (``xp``) become numba_math too."""
    from . import numba_math

    defaults = tuple(numba_math if isinstance(d, types.ModuleType) else d for d in (f.__defaults__ or ()))
    copy = types.FunctionType(f.__code__, namespace, f.__name__, defaults, f.__closure__)
    copy.__module__, copy.__qualname__ = f.__module__, f.__qualname__
    return jit(copy)


def compiled_functions() -> dict:
    """name -> compiled function, for kernels.py, flow.phase_sweep and scalar.py (compiled once)."""
    global _COMPILED
    if _COMPILED is not None:
        return _COMPILED
    try:
        import numba
    except ImportError:
        raise ImportError('the compiled backend needs numba: pip install "penny_env[fast]"') from None
    from . import kernels, numba_math, scalar
    flow = importlib.import_module(".flow", __package__)  # the module (the package exports the function flow)
    drop_stale_cache(Path(__file__).with_name("__pycache__"), physics_modules())

    jit = numba.njit(cache=True)
    namespace = {"__builtins__": builtins}
    for module in (kernels, flow, scalar):
        namespace.update({k: v for k, v in vars(module).items() if not k.startswith("__")})
    namespace["SCALAR"] = namespace["ARRAY"] = numba_math
    # the quadrature rules as 2-D arrays: the same numbers, which compiled code indexes faster than
    # a tuple of tuples
    for name in ("RULE_NODES", "RULE_WEIGHTS"):
        namespace[name] = np.array(getattr(flow, name))
    sources = [f for module in (kernels, scalar) for f in vars(module).values()
               if isinstance(f, types.FunctionType) and f.__module__ == module.__name__]
    sources.append(flow.phase_sweep)
    for f in sources:
        namespace[f.__name__] = jit_copy(f, namespace, jit)
    namespace["other_terms"] = namespace["other_hess"] = jit(_other_table)
    fns = {f.__name__: namespace[f.__name__] for f in sources}
    # the loops over pennies, compiled as copies too: module-level functions whose callees are
    # globals of the namespace (closures over dispatchers would miss numba's cache every process)
    namespace["prange"] = numba.prange
    namespace["_angle_trig"] = jit_copy(_angle_trig, namespace, jit)
    parallel = numba.njit(parallel=True, cache=True)
    for f in (_advance_batch, _flow_batch):
        fns[f.__name__] = jit_copy(f, namespace, parallel)
    _COMPILED = fns
    return fns


# -- the loops over the pennies of a batch (compiled by compiled_functions, never run as Python) --
def _angle_trig(s, trig, i):
    """cos theta, sin theta, cos phi, sin phi of state s into column i of trig (4, N)."""
    if trig.shape[1] > i:
        trig[0, i] = math.cos(s[2])
        trig[1, i] = math.sin(s[2])
        trig[2, i] = math.cos(s[3])
        trig[3, i] = math.sin(s[3])


def _advance_batch(S, acc1, acc2, dt, m, out, trig, counts, times, ends, posts):
    cap = times.shape[1]
    for i in prange(S.shape[1]):  # noqa: F821  (numba.prange, in the compiled copy's namespace)
        s = (S[0, i], S[1, i], S[2, i], S[3, i], S[4, i], S[5, i])
        a1, a2 = acc1[i], acc2[i]
        k = 0
        if certified_free1(s, a1, a2, dt, m):  # noqa: F821
            s1 = flow1(s, a1, a2, dt, m.R)  # noqa: F821
        else:
            s1, impacts, rests, _ = advance_through_m(s, a1, a2, dt, m)  # noqa: F821
            k = len(impacts)
            for j in range(min(k, cap)):
                times[i, j] = impacts[j][0]
                ends[i, j] = impacts[j][1]
                post = impacts[j][2]
                for r in range(6):
                    posts[i, j, r] = post[r]
        counts[i] = k
        for r in range(6):
            out[r, i] = s1[r]
        _angle_trig(s1, trig, i)


def _flow_batch(S, acc1, acc2, dt, R, out, trig):
    for i in prange(S.shape[1]):  # noqa: F821
        s1 = flow1((S[0, i], S[1, i], S[2, i], S[3, i], S[4, i], S[5, i]), acc1[i], acc2[i], dt, R)  # noqa: F821
        for r in range(6):
            out[r, i] = s1[r]
        _angle_trig(s1, trig, i)


class CompiledBatch:
    """advance() over one control interval for (6, N) batches, compiled (see the module docstring).

    ``CompiledBatch(params, table, law, settings)``; table None is the open plane. Raises ImportError
    without numba and ValueError for a table that does not compile (not Ellipse/Circle/Stadium)."""

    def __init__(self, params, table, law, settings):
        from .scalar import OTHER, scalar_model

        self.model = scalar_model(params, table, law, settings)
        if table is not None and self.model.kind == OTHER:
            raise ValueError(f"table: only the built-in tables compile, got {type(table).__name__}")
        self._fns = compiled_functions()
        self.R = params.R
        self.plane = table is None
        self._warm_up()

    def _warm_up(self):
        """Compile (or load from numba's cache) every path now rather than in the middle of a run:
        a batch of one penny at rest, and the one-penny rerun used when a buffer overflows."""
        S = np.zeros((6, 1))
        S[4] = 1.0
        zero = np.zeros(1)
        self.advance(S, zero, zero, 1e-9)
        if not self.plane:
            self._fns["advance_through_m"]((0.0, 0.0, 0.0, 0.0, 1.0, 0.0), 0.0, 0.0, 1e-9, self.model)

    def advance(self, S, acc1, acc2, dt, trig_out=None):
        """(new S (6, N), log): log None when no penny hit the wall, else (env, time, end, post (k, 6))
        sorted by penny then time, as physics.advance's EventLog. trig_out: optional (4, N) array
        that receives cos theta, sin theta, cos phi, sin phi of the new states (math.cos/sin)."""
        S = np.ascontiguousarray(S, dtype=np.float64)
        acc1 = np.ascontiguousarray(acc1, dtype=np.float64)
        acc2 = np.ascontiguousarray(acc2, dtype=np.float64)
        n = S.shape[1]
        out = np.empty_like(S)
        trig = np.empty((4, 0)) if trig_out is None else trig_out
        if trig.shape[1] not in (0, n) or trig.shape[0] != 4 or trig.dtype != np.float64 or not trig.flags.c_contiguous:
            raise ValueError(f"trig_out must be a C-contiguous float64 array of shape (4, {n})")
        if self.plane:
            self._fns["_flow_batch"](S, acc1, acc2, float(dt), self.R, out, trig)
            return out, None
        cap = IMPACT_CAPACITY
        counts = np.zeros(n, dtype=np.int64)
        times = np.empty((n, cap))
        ends = np.empty((n, cap), dtype=np.int64)
        posts = np.empty((n, cap, 6))
        self._fns["_advance_batch"](S, acc1, acc2, float(dt), self.model, out, trig, counts, times, ends, posts)
        total = int(counts.sum())
        if total == 0:
            return out, None
        env = np.repeat(np.arange(n), counts)
        rank = np.arange(total) - np.repeat(np.cumsum(counts) - counts, counts)
        stored = rank < cap
        t = np.empty(total)
        e = np.empty(total, dtype=np.int8)
        post = np.empty((total, 6))
        t[stored] = times[env[stored], rank[stored]]
        e[stored] = ends[env[stored], rank[stored]]
        post[stored] = posts[env[stored], rank[stored]]
        for i in np.flatnonzero(counts > cap):  # more impacts than the buffer holds: rerun this penny alone
            s = tuple(float(v) for v in S[:, i])
            _, impacts, _, _ = self._fns["advance_through_m"](s, float(acc1[i]), float(acc2[i]), float(dt), self.model)
            rows = np.flatnonzero(env == i)
            t[rows] = [imp[0] for imp in impacts]
            e[rows] = [imp[1] for imp in impacts]
            post[rows] = [imp[2] for imp in impacts]
        return out, (env, t, e, post)
