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

import math
import numbers
import os
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from ..physics import PennyParams, make_law, make_table
from ..physics.params import MAX_ANGULAR_SPEED
from ..physics.tables import TABLE_KINDS, Table
from ..physics.tables.base import LENGTH_RANGE
from ..physics.validation import check_actuation, check_table, step_speed_limits

CONFIG_DIR = Path(__file__).resolve().parent.parent / "presets"

ACTUATIONS = {"both": (0, 1), "steer": (0,), "drive": (1,)}
TASK_KINDS = ("reach", "park", "impacts")


class ConfigError(ValueError):
    """An invalid scene/task configuration; the message names the field."""


class ConfigTypeError(ConfigError, TypeError):
    """A configuration field of the wrong type (a string for a number, a list for a mapping): a
    ConfigError, and a TypeError as the rest of the package raises for a wrong type."""


class UnknownFieldError(ConfigError, TypeError):
    """A field (or keyword argument) that the scene and task do not have: a ConfigError, and a
    TypeError as Python raises for an unexpected keyword argument (tools such as TorchRL probe
    keywords that way)."""


def _config_error(exc, message):
    """The ConfigError for a table or law error: a ConfigTypeError where the cause was a TypeError."""
    return ConfigTypeError(message) if isinstance(exc, TypeError) else ConfigError(message)


def _num(owner: str, name: str, value, *, positive=False, nonneg=False, lo=None, hi=None) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        try:
            import numpy as np
            if isinstance(value, (np.integer, np.floating)):
                value = float(value)
            else:
                raise TypeError
        except TypeError:
            raise ConfigTypeError(f"{owner}.{name} must be a number, got {value!r}") from None
    value = float(value)
    if not math.isfinite(value):
        raise ConfigError(f"{owner}.{name} must be finite, got {value!r}")
    if positive and value <= 0:
        raise ConfigError(f"{owner}.{name} must be positive, got {value!r}")
    if nonneg and value < 0:
        raise ConfigError(f"{owner}.{name} must be non-negative, got {value!r}")
    if lo is not None and value < lo:
        raise ConfigError(f"{owner}.{name} must be >= {lo}, got {value!r}")
    if hi is not None and value > hi:
        raise ConfigError(f"{owner}.{name} must be <= {hi}, got {value!r}")
    return value


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
                  scale of its observations (ignored with walls)
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
        for name, bound in (("theta_dot", W_max), ("phi_dot", w_max)):
            worst = max(abs(v) for v in out[name])
            if worst > bound:
                raise ConfigError(f"{o}.init.{name} = {out[name]!r} rad/s: |{name}| must be <= {bound:.6g} rad/s, so that "
                                  f"a step at the torque limits stays within MAX_ANGULAR_SPEED = {MAX_ANGULAR_SPEED:g} "
                                  f"rad/s (and MAX_STEERED_PHASE; docs/physics.md#limits)")
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
        elif out["spawn_fraction"] > 1.0:
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


