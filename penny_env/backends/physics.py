"""The compiled physics: physics/kernels.py, flows.py, scalar.py and batch_loops.py as they are, built by
backends/builder.py for one target and one table kind.

Nothing here restates the physics. :func:`physics_build` has the builder copy the physics' functions, in
which the math namespace ``SCALAR`` is the target's, and puts in place of the plain loop's dispatches the
table's own formulas (``wall_terms``, ``wall_hess`` and ``wall_distance`` call them directly: the impact
search pays no branch over the registered shapes and keeps its helpers inlined) and a dispatch over the
registered laws (:func:`law_dispatch_source`, generated into a real file): laws only act at impacts. The
physics is compiled once per (target, table kind, the table's formulas, the laws). A penny takes the same
operations as in the plain-Python loop (the "python" target); tests/backends/test_compiled.py checks that they agree
bitwise.
"""
from __future__ import annotations

import importlib
import importlib.util
import sys
import types
from pathlib import Path

import numpy as np

from ..physics.build_names import build_supplied
from ..physics.scalar import flow_penny, table_constants_of
from . import cache, generated
from .interrupts import compiling, load_numba
from .builder import Builder, check_target
from .checks import recheck_law

# the table's formulas, which a build for one table kind supplies (its registered terms, Hessian and ray)
BUILD_SUPPLIED = ("table_terms", "table_hess", "table_ray")
table_terms, table_hess, table_ray = build_supplied(__name__, BUILD_SUPPLIED)


def variant_name(kind: int) -> str:
    """The name of the compiled variant for Model.kind ``kind``: "plane" (scalar.OTHER), else named after the
    table's formula (not its index, which follows the order of registration)."""
    if kind < 0:
        return "plane"
    from ..physics.tables import COMPILED_FORMULAS
    terms = COMPILED_FORMULAS[kind][0]
    name = f"{terms.__module__.rsplit('.', 1)[-1]}_{terms.__qualname__}"
    return "".join(ch if ch.isalnum() or ch == "_" else "_" for ch in name)


def check_kind(kind) -> int:
    """kind as an int: scalar.OTHER (the open plane) or an index into tables.COMPILED_FORMULAS."""
    from ..physics.tables import COMPILED_FORMULAS
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
    from ..physics.laws import COMPILED_LAWS, builtin_law_indices
    own = builtin_law_indices()
    if isinstance(law, bool) or not isinstance(law, (int, np.integer)):
        raise TypeError(f"law must be an int (Model.law), got {type(law).__name__}")
    if law >= len(COMPILED_LAWS):
        raise ValueError(f"law must be -1 or an index into laws.COMPILED_LAWS [0, {len(COMPILED_LAWS)}), got {law}")
    return own if law < 0 or law in own else tuple(sorted(own + (int(law),)))


def variant_key(kind: int, law: int = -1) -> tuple:
    """What the code compiled for table kind ``kind`` depends on: the kind's formulas and the laws it compiles
    (:func:`build_laws` of ``law``, a Model.law; -1: the built-in laws only)."""
    from ..physics.laws import COMPILED_LAWS
    from ..physics.tables import COMPILED_FORMULAS
    laws = build_laws(law)
    return (kind, COMPILED_FORMULAS[kind] if kind >= 0 else None, laws, tuple(COMPILED_LAWS[j] for j in laws))


def formulas(kind: int, law: int = -1) -> list:
    """The table's formulas and the laws that code compiled for ``kind`` inlines (cache.cacheable)."""
    from ..physics.laws import COMPILED_LAWS
    from ..physics.tables import COMPILED_FORMULAS
    return (list(COMPILED_FORMULAS[kind]) if kind >= 0 else []) + [COMPILED_LAWS[j] for j in build_laws(law)]


def physics_modules() -> tuple:
    """The modules whose functions the compiled physics copies: the physics, the backends that shape it, and
    every registered table's and law's module of penny_env's own (users' are never cached)."""
    from ..physics import batch_loops, flows, kernels, scalar
    from ..physics.laws import COMPILED_LAWS
    from ..physics.tables import COMPILED_FORMULAS
    from . import builder
    own = [g for triple in COMPILED_FORMULAS for g in triple if g is not None] + list(COMPILED_LAWS)
    tables = tuple(dict.fromkeys(sys.modules[f.__module__] for f in own if f.__module__.startswith("penny_env.")))
    # the math namespaces by their files (importing them imports numba)
    maths = tuple(types.SimpleNamespace(__name__=name, __file__=importlib.util.find_spec(name).origin)
                  for name in (f"{__package__}.numba_math", f"{__package__}.cuda_math"))
    return (kernels, flows, scalar, batch_loops, builder, generated, importlib.import_module(__name__)) + maths + tables


