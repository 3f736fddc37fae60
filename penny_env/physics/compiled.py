"""Compiled batches (numba): physics/scalar.py's own functions, compiled, run over the pennies of a
batch in parallel.

Nothing here restates the physics. :func:`compiled_functions` takes the functions of kernels.py,
flows.py and scalar.py as they are and compiles copies of them with numba, in which the math
namespace ``SCALAR`` is physics/numba_math.py (the same ``math`` functions, for numba). The only
new code is the loop over pennies (``_advance_batch``, ``_flow_batch``, ``_first_impact_batch``), the
unpacking of their impacts into arrays, and the tables' and laws' formulas put in place of the
plain loop's dispatch. The physics is compiled once per table kind (:func:`compiled_functions`):
``wall_terms`` and ``wall_hess`` call that table's formulas directly, so the impact search pays no
branch over the registered shapes and keeps its helpers inlined (with a dispatch over the four
built-in shapes, the vector env's step was about 3 % slower: PennyImpacts-Stadium-v0, N = 4096). The law is chosen at run time (:func:`law_dispatch_source`,
generated from laws.COMPILED_LAWS and compiled without the disk cache, its machine code cached
within its callers'): laws only act at impacts. Every cached copy's name carries a hash of the sources
it inlines (:func:`source_digest`), so no cache location can serve stale machine code. A penny therefore takes the same operations as
in the plain-Python loop (physics/pennies.py's ``backend="python"``); tests/test_compiled.py checks
that the two agree bitwise.

Every registered table (Ellipse, Circle, Stadium, RoundedRectangle, and any table registered with
formulas, see docs/extending.md) compiles; other tables (ConvexTable, protocol objects) run the
plain-Python loop. The first use in a fresh install compiles (about 10 s of CPU per table shape and
entry point, docs/compile_time.md; :func:`announce_compile` says so) and numba caches the machine
code on disk (``cache=True``).
"""
from __future__ import annotations

import builtins
import functools
import importlib
import importlib.util
import math
import types
from pathlib import Path

import numpy as np

# capacity of the per-penny impact buffer of one batch call; a penny with more impacts in one
# interval (accumulations) is rerun alone to collect them all
IMPACT_CAPACITY = 8

_COMPILED: dict = {}  # variant_key(kind) -> compiled functions


def available() -> bool:
    """numba is installed, so compiled batches can run (numba itself is imported at first use)."""
    return importlib.util.find_spec("numba") is not None


_WARNED = set()


def compiles(table) -> bool:
    """The table runs in the compiled loop: the open plane (None) or a registered table with formulas."""
    from .tables import compiled_kind
    return table is None or compiled_kind(type(table)) >= 0


def choose_backend(backend, params, table, law, settings, table_field="table", python="numpy") -> str:
    """'numba' or the plain-Python name ``python`` for ``backend`` in 'auto', 'numba', ``python``:
    'auto' takes numba where it is installed and the table compiles (:func:`compiles`), and warns once
    per table type naming the slower plain-Python path where it does not; an explicit 'numba' that
    cannot run raises ValueError naming the cause."""
    if backend not in ("auto", python, "numba"):
        raise ValueError(f"backend must be 'auto', {python!r} or 'numba', got {backend!r}")
    ok = compiles(table)
    if backend == "numba":
        if not available():
            raise ValueError("backend='numba' needs numba: pip install numba")
        if not ok:
            raise ValueError(f"backend='numba': {table_field} {type(table).__name__} does not compile "
                             f"(registered tables with formulas and the open plane do); use backend={python!r}")
    if backend == "auto":
        if not ok and type(table) not in _WARNED:
            import warnings
            _WARNED.add(type(table))
            warnings.warn(f"{table_field} {getattr(table, 'name', type(table).__name__)!s} ({type(table).__name__}) has no "
                          "compiled formulas: it runs the plain-Python event loop, much slower (register its "
                          "formulas to compile it, see docs/extending.md)", RuntimeWarning, stacklevel=3)
        return "numba" if available() and ok else python
    return backend


def _no_wall(m, x, y):
    """wall_terms / wall_hess of the open plane's loops, which never evaluate a wall (the
    environments and CompiledBatch flow the plane's pennies without an impact search)."""
    return np.nan, np.nan, np.nan


