"""The checks of a user's law or table that need numba: the compiled event loop runs what numba makes of the
user's functions, so the compiled copies are tried as the plain ones are (physics/law_checks.py,
physics/tables/registered.py). Called by the public registration functions (penny_env/registries.py) and,
per table instance, where a compiled backend is chosen for it (backends/choice.py).

A law or a table numba cannot compile is refused when it is registered, with numba's message and the name of
the law or class, rather than failing later inside an unrelated environment's build.
"""
from __future__ import annotations

import weakref

from ..physics.edits import globals_read
from ..physics.law_checks import ARGUMENTS, try_law
from .interrupts import load_numba
from ..physics.tables.base import N_CONSTANTS
from ..physics.tables.registered import check_formulas_on_grid, once

_COMPILED_FORMULAS = weakref.WeakKeyDictionary()  # table class -> (terms, hess) as numba compiles them
_CHECKED_TABLES = weakref.WeakKeyDictionary()     # table -> True: its compiled formulas were compared on the grid


def numba_message(exc, limit: int = 400) -> str:
    """The first lines of numba's error, at most ``limit`` characters (numba may print whole values)."""
    text = " ".join(ln.strip() for ln in str(exc).splitlines() if ln.strip())
    return text if len(text) <= limit else text[:limit] + " ..."


def compile_law(record) -> None:
    """numba compiles the law's update for float64 arguments, as the event loop does, and the compiled function
    passes the plain trials (law_checks.try_law: numba's math differs from Python's on domain errors,
    ``math.sqrt(-1)`` is NaN there); ValueError naming the law and numba's message otherwise."""
    load_numba()  # (the room it needs checked, Ctrl-C held: backends/interrupts.py)
    import numba
    from numba import types
    try:
        compiled = numba.njit(cache=False)(record.update)
        compiled.compile((types.float64,) * len(ARGUMENTS))
    except Exception as exc:  # noqa: BLE001 (numba raises many kinds; all mean "cannot compile")
        raise ValueError(f"register_law({record.name!r}): numba cannot compile update, so the compiled event loop "
                         f"could not run it ({type(exc).__name__}: {numba_message(exc)}); write it as plain math on "
                         "floats (docs/extending.md)") from None
    try_law(record.name, compiled, record.e, record.conserves_energy, "update compiled by numba")


def recheck_law(update, runs=None) -> None:
    """The trials of registration (law_checks.try_law) again, on what a build is about to run: ``runs``, the build's
    compiled copy of the user's law ``update`` (numba freezes the module's globals it reads when it compiles), or
    ``update`` itself (the plain-Python step calls it as it is now), once per registered record of it (its name, e and
    conserves_energy). A law whose module constants were edited after register_law (an energy-conserving law made
    lossy, say) was compiled as edited with no new check; now ValueError naming the law. Nothing for penny_env's own
    laws (tested in the suite)."""
    from ..physics.laws import LAW_KINDS, is_builtin_law
    if is_builtin_law(update):
        return
    label = ("update as this build compiles it" if runs is not None else "update as the plain-Python step runs it") + \
        " (its module's globals may have changed since register_law: register it again after an edit)"
    for record in [r for r in LAW_KINDS.values() if r.update is update]:
        try_law(record.name, update if runs is None else runs, record.e, record.conserves_energy, label)


def compile_table_formulas(cls) -> None:
    """numba compiles cls.terms and cls.hess for the arguments the event loop passes (c: N_CONSTANTS float64;
    x, y: float64), each returning three numbers; ValueError naming the class and numba's message otherwise.
    The compiled copies are kept for :func:`check_compiled_formulas`."""
    load_numba()  # (the room it needs checked, Ctrl-C held: backends/interrupts.py)
    import numba
    from numba import types
    arg = (types.UniTuple(types.float64, N_CONSTANTS), types.float64, types.float64)
    out = []
    for label in ("terms", "hess"):
        try:
            f = numba.njit(cache=False)(getattr(cls, label))
            f.compile(arg)
        except Exception as exc:  # noqa: BLE001 (numba raises many kinds; all mean "cannot compile")
            raise ValueError(f"register_table: {cls.__name__}.{label}: numba cannot compile it, so the compiled event "
                             f"loop could not run this table ({type(exc).__name__}: {numba_message(exc)}); write it "
                             "as plain math on floats (docs/extending.md)") from None
        ret = f.nopython_signatures[0].return_type
        if not (isinstance(ret, types.BaseTuple) and len(ret) == 3 and all(isinstance(t, types.Number) for t in ret)):
            raise ValueError(f"register_table: {cls.__name__}.{label} must return three numbers, numba types its result "
                             f"as {ret}")
        out.append(f)
    _COMPILED_FORMULAS[cls] = tuple(out)


def check_compiled_formulas(table) -> None:
    """A user table's formulas as numba compiles them against its own h, grad and hessian on the comparison
    grid (registered.check_formulas_on_grid), once per table, before a compiled backend runs it; ValueError
    naming the table otherwise. Nothing for penny_env's own shapes (tested in the suite) and the plane."""
    if table is None or type(table).__module__.startswith("penny_env."):
        return
    compiled = _COMPILED_FORMULAS.get(type(table))
    if compiled is None:
        return
    once(_CHECKED_TABLES, table, lambda t: check_formulas_on_grid(t, compiled[0], compiled[1], " (compiled by numba)"))


_CHECKED_AS_RUN = weakref.WeakKeyDictionary()  # table -> {what it was checked on: see check_table_as_run}


def check_table_as_run(table, build) -> None:
    """A user table's formulas as ``build`` (physics.physics_build's Builder) runs them, against its own h, grad (and
    hessian) on the comparison grid (registered.check_formulas_on_grid); ValueError naming the table and the first
    point where they differ. On the CPU, the build's compiled copies (numba freezes the module globals they read
    when it compiles them); with the plain-Python step and on CUDA (compiled from them), the formulas as they are
    now. A table whose module constants were edited after register_table, or after its first check, ran the edited
    formulas with no new check (the sibling of recheck_law); once per table and what it runs. Nothing for
    penny_env's own shapes and the plane.
    """
    from ..physics.tables import COMPILED_FORMULAS, compiled_kind
    if table is None or type(table).__module__.startswith("penny_env.") or compiled_kind(type(table)) < 0:
        return
    terms, hess, _ = COMPILED_FORMULAS[compiled_kind(type(table))]
    if build.target == "cpu":
        terms, hess = build.namespace["table_terms"], build.namespace["table_hess"]
        key = (terms, hess)  # (the compiled copies themselves: a fresh build's new copies are checked anew)
        how = " (as this build compiled it: register the table again after editing its module)"
    else:
        key = (build.target, globals_read(terms), globals_read(hess))
        how = " (as it is now: its module's globals may have changed since register_table)"
    try:
        done = _CHECKED_AS_RUN.setdefault(table, set())
    except TypeError:  # (an unhashable table: checked every time)
        done = set()
    if key in done:
        return
    check_formulas_on_grid(table, terms, hess, how)
    done.add(key)

