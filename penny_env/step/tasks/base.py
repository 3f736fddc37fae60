"""Tasks as records in a registry, as tables and laws are (physics/tables/base.py, physics/laws.py).

A task is one module: its configuration (a frozen dataclass derived from :class:`Task`, whose fields are
the YAML/keyword fields of the task), the numbers its formulas read (a NamedTuple built once by
``constants``), and its stages, plain functions that the env step (step/functional.py) calls and the
backends compile into it:

==================  ================================================================================
``reward``          ``reward(k, before, after, ctrl, n_arc, xp) -> (reward, success)``: one step's reward
                    and the success that terminates the episode (before, after: functional.PennyState;
                    ctrl: mean squared action; n_arc: the step's impacts on the marked arc)
``target``          ``target(k, p, m, s, trig, base, xp) -> (tx, ty, arc_cos, arc_sin)``: the target
                    and the marked arc's direction of a fresh episode (draws: ``draw_uniform(base, j,
                    xp)`` with j >= 6; j < 6 are the scene's)
``observation``     ``observation(k, st, obs, i)``: writes the task's own observation entries (from
                    column 10 on) of env i into obs, or None for none (``extra_obs`` holds their
                    bounds)
``marked_arc``      ``marked_arc(k, st) -> (cos b, sin b, cos half-width)``: the impacts the event loop
                    counts into n_arc (physics/scalar.record_impact), or None for none
==================  ================================================================================

All stages are plain math on floats and tuples (numba compiles them for the CPU and CUDA); ``xp`` is the
math namespace (kernels.SCALAR in plain Python). ``penny_env.register_task`` checks a record when it is
registered (:func:`check_task`, then trial calls of its stages: envs/task_trials.py): the configuration's
defaults build, its stages have the signatures above and return what the step needs. A new task is one
module that calls ``penny_env.register_task``, plus a YAML preset (or a dict) with ``kind: <its name>``; see
docs/extending.md.
"""
from __future__ import annotations

import inspect
import math
from dataclasses import dataclass, fields
from typing import Callable

from ..config import ConfigError, ConfigTypeError, count, number


@dataclass(frozen=True)
class Task:
    """The fields every task has (each task's configuration adds its own; see its module).

    kind:              the registered task's name ("reach", "park", "impacts", or a user's)
    max_episode_steps: episode length (truncation)
    ctrl_cost:         weight of the control cost mean(a^2)
    success_bonus:     reward added on the step that succeeds
    """

    kind: str = "reach"
    max_episode_steps: int = 400
    ctrl_cost: float = 0.01
    success_bonus: float = 10.0

    def __post_init__(self):
        o = "task"
        object.__setattr__(self, "max_episode_steps", count(o, "max_episode_steps", self.max_episode_steps))
        for name in ("ctrl_cost", "success_bonus"):
            object.__setattr__(self, name, number(o, name, getattr(self, name), nonneg=True))

    def set_number(self, name, **bounds):
        """Field ``name`` checked as a number (config.number) and stored as a float."""
        object.__setattr__(self, name, number("task", name, getattr(self, name), **bounds))


@dataclass(frozen=True)
class TaskRecord:
    """A registered task (module docstring): its name, configuration class, constants and stages."""

    name: str
    config: type
    constants: Callable
    reward: Callable
    target: Callable
    observation: Callable | None = None
    extra_obs: tuple = ()          # ((low, high), ...) of the entries ``observation`` writes
    marked_arc: Callable | None = None
    needs_walls: bool = False      # the task is meaningless on the open plane (the impacts task)
    goal: bool = False             # success is the contact point within task.tolerance of the target, which the
    #                                observation holds as obs[8:10] (reach): goal_env=True relabels goals with it

    @property
    def obs_dim(self) -> int:
        return 10 + len(self.extra_obs)


TASKS: dict = {}  # name -> TaskRecord
FLOAT32_MAX = 3.4028234663852886e38  # the largest finite float32: the observations' dtype

_SIGNATURES = {"constants": ("scene", "task", "L"), "reward": ("k", "before", "after", "ctrl", "n_arc", "xp"),
               "target": ("k", "p", "m", "s", "trig", "base", "xp"), "observation": ("k", "st", "obs", "i"),
               "marked_arc": ("k", "st")}


def _check_stage(record: TaskRecord, stage: str) -> None:
    f = getattr(record, stage)
    if f is None and stage in ("observation", "marked_arc"):
        return
    if not callable(f):
        raise TypeError(f"register_task({record.name!r}): {stage} must be a function, got {type(f).__name__}")
    try:
        params = list(inspect.signature(f).parameters)
    except (TypeError, ValueError):
        raise TypeError(f"register_task({record.name!r}): {stage} must be a plain Python function") from None
    if len(params) != len(_SIGNATURES[stage]):
        want = ", ".join(_SIGNATURES[stage])
        raise TypeError(f"register_task({record.name!r}): {stage} must take ({want}), got ({', '.join(params)})")


BUILTIN_TASKS = ("reach", "park", "impacts")  # names no user task may take (every environment id runs one)


def is_own(record: TaskRecord) -> bool:
    """The record's stages are penny_env's own functions (a built-in task)."""
    stages = (record.reward, record.target, record.observation, record.marked_arc)
    return all(f is None or str(getattr(f, "__module__", "")).startswith("penny_env.") for f in stages)


