"""Compiled batches: physics/scalar.py's own functions, built by physics/builder.py for a target ("cpu":
numba, parallel over the pennies of a batch; "cuda": one GPU thread per penny; "python": as they are).

Nothing here restates the physics. :func:`physics_build` takes the functions of kernels.py, flows.py and
scalar.py as they are and has the builder compile copies of them, in which the math namespace ``SCALAR`` is
the target's (physics/numba_math.py on the CPU). The only new code is the per-penny work of a batch
(:func:`advance_penny`, :func:`first_impact_penny`: one call of scalar.run_interval or of the first-impact
search) and its two-line loops (:func:`advance_batch`, :func:`first_impact_batch`), and the tables' and
laws' formulas put in place of the plain loop's dispatch. The physics is compiled once per table kind:
``wall_terms`` and ``wall_hess`` call that table's formulas directly, so the impact search pays no
branch over the registered shapes and keeps its helpers inlined (with a dispatch over the four
built-in shapes, the vector env's step was about 3 % slower: PennyImpacts-Stadium-v0, N = 4096). The law is chosen at run time (:func:`law_dispatch_source`,
generated from the build's laws, :func:`build_laws`: penny_env's own and the one user law the build's
pennies run, so that a user's law never enters another scene's code; compiled without the disk cache, its
machine code cached within its callers'): laws only act at impacts. Every cached copy's name carries a hash of the sources
it inlines (:func:`source_digest`), so no cache location can serve stale machine code. A penny therefore takes the same operations as
in the plain-Python loop (the "python" target); tests/test_compiled.py checks that they agree bitwise.

Every registered table (Ellipse, Circle, Stadium, RoundedRectangle, and any table registered with
formulas, see docs/extending.md) compiles; other tables (ConvexTable, protocol objects) run the
plain-Python loop. The first use in a fresh install compiles (about 10 s of CPU per table shape and
entry point, docs/compile_time.md; :func:`announce_compile` says so) and numba caches the machine
code on disk (``cache=True``).
"""
from __future__ import annotations

import importlib
import importlib.util
import math
import types
from pathlib import Path

import numpy as np

from .scalar import NO_ARC, first_impact_resumed, flow1, run_interval  # noqa: F401  (the plain loops' globals)

# capacity of the per-penny impact buffer of one batch call; a penny with more impacts in one
# interval (accumulations) is rerun alone to collect them all
IMPACT_CAPACITY = 8

_COMPILED: dict = {}  # (target,) + variant_key(kind, law) -> compiled functions


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


def law_dispatch_source(indices) -> str:
    """Source of the compiled ``law_terms``: a branch per law j of the build (``indices``: their indices in
    laws.COMPILED_LAWS, which Model.law holds), calling ``law_j``. A Model whose law the build lacks gets NaN
    velocities, which the event loop's guard reports as a fault of that law (scalar.law_fault) rather
    than running another law."""
    lines = ['"""Generated by penny_env.physics.compiled.law_dispatch_source: do not edit."""', "", "",
             "def law_terms(m, W, w, a, b, grad2):"]
    for j in indices:
        lines += [f"    if m.law == {j}:", f"        return law_{j}(W, w, a, b, grad2, m.e, m.Itot, m.J, m.m)"]
    lines += ["    return math.nan * W, math.nan * w", ""]
    return "\n".join(lines)