@dataclass(frozen=True)
class Task:
    """Reward and termination (see penny_env/presets/tasks/*.yaml and the PennyEnv docstring).

    kind:              "reach" | "park" | "impacts"
    max_episode_steps: episode length (truncation)
    tolerance:         [m] success radius around the target (reach, park)
    speed_tolerance:   [m/s] park: rolling speed |R theta_dot| below this counts as at rest
    spin_tolerance:    [rad/s] park: and the turning rate |phi_dot| below this (None: not checked)
    target_fraction:   targets are uniform in this fraction of the spawn ellipse (reach, park)
    progress_weight:   weight of the progress term (d_prev - d) / L (reach, park)
    speed_cost:        park: weight of the speed penalty |R theta_dot| / (R obs_scale.theta_dot) near the target
    ctrl_cost:         weight of the control cost mean(a^2)
    success_bonus:     reward added on the step that succeeds
    impact_reward:     impacts: reward per impact on the marked arc
    arc_half_width:    impacts: [rad] half-width of the marked arc (polar angle of the impact point
                       about the table's centre); >= pi marks the whole wall
    impacts_goal:      impacts: success after this many impacts on the arc
    heading_offset:    reach, park: [m] minimum distance of the target from the initial heading
                       line (the line through the start contact point along phi); 0 = no constraint.
                       Targets are drawn by rejection (up to 64 candidates, then the farthest).
    """

    kind: str = "reach"
    max_episode_steps: int = 400
    tolerance: float = 0.02
    speed_tolerance: float = 0.01
    spin_tolerance: float | None = None
    target_fraction: float = 0.6
    progress_weight: float = 10.0
    speed_cost: float = 0.1
    ctrl_cost: float = 0.01
    success_bonus: float = 10.0
    impact_reward: float = 1.0
    arc_half_width: float = 0.5
    impacts_goal: int = 10
    heading_offset: float = 0.0

    def __post_init__(self):
        o = "task"
        if not isinstance(self.kind, str):
            raise ConfigTypeError(f"{o}.kind must be a string, one of {list(TASK_KINDS)}, got {self.kind!r}")
        if self.kind not in TASK_KINDS:
            raise ConfigError(f"{o}.kind must be one of {list(TASK_KINDS)}, got {self.kind!r}")
        for name in ("max_episode_steps", "impacts_goal"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, numbers.Integral):
                raise ConfigTypeError(f"{o}.{name} must be a positive integer, got {v!r}")
            if v < 1:
                raise ConfigError(f"{o}.{name} must be a positive integer, got {v!r}")
            object.__setattr__(self, name, int(v))
        object.__setattr__(self, "tolerance", _num(o, "tolerance", self.tolerance, positive=True))
        object.__setattr__(self, "speed_tolerance", _num(o, "speed_tolerance", self.speed_tolerance, positive=True))
        if self.spin_tolerance is not None:
            object.__setattr__(self, "spin_tolerance", _num(o, "spin_tolerance", self.spin_tolerance, positive=True))
        object.__setattr__(self, "target_fraction", _num(o, "target_fraction", self.target_fraction, nonneg=True, hi=1.0))
        for name in ("progress_weight", "speed_cost", "ctrl_cost", "success_bonus", "impact_reward"):
            object.__setattr__(self, name, _num(o, name, getattr(self, name), nonneg=True))
        object.__setattr__(self, "arc_half_width", _num(o, "arc_half_width", self.arc_half_width, positive=True))
        object.__setattr__(self, "heading_offset", _num(o, "heading_offset", self.heading_offset, nonneg=True))


SCENE_FIELDS = tuple(f.name for f in fields(Scene))
TASK_FIELDS = tuple(f.name for f in fields(Task))
_MERGED = {"params", "torque_limits", "init", "obs_scale"}


def _yaml_load(path: Path) -> dict:
    import yaml
    try:
        with open(path) as f:
            data = yaml.safe_load(f)
    except FileNotFoundError:
        raise ConfigError(f"config file not found: {path}") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"invalid YAML in {path}: {exc}") from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigTypeError(f"{path}: the top level must be a mapping, got {type(data).__name__}")
    return data


def _preset(kind: str, name) -> dict:
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


def _build(cls, data: dict, owner: str):
    allowed = SCENE_FIELDS if cls is Scene else TASK_FIELDS
    unknown = sorted(set(data) - set(allowed))
    if unknown:
        raise UnknownFieldError(f"{owner}: unknown field(s) {unknown}; fields: {list(allowed)}")
    return cls(**data)


def resolve(scene="ellipse", task="reach", **overrides) -> tuple[Scene, Task]:
    """Validated (Scene, Task) from presets (names, YAML paths, dicts) and field overrides."""
    sc = _preset("scene", scene)
    tk = _preset("task", task)
    so = {k: v for k, v in overrides.items() if k in SCENE_FIELDS}
    to = {k: v for k, v in overrides.items() if k in TASK_FIELDS}
    unknown = sorted(set(overrides) - set(so) - set(to))
    if unknown:
        # worded as Python's own TypeError, which tools match (TorchRL retries without 'frameskip')
        raise UnknownFieldError(f"unexpected keyword argument {unknown[0]!r}: unknown field(s) {unknown}; "
                                f"scene fields: {list(SCENE_FIELDS)}, task fields: {list(TASK_FIELDS)}")
    where_s = f"scene {scene!r}" if isinstance(scene, (str, os.PathLike)) else "scene"
    where_t = f"task {task!r}" if isinstance(task, (str, os.PathLike)) else "task"
    return (_build(Scene, _merge(sc, so, where_s, SCENE_FIELDS), where_s),
            _build(Task, _merge(tk, to, where_t, TASK_FIELDS), where_t))


def env_presets() -> dict:
    """The registered env ids: {id: {"scene": ..., "task": ..., **overrides}} from penny_env/presets/envs.yaml."""
    data = _yaml_load(CONFIG_DIR / "envs.yaml")
    return data


__all__ = ["Scene", "Task", "ConfigError", "UnknownFieldError", "resolve", "env_presets", "CONFIG_DIR", "replace"]
