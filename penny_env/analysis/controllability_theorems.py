"""Which probe cells and start/target pairs the theory decides: docs/controllability_theory.md as code.

Only the open plane has impossibility theorems for the single-input probes:

* T2.3, steer only: theta_dot never changes without impacts, so a park (|R theta_dot| < speed_tolerance)
  is impossible from a start with |R theta_dot| >= speed_tolerance;
* T3.2, drive only: from phi_dot = 0 the heading never changes without impacts, so the contact point
  stays on its initial heading line and a target at least `tolerance` off that line is unreachable.

:func:`cell_theorem` says whether every start/target pair a scene/task can draw falls under one of
them (from the distributions' ranges); :func:`pair_theorem` decides one pair exactly. On a table no
probe cell is impossible by theorem (T2.5, T3.3, T3.4): there the witnesses decide. The verdict module
of the study links :data:`DOC` and names the returned id.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

DOC = "controllability_theory.md"


@dataclass(frozen=True)
class TheoremVerdict:
    """A cell or pair that a theorem of docs/controllability_theory.md makes impossible."""

    id: str          # the statement, e.g. "T2.3"
    anchor: str      # its section's anchor in DOC, e.g. "t2-steer-only"
    reason: str      # one sentence: why, with the numbers of the configuration

    @property
    def label(self) -> str:
        return f"impossible (theorem {self.id})"

    def link(self, base: str = "docs/") -> str:
        """The Markdown target of the statement's section (base: the folder of DOC as seen from the caller)."""
        return f"{base}{DOC}#{self.anchor}"


STEER = ("T2.3", "t2-steer-only")
DRIVE = ("T3.2", "t3-drive-only")


def _is_plane(scene) -> bool:
    return isinstance(scene.table, dict) and scene.table.get("kind") == "none"


def cell_theorem(scene, task) -> TheoremVerdict | None:
    """The theorem that makes every pair of this (Scene, Task) impossible, or None (the theory leaves it to
    witnesses). Drive only: the env draws targets at least `heading_offset` off the heading line (by rejection,
    with a fallback of probability below 1e-10 per episode, see docs/study_probes.md); use :func:`pair_theorem`
    to decide each drawn pair exactly."""
    if not _is_plane(scene):
        return None
    R = float(scene.params["R"])
    if scene.actuation == "steer" and task.kind == "park":
        lo, hi = scene.init["theta_dot"]
        slowest = 0.0 if lo <= 0.0 <= hi else min(abs(lo), abs(hi))
        if R * slowest >= task.speed_tolerance:
            return TheoremVerdict(*STEER, f"open plane, steering only: |R theta_dot| stays at its start value, at least "
                                          f"{R * slowest:g} m/s >= speed_tolerance {task.speed_tolerance:g} m/s")
    if scene.actuation == "drive" and task.kind in ("reach", "park"):
        if tuple(scene.init["phi_dot"]) == (0.0, 0.0) and task.heading_offset >= task.tolerance:
            return TheoremVerdict(*DRIVE, f"open plane, rolling only, phi_dot = 0: the contact point stays on its heading "
                                          f"line, targets are {task.heading_offset:g} m off it >= tolerance "
                                          f"{task.tolerance:g} m")
    return None


def pair_theorem(scene, task, state, target) -> TheoremVerdict | None:
    """The theorem that makes this start (x, y, theta, phi, theta_dot, phi_dot) and target (x, y) impossible
    under (Scene, Task), or None."""
    s = np.asarray(state, dtype=float)
    t = np.asarray(target, dtype=float)
    if s.shape != (6,) or not np.all(np.isfinite(s)):
        raise ValueError(f"state must be 6 finite numbers (x, y, theta, phi, theta_dot, phi_dot), got shape {s.shape}")
    if t.shape != (2,) or not np.all(np.isfinite(t)):
        raise ValueError(f"target must be 2 finite numbers (x, y), got shape {t.shape}")
    if not _is_plane(scene):
        return None
    R = float(scene.params["R"])
    if scene.actuation == "steer" and task.kind == "park" and abs(R * s[4]) >= task.speed_tolerance:
        return TheoremVerdict(*STEER, f"|R theta_dot| = {abs(R * s[4]):g} m/s >= speed_tolerance "
                                      f"{task.speed_tolerance:g} m/s forever")
    if scene.actuation == "drive" and task.kind in ("reach", "park") and s[5] == 0.0:
        off_line = abs(-(t[0] - s[0]) * math.sin(s[3]) + (t[1] - s[1]) * math.cos(s[3]))
        if off_line >= task.tolerance:
            return TheoremVerdict(*DRIVE, f"the target is {off_line:g} m off the heading line >= tolerance "
                                          f"{task.tolerance:g} m")
    return None


def resolve_id(env_id: str, **overrides):
    """(Scene, Task) of a registered id with field overrides (the way gymnasium.make(env_id, **overrides) builds it)."""
    from ..envs.scene import env_presets, resolve

    if not isinstance(env_id, str):
        raise TypeError(f"env_id must be a string, got {type(env_id).__name__}")
    presets = env_presets()
    if env_id not in presets:
        raise ValueError(f"env_id {env_id!r} is not a registered penny_env id (penny_env/presets/envs.yaml)")
    return resolve(**{**presets[env_id], **overrides})


def theorem_for(env_id: str, **overrides) -> TheoremVerdict | None:
    """:func:`cell_theorem` of a registered id with field overrides (table=..., law=...)."""
    return cell_theorem(*resolve_id(env_id, **overrides))