# -- what replaces the plain loop's dispatches in a build for one table kind -----------------------------------
def _no_wall(m, x, y):
    """wall_terms / wall_hess of the open plane's builds, which never evaluate a wall (the environments and the
    batch loops flow the plane's pennies without an impact search)."""
    return np.nan, np.nan, np.nan


def _no_ray(m, c, s):
    """wall_distance of the open plane's builds (no task draws a wall point there)."""
    return np.nan


def _table_wall_terms(m, x, y):
    """scalar.wall_terms for the one table kind a build is for (table_terms: its formula)."""
    return table_terms(table_constants_of(m), x, y)


def _table_wall_hess(m, x, y):
    return table_hess(table_constants_of(m), x, y)


def _table_wall_distance(m, c, s):
    """scalar.wall_distance for the one table kind a build is for: its ray formula."""
    return table_ray(table_constants_of(m), c, s)


def plane_advance_into(s, acc1, acc2, dt, m, stop_after, buf, row, base, arc):
    """scalar.advance_into in the open plane's builds: one flow, the whole motion where there is no wall (and
    run_interval never calls it there). It keeps the event loop out of the plane's machine code."""
    return flow_penny(s, acc1, acc2, dt, m.R), dt


def plane_advance_through_into(s, acc1, acc2, dt, m, stop_after, buf, row, arc):
    """scalar.advance_through_into in the open plane's builds (see :func:`plane_advance_into`)."""
    return flow_penny(s, acc1, acc2, dt, m.R), dt


def law_dispatch_source(indices) -> str:
    """Source of the compiled ``law_terms``: a branch per law j of the build (``indices``: their indices in
    laws.COMPILED_LAWS, which Model.law holds), calling ``law_j``. A Model whose law the build lacks gets NaN
    velocities, which the event loop's guard reports as a fault of that law (scalar.law_fault) rather
    than running another law."""
    lines = ['"""Generated by penny_env.backends.physics.law_dispatch_source: a branch per law of the build."""',
             "import math", "", "", "def law_terms(m, W, w, a, b, grad2):"]
    for j in indices:
        lines += [f"    if m.law == {j}:", f"        return law_{j}(W, w, a, b, grad2, m.e, m.Itot, m.J, m.m)"]
    lines += ["    return math.nan * W, math.nan * w", ""]
    return "\n".join(lines)


# -- the build ----------------------------------------------------------------------------------------------
_BUILDS: dict = {}  # (target,) + variant_key(kind) -> Builder


def physics_build(target: str, kind: int, fresh: bool = False, law: int = -1) -> Builder:
    """The Builder holding the physics' copies for ``target``, table kind ``kind`` and law ``law`` (a Model.law:
    the build holds the built-in laws and that one, :func:`build_laws`); the env step's build (backends/env.py)
    starts from a copy of its namespace. Built once per process and key; fresh: a new build, not kept (the PTX
    tests compile each compute capability from scratch)."""
    target = check_target(target)
    if target == "python":  # (plain Python dispatches over the tables and laws itself)
        kind, law = -1, -1
    key = (target,) + variant_key(check_kind(kind), law)
    if not fresh and key in _BUILDS:
        return _BUILDS[key]
    with compiling():  # (a Ctrl-C is held while numba loads and the copies are made, and kept: backends/interrupts.py)
        b = _physics_build(target, kind, law)
        if not fresh:
            _BUILDS[key] = b
    return b


def build_variant(target: str, kind: int, modules, task: str = "") -> str:
    """The name part of a build's copies: the table variant (and the task), the digest of the sources they inline
    (last on the CPU, whose cached files numba names after it), and "cuda" first on CUDA (never cached)."""
    name = f"{variant_name(kind)}_{task + '_' if task else ''}{cache.source_digest(modules)}"
    return f"cuda_{name}" if target == "cuda" else name