def _law_dispatch(indices):
    """law_terms of :func:`law_dispatch_source`, defined in memory (from a pseudo-file). It is compiled
    without numba's cache (numba has no cache locator for a pseudo-file, and writing a real file next to
    the package fails on a read-only install); its callers are cached, with its machine code linked
    into theirs, and their names carry :func:`source_digest`, which covers this module's generator."""
    source = law_dispatch_source(indices)
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
    machine code cached in ``folder`` (a package __pycache__) by earlier versions of ``modules``, so that
    edits do not pile up old files there. Only files whose names lack the current digest go: processes
    that start together after an edit (pytest-xdist workers, a pool of env workers) compile and load the
    current files side by side, and none deletes what another has just written (a segmentation fault
    was seen once while loading after such concurrent deletions; its cause is not pinned down). Other
    cache locations keep old files, which are never loaded (their names carry the old digest)."""
    folder = Path(folder)
    current = source_digest(modules)
    stamp = folder / "penny_env_numba.stamp"
    try:
        if stamp.exists() and stamp.read_text() == current:
            return
        for f in list(folder.glob("*.nbi")) + list(folder.glob("*.nbc")):
            if current not in f.name:
                f.unlink(missing_ok=True)
        folder.mkdir(exist_ok=True)
        stamp.write_text(current)
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

    from . import builder, flows, kernels, numba_math, scalar
    from .laws import COMPILED_LAWS
    from .tables import COMPILED_FORMULAS
    tables = tuple(dict.fromkeys(sys.modules[f.__module__] for f in [g for pair in COMPILED_FORMULAS for g in pair] + COMPILED_LAWS
                                 if f.__module__.startswith("penny_env.")))  # users' formulas are never cached
    return (kernels, flows, scalar, numba_math, builder, importlib.import_module(__name__)) + tables


def jit_copy(f, namespace, jit, variant="", math=None):
    """``jit`` of a copy of function f whose globals are ``namespace`` (where the math namespaces
    are physics/numba_math.py, or ``math``); default arguments that are modules (``xp``) become that
    namespace too.
    ``variant`` (a table kind's name, see :func:`variant_name`) goes into the copy's qualified name:
    numba's on-disk cache files are named after it, and copies compiled against different tables
    must not share them."""
    if math is None:
        from . import numba_math as math
    defaults = tuple(math if isinstance(d, types.ModuleType) else d for d in (f.__defaults__ or ()))
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


def build_laws(law: int = -1) -> tuple:
    """The indices in laws.COMPILED_LAWS of the laws a build compiles: penny_env's own, and the user's law
    ``law`` (a Model.law) where it is one. One user law per build: a law that numba cannot type, or that
    fails on a target, then breaks only the builds that run it, never the others nor the built-in ids."""
    from .laws import COMPILED_LAWS, builtin_law_indices
    own = builtin_law_indices()
    if isinstance(law, bool) or not isinstance(law, (int, np.integer)):
        raise TypeError(f"law must be an int (Model.law), got {type(law).__name__}")
    if law >= len(COMPILED_LAWS):
        raise ValueError(f"law must be -1 or an index into laws.COMPILED_LAWS [0, {len(COMPILED_LAWS)}), got {law}")
    return own if law < 0 or law in own else tuple(sorted(own + (int(law),)))


def variant_key(kind: int, law: int = -1) -> tuple:
    """What the code compiled for table kind ``kind`` depends on: the kind's formulas and the laws it compiles
    (:func:`build_laws` of ``law``, a Model.law; -1: the built-in laws only)."""
    from .laws import COMPILED_LAWS
    from .tables import COMPILED_FORMULAS
    laws = build_laws(law)
    return (kind, COMPILED_FORMULAS[kind] if kind >= 0 else None, laws, tuple(COMPILED_LAWS[j] for j in laws))


def cacheable(kind: int, law: int = -1) -> bool:
    """The code compiled for table kind ``kind`` and law ``law`` may go to numba's on-disk cache: penny_env's
    own formulas and laws only (a user's would be frozen into cached machine code that a later process,
    with other formulas under the same kind, would load)."""
    from .laws import COMPILED_LAWS
    from .tables import COMPILED_FORMULAS
    fs = list(COMPILED_FORMULAS[kind]) if kind >= 0 else []
    return all(f.__module__.startswith("penny_env.") for f in fs + [COMPILED_LAWS[j] for j in build_laws(law)])


def compiled_functions(kind: int, target: str = "cpu", law: int = -1) -> dict:
    """name -> function of the physics for ``target`` ("cpu": numba; "cuda": numba-cuda device functions
    and kernels; "python": the plain functions), specialised to one table kind: ``kind`` is the
    Model.kind of the pennies it will run (scalar.OTHER, -1: the open plane; else an index into
    tables.COMPILED_FORMULAS). ``wall_terms`` and ``wall_hess`` call that table's formulas; a Model of
    another kind must not be passed to these functions. The law is dispatched at run time over the
    build's laws (:func:`build_laws`: the built-in ones and ``law``, the Model.law of a user's law the
    pennies run). The loops over pennies (advance_batch, first_impact_batch) are compiled by
    physics/builder.py: parallel on the CPU, one thread per penny on CUDA.

    Built once per process for each (target, kind, its formulas, the build's laws). With penny_env's
    own formulas and laws the CPU machine code is cached on disk; a user's registered formulas compile
    in each process (cache=False, see :func:`cacheable`)."""
    from .builder import check_target
    target = check_target(target)
    kind = check_kind(kind)
    key = (target,) + variant_key(kind, law)
    if key in _COMPILED:
        return _COMPILED[key]
    if target == "python":
        from . import scalar
        fns = {k: v for k, v in vars(scalar).items() if isinstance(v, types.FunctionType)}
        fns.update(advance_batch=advance_batch, first_impact_batch=first_impact_batch)
        _COMPILED[key] = fns
        return fns
    _COMPILED[key] = fns = physics_build(target, kind, law=law).functions
    return fns


_BUILDS: dict = {}  # (target,) + variant_key(kind, law) -> Builder


def physics_build(target: str, kind: int, fresh: bool = False, law: int = -1):
    """The Builder (physics/builder.py) holding the physics' copies for ``target`` and table kind ``kind``;
    its ``functions`` attribute maps the names callers use to the compiled functions. The env step's build
    (envs/functional.py) starts from a copy of its namespace. Built once per process and key; fresh: a new
    build, not kept (the PTX tests compile each compute capability from scratch)."""
    key = (target,) + variant_key(check_kind(kind), law)
    if not fresh and key in _BUILDS:
        return _BUILDS[key]
    b = _physics_build(target, kind, law)
    if not fresh:
        _BUILDS[key] = b
    return b


def _physics_build(target, kind, law=-1):
    if target == "cpu":
        try:
            import numba
        except ImportError:
            raise ImportError('the compiled backend needs numba: pip install numba') from None
    from . import flows, kernels, scalar
    from .builder import Builder
    from .laws import COMPILED_LAWS
    from .tables import COMPILED_FORMULAS
    if target == "cpu":
        from . import parallel as parallel_setup
        parallel_setup.configure()  # before any parallel loop runs: the threading layer is chosen once per process
    own = target == "cpu" and cacheable(kind, law) and disk_cache_available()
    modules = physics_modules()
    variant = f"{variant_name(kind)}_{source_digest(modules)}" + ("_cuda" if target == "cuda" else "")
    if own:
        cache = Path(__file__).with_name("__pycache__")
        drop_stale_cache(cache, modules)
        drop_stale_cache(Path(__file__).parent / "tables" / "__pycache__", modules)  # the formulas' copies
    b = Builder(target, variant, cache=own)
    for module in (kernels, flows, scalar):
        b.add(module)
    # the quadrature rules as 2-D arrays: the same numbers, which compiled code indexes faster than
    # a tuple of tuples
    for name in ("RULE_NODES", "RULE_WEIGHTS"):
        b.namespace[name] = np.array(getattr(flows, name))
    sources = [f for module in (kernels, scalar) for f in vars(module).values()
               if isinstance(f, types.FunctionType) and f.__module__ == module.__name__]
    sources.append(flows.phase_sweep)
    b.copies(sources)
    # inlined where they are called: every penny's step runs them, and a call that passes the buffers
    # increments and decrements the reference counts of their six arrays (atomically: the threads of a
    # parallel loop contend for them)
    b.copies((scalar.run_interval, scalar.clear_row), inline=True)

    def formula(f):  # penny_env's run in the physics namespace; a user's in its own globals
        if f.__module__.startswith("penny_env."):
            return b.copy(f)
        return b._jit(f)

    # the table's formulas in place of scalar.wall_terms / wall_hess (which index a Python list),
    # and the laws' dispatch in place of scalar.law_terms
    if kind >= 0:
        b.namespace["table_terms"], b.namespace["table_hess"] = (formula(f) for f in COMPILED_FORMULAS[kind])
        b.namespace["wall_terms"], b.namespace["wall_hess"] = b.copy(_table_wall_terms), b.copy(_table_wall_hess)
    else:  # the open plane never evaluates a wall, nor runs the event loop (about halves its build)
        b.namespace["wall_terms"] = b.namespace["wall_hess"] = b.copy(_no_wall)
        b.namespace["advance_into"] = b.copy(plane_advance_into)
        b.namespace["advance_through_into"] = b.copy(plane_advance_through_into)
    # only the build's laws (build_laws): a user's law enters only the builds whose pennies run it
    laws = build_laws(law)
    for j in laws:
        b.namespace[f"law_{j}"] = formula(COMPILED_LAWS[j])
    b.laws = [b.namespace[f"law_{j}"] for j in laws]  # (their compiled copies, for tests)
    dispatch = _law_dispatch(laws)
    if target == "cpu":  # in memory, so never disk-cached itself (see _law_dispatch)
        import numba
        b.copy(dispatch, jit=numba.njit(cache=False))
    else:
        b.copy(dispatch)
    functions = {f.__name__: b.namespace[f.__name__] for f in sources}
    functions.update(advance_into=b.namespace["advance_into"], advance_through_into=b.namespace["advance_through_into"])
    # the per-penny bodies and their loops (parallel over pennies on the CPU, a kernel on CUDA)
    # inlined into the loops (the records they pass on are written in called functions only: numba's
    # parallel loops lose writes through a NamedTuple's attribute made in the loop body itself, see
    # envs/functional.step_env)
    b.copies((angle_trig_into, advance_penny, first_impact_penny), inline=True)
    # called under parallel.PARALLEL_LOCK on the CPU; the event loop's driver pasted into the batch loop
    # (builder.inline_source: no per-penny reference counting of the buffers)
    functions["advance_batch"] = b.loop(advance_batch, inline=(scalar.run_interval,))
    functions["first_impact_batch"] = b.loop(first_impact_batch)
    b.functions = functions
    return b


def plane_advance_into(s, acc1, acc2, dt, m, stop_after, buf, row, base, arc):
    """scalar.advance_into in the open plane's builds: one flow, the whole motion where there is no wall
    (and run_interval never calls it there). It keeps the event loop out of the plane's machine code."""
    return flow1(s, acc1, acc2, dt, m.R), dt  # noqa: F821  (in the compiled copy's namespace)


def plane_advance_through_into(s, acc1, acc2, dt, m, stop_after, buf, row, arc):
    """scalar.advance_through_into in the open plane's builds (see :func:`plane_advance_into`)."""
    return flow1(s, acc1, acc2, dt, m.R), dt  # noqa: F821


# -- the per-penny work of a batch and its loops (physics/builder.py compiles them for each target) -----
prange = range  # numba.prange in the CPU copies; the CUDA kernels run one penny per thread


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
    s1, el = run_interval(s, math.cos(s[3]), math.sin(s[3]), acc1[i], acc2[i], dt[i], m, plane, True,  # noqa: F821
                          stop_after, buf, i, NO_ARC)  # noqa: F821
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
    t_out[i], end_out[i] = first_impact_resumed(s, acc1[i], acc2[i], horizon[i], m, rounds)  # noqa: F821


def first_impact_batch(S, acc1, acc2, horizon, m, rounds, t_out, end_out):
    for i in prange(S.shape[1]):
        first_impact_penny(i, S, acc1, acc2, horizon, m, rounds, t_out, end_out)


class CompiledBatch:
    """The per-penny event loop over one interval for (6, N) batches, on one target (physics/builder.py):
    "cpu" (numba, parallel over pennies, the default), "cuda" (one GPU thread per penny) or "python" (the
    plain functions: the readable reference). :meth:`states_and_impacts`, :meth:`run_intervals`,
    :meth:`first_impacts`.

    ``CompiledBatch(params, table, law, settings, target="cpu")``; table None is the open plane. Raises
    ImportError without numba and ValueError for a table that does not compile (see :func:`compiles`;
    the "python" target runs any table)."""

    CAPACITY = IMPACT_CAPACITY

    def __init__(self, params, table, law, settings, target="cpu"):
        from .builder import check_target
        from .scalar import scalar_model

        self.target = check_target(target)
        if target != "python" and not compiles(table):
            raise ValueError(f"table: only registered tables with compiled formulas compile, got {type(table).__name__}")
        self.model = scalar_model(params, table, law, settings)
        self._fns = compiled_functions(self.model.kind if target != "python" else -1, target, self.model.law)
        self.law = law
        self.R = params.R
        self.plane = table is None
        self.table = table
        if target == "cpu":
            self._warm_up()

    def _warm_up(self):
        """Compile (or load from numba's cache) every path now rather than in the middle of a run:
        a batch of one penny at rest, and the parallel loop (SERIAL_BELOW pennies)."""
        batch = self._fns["advance_batch"]
        announce_compile("compiled batch", "open plane" if self.plane else type(self.table).__name__, self.model.kind,
                         batch.__wrapped__)
        from .parallel import SERIAL_BELOW, serial_now
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
        returned buffers' capacity is the largest count). ValueError naming the law or the table where
        the event loop's guard stopped a penny (physics/faults.py)."""
        from .scalar import impact_buffers
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
            from .faults import check_faults
            check_faults(buf, self.law, self.table, out, self.R, elapsed=elapsed)
        over = np.flatnonzero(buf.count > self.CAPACITY)
        if over.size:  # more impacts than a slot row holds: rerun those pennies alone, with room for all
            big = impact_buffers(n, int(buf.count.max()))
            for name in ("time", "end", "post", "rest"):
                getattr(big, name)[:, :self.CAPACITY] = getattr(buf, name)
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
                    getattr(big, name)[i, :k] = getattr(one, name)[0]
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
    return (env, buf.time[env, rank], buf.end[env, rank].astype(np.int8), buf.post[env, rank],
            buf.rest[env, rank].astype(np.int8))


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