def check_task(record: TaskRecord) -> None:
    """The static checks of a task before it is registered: a TaskRecord; a name that is an identifier and
    not a built-in task's (unless the record is penny_env's own); a configuration class derived from
    :class:`Task` whose defaults build; stages with the documented signatures; extra_obs bounds as (low, high)
    pairs of finite numbers with low < high. TypeError / ValueError naming the task otherwise. The trial calls
    of the stages are penny_env.register_task's (envs/task_trials.py)."""
    if not isinstance(record, TaskRecord):
        raise TypeError(f"register_task takes a TaskRecord, got {type(record).__name__}")
    if not isinstance(record.name, str) or not record.name.isidentifier():
        raise ValueError(f"register_task: name must be an identifier, got {record.name!r}")
    if record.name in BUILTIN_TASKS and not is_own(record):
        raise ValueError(f"register_task: {record.name!r} is a built-in task and cannot be replaced (environment ids "
                         "run it); register yours under another name")
    if not (isinstance(record.config, type) and issubclass(record.config, Task)):
        raise TypeError(f"register_task({record.name!r}): config must be a dataclass derived from "
                        f"penny_env.step.tasks.Task, got {record.config!r}")
    for stage in _SIGNATURES:
        _check_stage(record, stage)
    for j, pair in enumerate(record.extra_obs):
        if (not isinstance(pair, tuple) or len(pair) != 2 or not all(isinstance(v, (int, float)) for v in pair)
                or not all(math.isfinite(v) for v in pair) or not pair[0] < pair[1]):
            raise ValueError(f"register_task({record.name!r}): extra_obs[{j}] must be a (low, high) pair of finite "
                             f"numbers with low < high, got {pair!r}")
        if not all(abs(v) <= FLOAT32_MAX for v in pair):  # (observation_space's float32 would hold it as inf)
            raise ValueError(f"register_task({record.name!r}): extra_obs[{j}] = {pair!r} must be within the float32 "
                             f"range of the observation, |bound| <= {FLOAT32_MAX:.8g}")
    if bool(record.extra_obs) != (record.observation is not None):
        raise ValueError(f"register_task({record.name!r}): observation writes the extra_obs entries: give both or neither")
    try:
        record.config(kind=record.name)
    except (ConfigError, TypeError, ValueError) as exc:
        raise ValueError(f"register_task({record.name!r}): the configuration's defaults do not build: {exc}") from None


def add_task(record: TaskRecord) -> None:
    """Put a task under ``record.name`` (``task: {kind: <name>, ...}`` in a preset or a dict) once
    :func:`check_task` accepts it. Registering a name again replaces the record for everything built afterwards
    (the compiled steps are keyed on the record, never on its name, so the new one compiles anew), with a
    UserWarning: environments built before keep the task they were built with."""
    check_task(record)
    old = TASKS.get(record.name)
    TASKS[record.name] = record
    if old is not None and old != record:
        import warnings
        warnings.warn(f"register_task: {record.name!r} now names the new task for everything built from here on; "
                      "environments built before keep the task they were built with", UserWarning, stacklevel=3)


RETRIALS: dict = {}  # id(record) -> (record, retry): what penny_env.register_task asks a Core to run before use


def retry_before_use(record) -> None:
    """The re-trial that penny_env.register_task left for ``record`` (envs/task_trials.retry_if_edited: its trials
    again where a module constant its stages read was edited since), run by every Core before it uses the record;
    nothing for a record registered otherwise."""
    entry = RETRIALS.get(id(record))
    if entry is not None and entry[0] is record:
        entry[1]()


def task_record(kind) -> TaskRecord:
    """The registered record of task kind ``kind`` (ConfigError naming the registered kinds otherwise)."""
    if not isinstance(kind, str):
        raise ConfigTypeError(f"task.kind must be a string, one of {sorted(TASKS)}, got {kind!r}")
    if kind not in TASKS:
        raise ConfigError(f"task.kind must be one of {sorted(TASKS)}, got {kind!r}")
    return TASKS[kind]


def config_fields(kind: str) -> tuple:
    """The field names of task kind ``kind``'s configuration."""
    return tuple(f.name for f in fields(task_record(kind).config))


def all_config_fields() -> tuple:
    """Every field of every registered task (an override must be a field of its task)."""
    out = {}
    for record in TASKS.values():
        out.update((f.name, None) for f in fields(record.config))
    return tuple(out)


def check_constants(record: TaskRecord, k) -> None:
    """The task's constants must be a NamedTuple of plain numbers (they travel packed as float64, see
    backends/packing.py)."""
    if not (isinstance(k, tuple) and hasattr(k, "_fields")):
        raise TypeError(f"task {record.name!r}: constants() must return a NamedTuple, got {type(k).__name__}")
    hints = getattr(type(k), "__annotations__", {})
    for name, v in zip(k._fields, k):
        if type(v) not in (int, float, bool):
            raise TypeError(f"task {record.name!r}: constants field {name} must be an int, float or bool, got "
                            f"{type(v).__name__}")
        declared = hints.get(name)
        declared = getattr(declared, "__forward_arg__", getattr(declared, "__name__", declared))
        # an int field travels as an int64 (backends/packing.py): 2**70 was a bare OverflowError at env build
        if type(v) is int and declared != "float" and not -(1 << 63) <= v < (1 << 63):
            raise ValueError(f"task {record.name!r}: constants field {name} = {v} does not fit the int64 it travels "
                             "as; use a smaller integer, or declare the field a float")