def _table_wall_terms(m, x, y):
    """scalar.wall_terms for the one table kind a namespace is compiled for (table_terms: its formula)."""
    return table_terms((m.t0, m.t1, m.t2, m.t3, m.t4), x, y)  # noqa: F821  (in the compiled copy's namespace)


def _table_wall_hess(m, x, y):
    return table_hess((m.t0, m.t1, m.t2, m.t3, m.t4), x, y)  # noqa: F821


def law_dispatch_source(n_laws: int) -> str:
    """Source of the compiled ``law_terms``: a branch per registered law function j, calling ``law_j``."""
    lines = ['"""Generated by penny_env.physics.compiled.law_dispatch_source: do not edit."""', "", "",
             "def law_terms(m, W, w, a, b, grad2):"]
    for j in range(n_laws - 1):
        lines += [f"    if m.law == {j}:", f"        return law_{j}(W, w, a, b, grad2, m.e, m.Itot, m.J, m.m)"]
    lines += [f"    return law_{n_laws - 1}(W, w, a, b, grad2, m.e, m.Itot, m.J, m.m)", ""]
    return "\n".join(lines)


def _law_dispatch(n_laws: int):
    """law_terms of :func:`law_dispatch_source`, defined in memory (from a pseudo-file). It is compiled
    without numba's cache (numba has no cache locator for a pseudo-file, and writing a real file next to
    the package fails on a read-only install); its callers are cached, with its machine code linked
    into theirs, and their names carry :func:`source_digest`, which covers this module's generator."""
    source = law_dispatch_source(n_laws)
    scope: dict = {"__name__": __name__}
    exec(compile(source, "<penny_env law dispatch>", "exec"), scope)
    return scope["law_terms"]


def source_digest(modules) -> str:
    """A short hash of the sources of ``modules``: it goes into the qualified name of every cached
    compiled copy (:func:`jit_copy`), so numba's cache files are named after the sources of everything
    they inline. numba checks a cached function against its own file only, while these copies also
    freeze constants and callees of other modules (quadrature rules, table formulas, laws, the physics
    called by the environment's step); a name keyed on all those sources can never load stale machine
    code, whichever cache location numba picks (the package's __pycache__, NUMBA_CACHE_DIR, the
    user-wide cache of a read-only install)."""
    import hashlib

    h = hashlib.sha256()
    for m in modules:
        h.update(m.__name__.encode() + b"\0" + Path(m.__file__).read_bytes() + b"\0")
    return h.hexdigest()[:16]


def drop_stale_cache(folder, modules) -> None:
    """Tidy-up only (correctness comes from :func:`source_digest` in the copies' names): delete the
    machine code cached in ``folder`` (a package __pycache__) when any of ``modules`` changed since it
    was written, so that edits do not pile up old files there. Other cache locations keep old files,
    which are never loaded (their names carry the old digest)."""
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


_CACHE_AVAILABLE: list = []


def disk_cache_available() -> bool:
    """numba finds a writable place to cache this package's functions: the package's __pycache__,
    NUMBA_CACHE_DIR, or numba's user-wide cache directory (a read-only install). Where none is writable
    (no writable home either), the functions compile in each process, with one logged warning, rather
    than fail ("cannot cache function ...: no locator available")."""
    if not _CACHE_AVAILABLE:
        import numba
        try:
            numba.njit(cache=True)(_no_wall)  # numba picks its cache location when caching is enabled
            ok = True
        except RuntimeError:
            ok = False
            import logging
            logging.getLogger("penny_env").warning("penny_env: numba finds no writable cache directory (set NUMBA_CACHE_DIR to one): "
                           "the compiled env step and physics compile in every process")
        _CACHE_AVAILABLE.append(ok)
    return _CACHE_AVAILABLE[0]


_ANNOUNCED: set = set()