def _physics_build(target, kind, law=-1):
    if target != "python":
        try:
            load_numba()  # (the room it needs checked, Ctrl-C held, numba's cache repaired: backends/interrupts.py)
        except ImportError:
            raise ImportError("the compiled backend needs numba: pip install numba") from None
    if target == "cpu":
        from . import threads
        threads.configure()  # before any parallel loop runs: the threading layer is chosen once per process
    from ..physics import batch_loops, flows, kernels, scalar
    from ..physics.laws import COMPILED_LAWS
    from ..physics.tables import COMPILED_FORMULAS
    own = target == "cpu" and cache.cacheable(formulas(kind, law)) and cache.disk_cache_available()
    modules = physics_modules() if target != "python" else ()
    if own:
        for folder in (Path(scalar.__file__).with_name("__pycache__"), Path(scalar.__file__).parent / "tables" / "__pycache__",
                       generated.generated_dir() / "__pycache__"):
            cache.drop_stale_cache(folder, modules)
    b = Builder(target, build_variant(target, kind, modules) if modules else "python", cache=own)
    for module in (kernels, flows, scalar):
        b.add(module)
    if target == "python":  # the physics as it is (its own dispatches: any table, any law), for every kind
        b.laws = list(COMPILED_LAWS)
        b.functions = {k: v for k, v in vars(scalar).items() if isinstance(v, types.FunctionType)}
        b.functions.update(advance_batch=batch_loops.advance_batch, first_impact_batch=batch_loops.first_impact_batch)
        b.namespace.update(b.functions)
        b.origin.update((k, v) for k, v in b.namespace.items() if isinstance(v, types.FunctionType))
        return b
    # the quadrature rules as 2-D arrays: the same numbers, which compiled code indexes faster than a tuple of tuples
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

    # the table's formulas in place of scalar.wall_terms / wall_hess / wall_distance (which index a Python
    # list), and the laws' dispatch in place of scalar.law_terms
    if kind >= 0:
        terms, hess, ray = COMPILED_FORMULAS[kind]
        b.supply("table_terms", formula(terms))
        b.supply("table_hess", formula(hess))
        b.copy(_table_wall_terms, name="wall_terms", replaces=scalar.wall_terms)
        b.copy(_table_wall_hess, name="wall_hess", replaces=scalar.wall_hess)
        if ray is not None:
            b.supply("table_ray", formula(ray))
            b.copy(_table_wall_distance, name="wall_distance", replaces=scalar.wall_distance)
        else:
            b.copy(scalar.wall_distance_bisection, name="wall_distance", replaces=scalar.wall_distance)
    else:  # the open plane never evaluates a wall, nor runs the event loop (about halves its build)
        b.copy(_no_wall, name="wall_terms", replaces=scalar.wall_terms)
        b.copy(_no_wall, name="wall_hess", replaces=scalar.wall_hess)
        b.copy(_no_ray, name="wall_distance", replaces=scalar.wall_distance)
        b.copy(plane_advance_into, name="advance_into", replaces=scalar.advance_into)
        b.copy(plane_advance_through_into, name="advance_through_into", replaces=scalar.advance_through_into)
    # only the build's laws (build_laws): a user's law enters only the builds whose pennies run it
    laws = build_laws(law)
    for j in laws:
        b.namespace[f"law_{j}"] = formula(COMPILED_LAWS[j])
        # a user's law tried again as this build compiles it (a module constant edited after register_law changes
        # what numba freezes into it); a device function is tried as the plain function it is compiled from
        recheck_law(COMPILED_LAWS[j], b.namespace[f"law_{j}"] if target == "cpu" else None)
    b.laws = [b.namespace[f"law_{j}"] for j in laws]  # (their compiled copies, for tests)
    dispatch = generated.define("law_dispatch", law_dispatch_source(laws), {}, __name__)["law_terms"]
    b.copy(dispatch, replaces=scalar.law_terms)
    functions = {f.__name__: b.namespace[f.__name__] for f in sources}
    functions.update(advance_into=b.namespace["advance_into"], advance_through_into=b.namespace["advance_through_into"],
                     wall_distance=b.namespace["wall_distance"])
    # the per-penny bodies and their loops (parallel over pennies on the CPU, a kernel on CUDA), inlined into
    # the loops; the event loop's driver pasted into the batch loop (builder.inline_source: no per-penny
    # reference counting of the buffers)
    b.copies((batch_loops.angle_trig_into, batch_loops.advance_penny, batch_loops.first_impact_penny), inline=True)
    functions["advance_batch"] = b.loop(batch_loops.advance_batch, inline=(scalar.run_interval,))
    functions["first_impact_batch"] = b.loop(batch_loops.first_impact_batch)
    b.functions = functions
    b.check_supplied()
    return b
