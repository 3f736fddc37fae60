"""Trial calls of a task's stages before it is registered (penny_env.register_task), in plain Python, on the
default scene: a stage that cannot run, returns the wrong number or kind of values, a non-finite number, or
writes where it must not, is refused with a message naming the task and the stage, rather than failing later
inside an environment's build or, worse, running with NaN rewards.

* ``constants(scene, task, L)`` builds a NamedTuple of plain numbers (an exception is reported as the stage's);
* ``target`` returns four finite numbers (tx, ty, cos b, sin b) on fresh episodes, a target on the table (the
  observation's target entries within the observation space);
* ``reward`` returns (reward, success): a finite real number that fits a float64 (not an array, not a tuple of
  three) and a bool-like success;
* ``observation`` writes only its own entries (columns 10 to obs_dim - 1) of its own row, finite and within
  ``extra_obs``: it is called on a guarded array (rows around the env's, filled with NaN) and any other write is
  named; an index past the row raises and is reported as such;
* ``marked_arc`` returns three finite numbers.

A trial cannot prove a stage right everywhere: at run time, the step ends an episode whose reward is not finite,
whose target leaves the table (the observation's target entries outside the space) or whose own observation entries
leave their declared bounds (info["limit"] "task_output", step/functional.py), with a
warning naming the task.
"""
from __future__ import annotations

import math

import numpy as np

from ..physics.edits import globals_read
from ..physics.kernels import SCALAR
from ..physics.numbers import is_real
from ..physics.scalar import scalar_model
from ..step.draws import draw_stream, draw_uniform
from ..step.functional import PennyState, angle_trig, distance, env_params, observation
from ..step.tasks.base import check_constants

TRIALS = 16  # episodes (start states, targets) each stage is tried on


def _owner(record, stage) -> str:
    return f"register_task({record.name!r}): {stage}"


def _call(record, stage, f, *args):
    try:
        return f(*args)
    except Exception as exc:  # noqa: BLE001 (any failure of the user's function is reported as the stage's)
        raise ValueError(f"{_owner(record, stage)} raised {type(exc).__name__}: {exc}") from exc


def _numbers(record, stage, out, n, what) -> tuple:
    """out as n finite real numbers, else TypeError / ValueError naming the stage."""
    if not isinstance(out, tuple) or len(out) != n:
        got = f"{len(out)} values" if isinstance(out, tuple) else f"a {type(out).__name__}"
        raise TypeError(f"{_owner(record, stage)} must return {n} numbers ({what}), got {got}: {out!r}")
    for v in out:
        _finite(record, stage, v, what)
    return tuple(float(v) for v in out)


def _finite(record, stage, v, what) -> float:
    if isinstance(v, np.ndarray) and v.ndim > 0 or not (is_real(v) or isinstance(v, (bool, np.bool_))):
        raise TypeError(f"{_owner(record, stage)} must return real numbers ({what}), got {type(v).__name__} {v!r}")
    if isinstance(v, int) and not -(1 << 63) <= v < (1 << 63):
        raise ValueError(f"{_owner(record, stage)} returned the integer {v}, which the compiled step cannot hold "
                         "(int64); return a float")
    if not math.isfinite(float(v)):
        raise ValueError(f"{_owner(record, stage)} returned a non-finite number {v!r} ({what})")
    return float(v)


_TRIED: dict = {}  # id(record) -> (record, stage_globals(record) when its trials last passed)


def stage_globals(record) -> tuple:
    """The module globals the task's stages read (physics/edits.py): what an edit of a module constant changes."""
    return tuple(globals_read(f) for f in (record.constants, record.reward, record.target, record.observation,
                                           record.marked_arc) if f is not None)


def retry_if_edited(record) -> None:
    """The trials again where a registered task's stages read other module globals than when its trials passed (a
    module constant edited after register_task: the step would run it untried; an observation that now writes
    into the penny's entries, say); ValueError / TypeError as register_task's, saying why. Nothing for a record
    that was never tried (penny_env's own tasks, a record handed to a Core directly)."""
    entry = _TRIED.get(id(record))
    if entry is None or entry[0] is not record:
        return
    now = stage_globals(record)
    if now == entry[1]:
        return
    _TRIED[id(record)] = (record, now)  # (the trials' own Core sees the fingerprint it is trying)
    try:
        trial_task(record)
    except (TypeError, ValueError) as exc:
        del _TRIED[id(record)]
        raise type(exc)(f"{exc} (tried again: a module global that task {record.name!r}'s stages read changed "
                        "since register_task; register it again after an edit)") from None


