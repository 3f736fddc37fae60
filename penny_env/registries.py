"""The public registration functions: a user's impact law, table shape or task, checked when it is registered.

Each registry holds records keyed by the user's object itself (never by its name: the compiled builds are keyed
on the record's functions). The plain-Python checks are the physics' and the step's own
(physics/laws.law_record, physics/tables/base.check_table_class, step/tasks/base.check_task); the checks that
need numba (the compiled copies of a law or a table's formulas) are the backends' (backends/checks.py), so that
the physics and the step stay free of numba; a task's stages are tried on the default scene
(envs/task_trials.py). docs/extending.md shows one of each.
"""
from __future__ import annotations

from .backends.checks import compile_law, compile_table_formulas
from .physics.laws import add_law, is_builtin_law, law_record
from .physics.tables.base import add_table, check_table_class, is_own
from .step.tasks.base import add_task, check_task

__all__ = ["register_law", "register_table", "register_task"]


def register_law(name: str, update, e: float = 1.0, *, jacobian=None, conserves_energy: bool = False) -> None:
    """Make ``make_law(name)`` (and ``law: name`` in a scene) the law whose post-impact velocities are
    ``update(W, w, a, b, grad2, e, Itot, J, m) -> (W+, w+)`` (physics/laws.law_record says what each argument
    is). Tried before it is accepted: its signature, typical impacts in plain Python (two finite real numbers,
    no energy gain, the end no longer moving outward; physics/law_checks.py) and the same impacts compiled by
    numba (backends/checks.compile_law): TypeError / ValueError naming the law otherwise. Registering a name
    again replaces its law for everything built afterwards, with a UserWarning; the built-in names cannot be
    replaced."""
    record = law_record(name, update, e, jacobian=jacobian, conserves_energy=conserves_energy)
    if not is_builtin_law(update):
        compile_law(record)
    add_law(record)


def register_table(name: str, cls) -> None:
    """Make ``make_table({"kind": name, ...})`` (and scene YAML ``table: {kind: name, ...}``) build ``cls(...)``
    (physics/tables/base.add_table). A class with static ``terms`` and ``hess`` runs in the compiled event loop:
    their signatures are checked, and numba compiles them now (backends/checks.compile_table_formulas); each
    instance is checked on a grid before a penny rolls on it. TypeError / ValueError naming the class
    otherwise. Registering a name again replaces the class for every table built afterwards, with a
    UserWarning; the names of penny_env's own shapes cannot be taken by another class."""
    check_table_class(name, cls)
    if cls.terms is not None and not is_own(cls):
        compile_table_formulas(cls)
    add_table(name, cls)


def register_task(record) -> None:
    """Register a task record (step/tasks/base.TaskRecord) under ``record.name`` (``task: {kind: <name>, ...}`` in
    a preset or a dict). Checked now, not when an environment compiles: the record's shape
    (step/tasks/base.check_task: signatures, extra_obs, defaults; the built-in names reach, park and impacts are
    refused), then trial calls of its stages on the default scene (envs/task_trials.py: what each returns, and
    where its observation writes). TypeError / ValueError naming the task and the stage otherwise. Registering
    a name again replaces the task for everything built afterwards, with a UserWarning."""
    from functools import partial

    from .envs.task_trials import retry_if_edited, trial_task
    from .step.tasks.base import RETRIALS
    check_task(record)
    trial_task(record)
    add_task(record)
    RETRIALS[id(record)] = (record, partial(retry_if_edited, record))  # (an edit after this: tried again before use)