def compiles_now(dispatcher):
    """True if numba has no machine code cached on disk for ``dispatcher`` (its first call compiles),
    False if its cache index exists (the first call loads it; it could still compile a signature the
    index lacks), None if numba's cache internals are not as expected (private API, numba 0.61-0.68)."""
    cache = getattr(dispatcher, "_cache", None)
    index = getattr(getattr(cache, "_cache_file", None), "_index_path", None)
    if cache is None:
        return None
    if index is None:
        return True if type(cache).__name__ == "NullCache" else None  # NullCache: caching is off
    return not Path(index).exists()


def announce_compile(entry: str, shape: str, kind: int, dispatcher) -> None:
    """One line on the "penny_env" logger (at WARNING, which Python prints to stderr when logging is
    not configured; silence it with logging.getLogger("penny_env").setLevel(logging.ERROR)) before
    the first build of ``entry`` for table kind ``kind`` in this process, if numba will compile it
    (:func:`compiles_now`); nothing when it loads the cache. Once per (entry, kind) per process."""
    if (entry, kind) in _ANNOUNCED:
        return
    _ANNOUNCED.add((entry, kind))
    fresh = compiles_now(dispatcher)
    if fresh is False:
        return
    import logging
    verb = "compiling" if fresh else "compiling (or loading from numba's cache)"
    logging.getLogger("penny_env").warning(
        f"penny_env: {verb} the {entry} for table {shape}: the first use of a table shape after installing takes "
        "about 10 s (up to a minute on a slow or busy machine); numba caches the machine code, later runs load it "
        "in about a second")


def physics_modules() -> tuple:
    """The modules whose functions compiled code copies (see :func:`compiled_functions`): the
    physics and every registered table's module (their formulas are compiled into the loop)."""
    import sys

    from . import flows, kernels, numba_math, scalar
    from .laws import COMPILED_LAWS
    from .tables import COMPILED_FORMULAS
    tables = tuple(dict.fromkeys(sys.modules[f.__module__] for f in [g for pair in COMPILED_FORMULAS for g in pair] + COMPILED_LAWS
                                 if f.__module__.startswith("penny_env.")))  # users' formulas are never cached
    return (kernels, flows, scalar, numba_math, importlib.import_module(__name__)) + tables


def jit_copy(f, namespace, jit, variant=""):
    """``jit`` of a copy of function f whose globals are ``namespace`` (where the math namespaces
    are physics/numba_math.py); default arguments that are modules (``xp``) become numba_math too.
    ``variant`` (a table kind's name, see :func:`variant_name`) goes into the copy's qualified name:
    numba's on-disk cache files are named after it, and copies compiled against different tables
    must not share them."""
    from . import numba_math

    defaults = tuple(numba_math if isinstance(d, types.ModuleType) else d for d in (f.__defaults__ or ()))
    copy = types.FunctionType(f.__code__, namespace, f.__name__, defaults, f.__closure__)
    copy.__module__ = f.__module__
    copy.__qualname__ = f"{f.__qualname__}__{variant}" if variant else f.__qualname__
    return jit(copy)


def variant_name(kind: int) -> str:
    """The name of the compiled variant for Model.kind ``kind``: "plane" (scalar.OTHER), else named
    after the table's formula (not its index, which follows the order of registration)."""
    if kind < 0:
        return "plane"
    from .tables import COMPILED_FORMULAS
    terms = COMPILED_FORMULAS[kind][0]
    name = f"{terms.__module__.rsplit('.', 1)[-1]}_{terms.__qualname__}"
    return "".join(ch if ch.isalnum() or ch == "_" else "_" for ch in name)


def check_kind(kind) -> int:
    """kind as an int: scalar.OTHER (the open plane) or an index into tables.COMPILED_FORMULAS."""
    from .tables import COMPILED_FORMULAS
    if isinstance(kind, bool) or not isinstance(kind, (int, np.integer)):
        raise TypeError(f"kind must be an int (Model.kind), got {type(kind).__name__}")
    if not -1 <= kind < len(COMPILED_FORMULAS):
        raise ValueError(f"kind must be -1 (the open plane) or a registered table kind in [0, {len(COMPILED_FORMULAS)}), "
                         f"got {kind}")
    return int(kind)


def variant_key(kind: int) -> tuple:
    """What the code compiled for table kind ``kind`` depends on: the kind's formulas and every law."""
    from .laws import COMPILED_LAWS
    from .tables import COMPILED_FORMULAS
    return (kind, COMPILED_FORMULAS[kind] if kind >= 0 else None, tuple(COMPILED_LAWS))