def trial_task(record) -> None:
    """The trials of the module docstring on the default scene (the paper's ellipse); ValueError / TypeError
    naming the task and the stage. Passed, the globals its stages read are kept (:func:`retry_if_edited`)."""
    from .core import Core
    from .scene import Scene
    scene = Scene()
    task = record.config(kind=record.name)
    try:
        core = Core(scene, task, backend="python", record=record)
    except Exception as exc:  # noqa: BLE001
        raise ValueError(f"{_owner(record, 'constants')} failed on the default scene: {type(exc).__name__}: "
                         f"{exc}") from exc
    k = core.k
    check_constants(record, k)
    p = env_params(core)
    m = scalar_model(core.params, core.table, core.law, core.settings)
    lo, hi = core.obs_bounds()
    d = core.obs_dim
    for episode in range(TRIALS):
        base = draw_stream(np.uint64(0x9E3779B97F4A7C15 + episode), 0, SCALAR)
        r = 0.5 * p.spawn_fraction * math.sqrt(draw_uniform(base, 0, SCALAR))
        a = 2.0 * math.pi * draw_uniform(base, 1, SCALAR)
        s = (r * p.spawn_ax * math.cos(a), r * p.spawn_ay * math.sin(a), 0.0, 2.0 * math.pi * draw_uniform(base, 3, SCALAR),
             (p.theta_dot_lo + p.theta_dot_hi) / 2, (p.phi_dot_lo + p.phi_dot_hi) / 2)
        trig = angle_trig(s)
        tx, ty, cb, sb = _numbers(record, "target", _call(record, "target", record.target, k, p, m, s, trig, base, SCALAR),
                                  4, "tx, ty, cos b, sin b")
        before = PennyState(s, trig, (tx, ty), (cb, sb), 0, distance(s, (tx, ty)), episode, 0.05 * episode)
        seen = np.float32(observation(before, p)[8:10])  # (as the float32 observation holds them)
        if not ((seen >= lo[8:10]) & (seen <= hi[8:10])).all():
            raise ValueError(f"{_owner(record, 'target')} returned the target ({tx:.6g}, {ty:.6g}) m, which puts the "
                             f"observation's target entries obs[8:10] = {seen.tolist()} (the target relative to the "
                             f"contact point, in table sizes) outside the observation space's [{lo[8]:g}, {hi[8]:g}]: a "
                             "target must lie on the table")
        s1 = (s[0] + 1e-3, s[1] - 1e-3, s[2] + 0.1, s[3] + 0.05, s[4], s[5])
        after = PennyState(s1, angle_trig(s1), (tx, ty), (cb, sb), episode % 2, distance(s1, (tx, ty)), episode + 1,
                           0.05 * (episode + 1))
        out = _call(record, "reward", record.reward, k, before, after, 0.25, episode % 2, SCALAR)
        if not isinstance(out, tuple) or len(out) != 2:
            got = f"{len(out)} values" if isinstance(out, tuple) else f"a {type(out).__name__}"
            raise TypeError(f"{_owner(record, 'reward')} must return (reward, success), got {got}: {out!r}")
        _finite(record, "reward", out[0], "the reward")
        if isinstance(out[1], np.ndarray) and out[1].ndim > 0 or not isinstance(out[1], (bool, np.bool_, int, np.integer)):
            raise TypeError(f"{_owner(record, 'reward')}'s success must be a bool, got {type(out[1]).__name__} {out[1]!r}")
        if record.observation is not None:
            obs = np.full((3, d), np.nan, dtype=np.float32)
            _call(record, "observation", record.observation, k, after, obs, 1)
            touched = ~np.isnan(obs)
            own = np.zeros_like(touched)
            own[1, 10:] = True
            if (touched & ~own).any():
                row, col = (int(v) for v in np.argwhere(touched & ~own)[0])
                raise ValueError(f"{_owner(record, 'observation')} wrote obs[{row - 1:+d} rows, {col}] (row {row} of the "
                                 f"guarded array, env row 1): a task writes only its own entries, columns 10 to {d - 1} "
                                 f"of row i (declare more entries in extra_obs)")
            vals = obs[1, 10:]
            bad = np.flatnonzero(~((vals >= lo[10:]) & (vals <= hi[10:])))
            if bad.size:
                j = int(bad[0]) + 10
                raise ValueError(f"{_owner(record, 'observation')} wrote obs[i, {j}] = {float(obs[1, j])!r}, outside its "
                                 f"declared bounds extra_obs[{j - 10}] = {record.extra_obs[j - 10]} (or left it unwritten)")
        if record.marked_arc is not None:
            _numbers(record, "marked_arc", _call(record, "marked_arc", record.marked_arc, k, after), 3,
                     "cos b, sin b, cos half-width")
    _TRIED[id(record)] = (record, stage_globals(record))
