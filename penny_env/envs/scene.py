"""Scenes and tasks: frozen dataclasses, YAML presets under penny_env/presets/, validation that names fields.

A **scene** is the physical setting: the table, the impact law, the actuation, the penny's
parameters, the control period, the torque limits and the initial-state distribution. A **task**
is what the agent is asked to do: reward, termination, the episode length.

Presets are YAML files: ``penny_env/presets/scenes/<name>.yaml``, ``penny_env/presets/tasks/<name>.yaml`` and
``penny_env/presets/envs.yaml`` (one entry per registered env id: a scene, a task and overrides).
:func:`resolve` turns (scene, task, overrides) into validated :class:`Scene` and :class:`Task`;
every override key must be a field of one of them (nested dict fields such as ``init`` or
``torque_limits`` are merged key by key; ``table`` is replaced when it names a ``kind``).
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from ..physics import PennyParams, make_law, make_table
from ..physics.params import MAX_ANGULAR_SPEED
from ..physics.tables import TABLE_KINDS, Table
from ..physics.tables.base import LENGTH_RANGE
from ..physics.validation import check_actuation, check_table, step_speed_limits
from ..step.config import ConfigError, ConfigTypeError, UnknownFieldError, number
from ..step.tasks import TASKS, Task, config_fields, task_record

CONFIG_DIR = Path(__file__).resolve().parent.parent / "presets"

ACTUATIONS = {"both": (0, 1), "steer": (0,), "drive": (1,)}


def _config_error(exc, message):
    """The ConfigError for a table or law error: a ConfigTypeError where the cause was a TypeError."""
    return ConfigTypeError(message) if isinstance(exc, TypeError) else ConfigError(message)


def _num(owner: str, name: str, value, **bounds) -> float:
    return number(owner, name, value, **bounds)


def _range(owner: str, name: str, value) -> tuple[float, float]:
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        v = _num(owner, name, value)
        return (v, v)
    if not isinstance(value, (list, tuple)):
        raise ConfigTypeError(f"{owner}.{name} must be a number or a [low, high] pair, got {value!r}")
    if len(value) != 2:
        raise ConfigError(f"{owner}.{name} must be a number or a [low, high] pair, got {value!r}")
    lo, hi = (_num(owner, f"{name}[{i}]", v) for i, v in enumerate(value))
    if lo > hi:
        raise ConfigError(f"{owner}.{name} must have low <= high, got {value!r}")
    return (lo, hi)


def _keys(owner: str, value, allowed: dict) -> dict:
    if not isinstance(value, dict):
        raise ConfigTypeError(f"{owner} must be a mapping, got {type(value).__name__}")
    unknown = sorted(set(value) - set(allowed))
    if unknown:
        raise UnknownFieldError(f"{owner}: unknown field(s) {unknown}; allowed: {sorted(allowed)}")
    out = dict(allowed)
    out.update(value)
    return out


# The scene defaults, written here only: the presets (penny_env/presets/scenes/*.yaml) give what differs.
INIT_DEFAULTS = {"spawn_fraction": 0.7, "theta": [-3.141592653589793, 3.141592653589793],
                 "phi": [-3.141592653589793, 3.141592653589793], "theta_dot": [-2.0, 2.0], "phi_dot": [-1.0, 1.0]}
# +-1 action = +-limit [N m]: u1 = J * 10 rad/s^2 (steering), u2 = (I + m R^2) * 40 rad/s^2 (rolling), US penny
TORQUE_DEFAULTS = {"u1": 6.25e-7, "u2": 1.5e-5}
OBS_SCALE_DEFAULTS = {"theta_dot": 30.0, "phi_dot": 10.0}
PARAM_DEFAULTS = {name: getattr(PennyParams(), name) for name in ("R", "m", "I", "J")}  # the US penny


@dataclass(frozen=True)
class Scene:
    """The physical setting of an environment (see penny_env/presets/scenes/*.yaml).

    table:        {"kind": "ellipse", "a", "b"} | {"kind": "circle", "radius"} |
                  {"kind": "stadium", "radius", "length"} |
                  {"kind": "rounded_rectangle", "width", "height", "radius"} | any registered kind
                  (physics.tables.TABLE_KINDS) | {"kind": "none"} (the open plane); or a table object
                  (a ConvexTable, a RoundedRectangle, any object following the table protocol)
    law:          "elastic" | "plastic" | restitution coefficient e in [0, 1]
    actuation:    "both" (u1 steering and u2 rolling torque) | "steer" (u1 only) | "drive" (u2 only)
    params:       the penny's {R, m, I, J} (the paper's US penny by default)
    control_dt:   control period [s]; the torques are held constant over it
    torque_limits: {u1, u2} [N m]: the action +-1 maps to +-limit
    init:         initial-state distribution, uniform: spawn_fraction f (the contact point is
                  uniform in f times the table's spawn ellipse; f <= 1 - R / inradius keeps the
                  penny inside), ranges [low, high] of theta, phi, theta_dot, phi_dot
    obs_scale:    {theta_dot, phi_dot} [rad/s]: velocities are observed as tanh(v / scale)
    arena:        half-size [m] of the spawn and target region on the open plane, and the length
                  scale of its observations and rewards (ignored with walls); more than R, and more
                  than the task's tolerance
    """

    table: dict = field(default_factory=lambda: {"kind": "ellipse", "a": 0.15, "b": 0.2})
    law: Any = "elastic"
    actuation: str = "both"
    params: dict = field(default_factory=lambda: dict(PARAM_DEFAULTS))
    control_dt: float = 0.05
    torque_limits: dict = field(default_factory=lambda: dict(TORQUE_DEFAULTS))
    init: dict = field(default_factory=lambda: dict(INIT_DEFAULTS))
    obs_scale: dict = field(default_factory=lambda: dict(OBS_SCALE_DEFAULTS))
    arena: float = 0.2

    def __post_init__(self):
        o = "scene"
        table = self.table
        if table is None:
            table = {"kind": "none"}
        if isinstance(table, (str, int, float, list, tuple)):
            raise ConfigTypeError(f"{o}.table must be a mapping with a 'kind' or a table object, got {table!r}")
        try:
            t = make_table(dict(table) if isinstance(table, dict) else table)
        except (ValueError, TypeError) as exc:
            raise _config_error(exc, f"{o}.table: {exc}") from None
        # a dict spec is kept as given (YAML, repr); a table object is kept as the checked Table
        object.__setattr__(self, "table", dict(table) if isinstance(table, dict) else t)
        try:
            law = make_law(self.law)
        except (ValueError, TypeError) as exc:
            raise _config_error(exc, f"{o}.law: {exc}") from None
        object.__setattr__(self, "law", law.kind if law.kind != "restitution" else law.e)
        if not isinstance(self.actuation, str):
            raise ConfigTypeError(f"{o}.actuation must be a string, one of {sorted(ACTUATIONS)}, got {self.actuation!r}")
        if self.actuation not in ACTUATIONS:
            raise ConfigError(f"{o}.actuation must be one of {sorted(ACTUATIONS)}, got {self.actuation!r}")
        p = _keys(f"{o}.params", self.params, PARAM_DEFAULTS)
        p = {k: _num(f"{o}.params", k, v, positive=True) for k, v in p.items()}
        object.__setattr__(self, "params", p)
        object.__setattr__(self, "control_dt", _num(o, "control_dt", self.control_dt, positive=True))
        tl = _keys(f"{o}.torque_limits", self.torque_limits, TORQUE_DEFAULTS)
        object.__setattr__(self, "torque_limits", {k: _num(f"{o}.torque_limits", k, v, positive=True) for k, v in tl.items()})
        init = _keys(f"{o}.init", self.init, INIT_DEFAULTS)
        out = {"spawn_fraction": _num(f"{o}.init", "spawn_fraction", init["spawn_fraction"], nonneg=True)}
        for k in ("theta", "phi", "theta_dot", "phi_dot"):
            out[k] = list(_range(f"{o}.init", k, init[k]))
        object.__setattr__(self, "init", out)
        sc = _keys(f"{o}.obs_scale", self.obs_scale, OBS_SCALE_DEFAULTS)
        object.__setattr__(self, "obs_scale", {k: _num(f"{o}.obs_scale", k, v, positive=True) for k, v in sc.items()})
        object.__setattr__(self, "arena", _num(o, "arena", self.arena, positive=True))
        R = p["R"]
        penny = PennyParams(**p)
        try:  # documented limits that bound the work of a step (physics.validation, docs/physics.md#limits)
            check_actuation(penny, self.torque_limits["u1"], self.torque_limits["u2"], self.control_dt)
        except ValueError as exc:
            raise ConfigError(f"{o}.{exc}") from None
        # the initial speeds: one step at the torque limits from any of them stays within the limits
        W_max, w_max = self.step_speed_limits()
        for name, bound, torque in (("theta_dot", W_max, "u2"), ("phi_dot", w_max, "u1")):
            worst = max(abs(v) for v in out[name])
            if worst > bound:
                room = max(bound, 0.0)
                where = (f"a step at torque_limits.{torque} = {self.torque_limits[torque]!r} N m over control_dt = "
                         f"{self.control_dt!r} s stays within MAX_ANGULAR_SPEED = {MAX_ANGULAR_SPEED:g} rad/s (and "
                         "MAX_STEERED_PHASE; docs/physics.md#limits)")
                if out[name] == list(_range(o, name, INIT_DEFAULTS[name])):
                    # the range is the default one: the torque limit (or control_dt) the user set leaves no room for it
                    raise ConfigError(f"{o}.torque_limits.{torque} = {self.torque_limits[torque]!r} N m with control_dt = "
                                      f"{self.control_dt!r} s leaves room for |{name}| <= {room:.6g} rad/s only (from a "
                                      f"faster start, one step at that torque could pass MAX_ANGULAR_SPEED = "
                                      f"{MAX_ANGULAR_SPEED:g} rad/s or MAX_STEERED_PHASE; docs/physics.md#limits), less than "
                                      f"the default init.{name} = {out[name]!r} rad/s: lower torque_limits.{torque} or "
                                      f"control_dt (or narrow init.{name})")
                raise ConfigError(f"{o}.init.{name} = {out[name]!r} rad/s: |{name}| must be <= {room:.6g} rad/s, so that "
                                  f"{where}")
        lo_len, hi_len = LENGTH_RANGE
        if not lo_len <= self.arena <= hi_len:  # beyond it the squared distances of the reward overflow
            raise ConfigError(f"{o}.arena must be within [{lo_len:g}, {hi_len:g}] m, got {self.arena!r}")
        if t is not None:
            if not t.inradius > R:
                raise ConfigError(f"{o}.table is too small for the penny: inradius {t.inradius:.4g} m <= R = {R:.4g} m")
            try:
                check_table(t, penny)
            except ValueError as exc:
                raise ConfigError(f"{o}.{exc}") from None
            fmax = 1.0 - R / t.inradius
            if out["spawn_fraction"] > fmax:
                raise ConfigError(f"{o}.init.spawn_fraction must be <= 1 - R / inradius = {fmax:.6g} "
                                  f"(so the penny starts inside), got {out['spawn_fraction']!r}")
        else:
            # the plane's arena is its length scale (the reward's progress term is divided by it) and its table: one
            # below the penny, as a table whose inradius is, is no region for it (1e-9 m paid -5.7e6 at the first step)
            if not self.arena > R:
                raise ConfigError(f"{o}.arena = {self.arena!r} m is too small for the penny: the open plane's spawn and "
                                  f"target region must exceed its radius R = {R:.4g} m")
            if out["spawn_fraction"] > 1.0:
                raise ConfigError(f"{o}.init.spawn_fraction must be <= 1 on the open plane, got {out['spawn_fraction']!r}")

    # derived objects ---------------------------------------------------------------------
    def step_speed_limits(self) -> tuple[float, float]:
        """(W_max, w_max): |theta_dot| and |phi_dot| beyond which a step at this scene's torque limits
        could pass the physics' documented limits (physics.validation.step_speed_limits): the
        initial speeds must be within them, and an episode ends, truncated, when a state passes them."""
        u1 = self.torque_limits["u1"] if 0 in self.controls else 0.0
        u2 = self.torque_limits["u2"] if 1 in self.controls else 0.0
        return step_speed_limits(self.make_params(), u1, u2, self.control_dt)

    def make_table(self) -> Table | None:
        return make_table(dict(self.table)) if isinstance(self.table, dict) else self.table

    def make_law(self):
        return make_law(self.law)

    def make_params(self) -> PennyParams:
        return PennyParams(**self.params)

    @property
    def controls(self) -> tuple[int, ...]:
        """Indices of the actuated controls among (u1, u2)."""
        return ACTUATIONS[self.actuation]

    def spawn_axes(self) -> tuple[float, float]:
        """Semi-axes of the spawn ellipse E (inside the table, containing the inscribed disk: the
        table's own spawn_axes), or the arena on the open plane."""
        tab = self.make_table()
        return tab.spawn_axes() if tab is not None else (self.arena, self.arena)

    def length_scale(self) -> float:
        """L: positions are observed as position / L (walls) or tanh(position / L) (open plane)."""
        tab = self.make_table()
        return tab.size if tab is not None else self.arena


SCENE_FIELDS = tuple(f.name for f in fields(Scene))
_MERGED = {"params", "torque_limits", "init", "obs_scale"}


def _yaml_load(path: Path) -> dict:
    import yaml

    from .yaml_io import read_text, safe_load
    try:
        text = read_text(path)  # (a folder, a missing file, bytes that are not UTF-8: named)
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    try:
        data = safe_load(text)  # (1e-2 is a float, as in YAML 1.2; a key given twice is refused)
    except yaml.YAMLError as exc:
        raise ConfigError(f"invalid YAML in {path}: {exc}") from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigTypeError(f"{path}: the top level must be a mapping, got {type(data).__name__}")
    return data


def preset_dict(kind: str, name) -> dict:
    """A scene/task dict from a preset name, a YAML path, a dict or a Scene/Task."""
    if isinstance(name, (Scene, Task)):
        return {f.name: getattr(name, f.name) for f in fields(name)}
    if isinstance(name, dict):
        return dict(name)
    if isinstance(name, (str, os.PathLike)):
        p = Path(name)
        if p.suffix in (".yaml", ".yml"):
            return _yaml_load(p)
        path = CONFIG_DIR / f"{kind}s" / f"{name}.yaml"
        if not path.exists():
            names = sorted(q.stem for q in (CONFIG_DIR / f"{kind}s").glob("*.yaml"))
            raise ConfigError(f"unknown {kind} preset {str(name)!r}; presets: {names} (or a path to a .yaml file)")
        return _yaml_load(path)
    raise ConfigTypeError(f"{kind} must be a preset name, a .yaml path, a dict or a {kind.title()}, got {type(name).__name__}")


def _merge(base: dict, over: dict, owner: str, allowed: tuple) -> dict:
    out = dict(base)
    for k, v in over.items():
        if k not in allowed:
            raise UnknownFieldError(f"{owner}: unknown field {k!r}; fields: {list(allowed)}")
        if k in _MERGED and isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = {**out[k], **v}
        elif k == "table" and isinstance(v, dict) and "kind" not in v and isinstance(out.get(k), dict):
            merged = {**out[k], **v}
            # a deprecated field name in the override replaces the preset's field it aliases (Circle: r -> radius)
            kind = merged.get("kind")
            aliases = getattr(TABLE_KINDS.get(kind) if isinstance(kind, str) else None, "field_aliases", {})
            for old, new in aliases.items():
                if old in v and new not in v:
                    merged.pop(new, None)
            out[k] = merged
        else:
            out[k] = v
    return out


def _build_scene(data: dict, owner: str) -> Scene:
    unknown = sorted(set(data) - set(SCENE_FIELDS))
    if unknown:
        raise UnknownFieldError(f"{owner}: unknown field(s) {unknown}; fields: {list(SCENE_FIELDS)}")
    return Scene(**data)


def _build_task(data: dict, owner: str) -> Task:
    """The task's configuration: the class its registered kind names (step/tasks/), its fields checked."""
    record = task_record(data.get("kind", "reach"))
    allowed = config_fields(record.name)
    unknown = sorted(set(data) - set(allowed))
    if unknown:
        raise UnknownFieldError(f"{owner}: unknown field(s) {unknown} for task kind {record.name!r}; fields: {list(allowed)}")
    return record.config(**data)


def resolve(scene="ellipse", task="reach", **overrides) -> tuple[Scene, Task]:
    """Validated (Scene, Task) from presets (names, YAML paths, dicts) and field overrides. A task field must
    be one of the fields of the task's kind (its registered record's configuration, step/tasks/)."""
    sc = preset_dict("scene", scene)
    tk = preset_dict("task", task)
    kind = overrides.get("kind", tk.get("kind", "reach"))
    task_fields = config_fields(task_record(kind).name)
    so = {k: v for k, v in overrides.items() if k in SCENE_FIELDS}
    to = {k: v for k, v in overrides.items() if k in task_fields}
    unknown = sorted(set(overrides) - set(so) - set(to))
    if unknown:
        # worded as Python's own TypeError, which tools match (TorchRL retries without 'frameskip')
        raise UnknownFieldError(f"unexpected keyword argument {unknown[0]!r}: unknown field(s) {unknown}; "
                                f"scene fields: {list(SCENE_FIELDS)}, task fields ({kind}): {list(task_fields)}")
    where_s = f"scene {scene!r}" if isinstance(scene, (str, os.PathLike)) else "scene"
    where_t = f"task {task!r}" if isinstance(task, (str, os.PathLike)) else "task"
    merged = dict(tk)
    merged.update(to)
    return _build_scene(_merge(sc, so, where_s, SCENE_FIELDS), where_s), _build_task(merged, where_t)


def env_presets() -> dict:
    """The registered env ids: {id: {"scene": ..., "task": ..., **overrides}} from penny_env/presets/envs.yaml."""
    data = _yaml_load(CONFIG_DIR / "envs.yaml")
    return data


__all__ = ["Scene", "Task", "ConfigError", "ConfigTypeError", "UnknownFieldError", "resolve", "env_presets", "CONFIG_DIR",
           "replace", "TASKS"]