def cacheable(kind: int) -> bool:
    """The code compiled for table kind ``kind`` may go to numba's on-disk cache: penny_env's own
    formulas and laws only (a user's would be frozen into cached machine code that a later process,
    with other formulas under the same kind, would load)."""
    from .laws import COMPILED_LAWS
    from .tables import COMPILED_FORMULAS
    fs = list(COMPILED_FORMULAS[kind]) if kind >= 0 else []
    return all(f.__module__.startswith("penny_env.") for f in fs + COMPILED_LAWS)


def compiled_functions(kind: int) -> dict:
    """name -> compiled function, for kernels.py, flows.phase_sweep and scalar.py, specialised to
    one table kind: ``kind`` is the Model.kind of the pennies it will run (scalar.OTHER, -1: the open
    plane; else an index into tables.COMPILED_FORMULAS). ``wall_terms`` and ``wall_hess`` call that
    table's formulas; a Model of another kind must not be passed to these functions. The law is
    dispatched at run time over laws.COMPILED_LAWS.

    Compiled once per process for each (kind, its formulas, the registered laws). With penny_env's own
    formulas and laws the machine code is cached on disk; a user's registered formulas compile in each
    process (cache=False, see :func:`cacheable`)."""
    try:
        import numba
    except ImportError:
        raise ImportError('the compiled backend needs numba: pip install numba') from None
    from . import flows, kernels, numba_math, scalar
    from .laws import COMPILED_LAWS
    from .tables import COMPILED_FORMULAS
    kind = check_kind(kind)
    key = variant_key(kind)
    if key in _COMPILED:
        return _COMPILED[key]
    from . import parallel as parallel_setup
    parallel_setup.configure()  # before any parallel loop runs: the threading layer is chosen once per process
    own = cacheable(kind) and disk_cache_available()
    modules = physics_modules()
    variant = f"{variant_name(kind)}_{source_digest(modules)}"
    if own:
        cache = Path(__file__).with_name("__pycache__")
        drop_stale_cache(cache, modules)
        drop_stale_cache(Path(__file__).parent / "tables" / "__pycache__", modules)  # the formulas' copies

    jit = numba.njit(cache=own)

    def copy(f, compiler=jit):
        return jit_copy(f, namespace, compiler, variant)

    namespace = {"__builtins__": builtins}
    for module in (kernels, flows, scalar):
        namespace.update({k: v for k, v in vars(module).items() if not k.startswith("__")})
    namespace["SCALAR"] = namespace["ARRAY"] = numba_math
    # the quadrature rules as 2-D arrays: the same numbers, which compiled code indexes faster than
    # a tuple of tuples
    for name in ("RULE_NODES", "RULE_WEIGHTS"):
        namespace[name] = np.array(getattr(flows, name))
    sources = [f for module in (kernels, scalar) for f in vars(module).values()
               if isinstance(f, types.FunctionType) and f.__module__ == module.__name__]
    sources.append(flows.phase_sweep)
    for f in sources:
        namespace[f.__name__] = copy(f)

    def formula(f):  # penny_env's run in the physics namespace (numba_math); a user's in its own globals
        return copy(f) if f.__module__.startswith("penny_env.") else jit(f)

    # the table's formulas in place of scalar.wall_terms / wall_hess (which index a Python list),
    # and the laws' dispatch in place of scalar.law_terms
    if kind >= 0:
        namespace["table_terms"], namespace["table_hess"] = (formula(f) for f in COMPILED_FORMULAS[kind])
        namespace["wall_terms"], namespace["wall_hess"] = copy(_table_wall_terms), copy(_table_wall_hess)
    else:
        namespace["wall_terms"] = namespace["wall_hess"] = copy(_no_wall)
    for j, update in enumerate(COMPILED_LAWS):
        namespace[f"law_{j}"] = formula(update)
    namespace["law_terms"] = copy(_law_dispatch(len(COMPILED_LAWS)), numba.njit(cache=False))
    fns = {f.__name__: namespace[f.__name__] for f in sources}
    # the loops over pennies, compiled as copies too: module-level functions whose callees are
    # globals of the namespace (closures over dispatchers would miss numba's cache every process)
    namespace["prange"] = numba.prange
    namespace["_angle_trig"] = copy(_angle_trig)
    parallel = numba.njit(parallel=True, cache=own)
    for f in (_advance_batch, _flow_batch, _first_impact_batch):  # called under parallel.PARALLEL_LOCK
        # serially in a child forked after OpenMP ran (its own name: never the parallel copy's cache files)
        serial = functools.partial(jit_copy, f, namespace, jit, f"{variant}_serial")
        fns[f.__name__] = parallel_setup.locked(copy(f, parallel), serial)
    _COMPILED[key] = fns
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


def _first_impact_batch(S, acc1, acc2, horizon, m, rounds, t_out, end_out):
    for i in prange(S.shape[1]):  # noqa: F821
        s = (S[0, i], S[1, i], S[2, i], S[3, i], S[4, i], S[5, i])
        t_out[i], end_out[i] = first_impact_resumed(s, acc1[i], acc2[i], horizon[i], m, rounds)  # noqa: F821


def _flow_batch(S, acc1, acc2, dt, R, out, trig):
    for i in prange(S.shape[1]):  # noqa: F821
        s1 = flow1((S[0, i], S[1, i], S[2, i], S[3, i], S[4, i], S[5, i]), acc1[i], acc2[i], dt, R)  # noqa: F821
        for r in range(6):
            out[r, i] = s1[r]
        _angle_trig(s1, trig, i)


class CompiledBatch:
    """The per-penny event loop over one control interval for (6, N) batches, compiled (see the
    module docstring): :meth:`states_and_impacts`.

    ``CompiledBatch(params, table, law, settings)``; table None is the open plane. Raises ImportError
    without numba and ValueError for a table that does not compile (see :func:`compiles`)."""

    def __init__(self, params, table, law, settings):
        from .scalar import scalar_model

        if not compiles(table):
            raise ValueError(f"table: only registered tables with compiled formulas compile, got {type(table).__name__}")
        self.model = scalar_model(params, table, law, settings)
        self._fns = compiled_functions(self.model.kind)
        self.R = params.R
        self.plane = table is None
        self.table = table
        self._warm_up()

    def _warm_up(self):
        """Compile (or load from numba's cache) every path now rather than in the middle of a run:
        a batch of one penny at rest, and the one-penny rerun used when a buffer overflows."""
        batch = self._fns["_flow_batch" if self.plane else "_advance_batch"]
        announce_compile("compiled batch", "open plane" if self.plane else type(self.table).__name__, self.model.kind,
                         batch.__wrapped__)
        from .parallel import SERIAL_BELOW, serial_now
        # both loops: one penny runs on the calling thread, SERIAL_BELOW in parallel (not in a forked child)
        for n in (1,) if serial_now() else (1, SERIAL_BELOW):
            S = np.zeros((6, n))
            S[4] = 1.0
            zero = np.zeros(n)
            self.states_and_impacts(S, zero, zero, 1e-9)
        if not self.plane:
            self._fns["advance_through_m"]((0.0, 0.0, 0.0, 0.0, 1.0, 0.0), 0.0, 0.0, 1e-9, self.model)

    def first_impacts(self, S, acc1, acc2, horizon, rounds=64):
        """(t_hit (N,), end (N,) int8) of scalar.first_impact_resumed for each penny, in parallel."""
        n = S.shape[1]
        t = np.empty(n)
        end = np.empty(n, dtype=np.int64)
        self._fns["_first_impact_batch"](np.ascontiguousarray(S, dtype=np.float64), np.ascontiguousarray(acc1, dtype=np.float64),
                                         np.ascontiguousarray(acc2, dtype=np.float64),
                                         np.ascontiguousarray(horizon, dtype=np.float64), self.model, int(rounds), t, end)
        return t, end.astype(np.int8)

    def states_and_impacts(self, S, acc1, acc2, dt, trig_out=None):
        """(new S (6, N), log) after one interval dt: log None when no penny hit the wall, else
        (env, time, end, post (k, 6)) sorted by penny then time. trig_out: optional (4, N) array
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
