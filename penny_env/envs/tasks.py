"""Rewards and termination of the tasks, written once for the one env step (envs/functional.py):
Python floats (backend "python") and compiled code (numba), in the style of physics/kernels.py:
the math namespace ``xp`` comes last (kernels.SCALAR, or numba_math when compiled; numpy's
kernels.ARRAY works too, for arrays over envs).

Notation: d = |target - contact point| [m], d_prev its value before the step, L the scene's
length scale, v = |R theta_dot| the rolling speed [m/s], a the clipped action in [-1, 1]^k,
ctrl = sum(a^2) / k, n_arc the impacts of the step on the marked arc, count their running total.

========  ==========================================================================  ==================================
task      reward per step                                                             success (terminates the episode)
========  ==========================================================================  ==================================
reach     progress_weight (d_prev - d) / L - ctrl_cost ctrl + success_bonus [success]  d < tolerance
park      progress_weight (d_prev - d) / L - speed_cost v / v_ref [d < 2 tolerance]    d < tolerance and v < speed_tolerance
          - ctrl_cost ctrl + success_bonus [success]   (v_ref = R obs_scale.theta_dot)      (and |phi_dot| < spin_tolerance
                                                                                       when the task sets one)
impacts   impact_reward n_arc - ctrl_cost ctrl + success_bonus [success]               count >= impacts_goal
========  ==========================================================================  ==================================

An impact is on the arc when its impact point p (the end on the wall) satisfies
p . (cos beta, sin beta) >= cos(arc_half_width) |p| (beta: the arc's centre direction, drawn each
episode); with arc_half_width >= pi every impact counts.
"""
from __future__ import annotations

import math
from typing import NamedTuple

from ..physics.kernels import SCALAR

REACH, PARK, IMPACTS = 0, 1, 2
KIND_CODE = {"reach": REACH, "park": PARK, "impacts": IMPACTS}


class TaskConstants(NamedTuple):
    """The numbers the formulas need, taken once from (Scene, Task) by :func:`task_constants`
    (plain numbers, so compiled code takes them too)."""

    kind: int
    L: float
    tol: float
    tol2: float
    vtol: float
    wtol: float      # |phi_dot| bound of park's rest (inf: not checked)
    pw: float
    sc: float
    cc: float
    bonus: float
    ir: float
    goal: int
    R: float
    v_ref: float
    all_arc: bool
    cos_hw: float


def task_constants(scene, task, L) -> TaskConstants:
    return TaskConstants(
        kind=KIND_CODE[task.kind], L=float(L), tol=float(task.tolerance), tol2=2.0 * task.tolerance,
        vtol=float(task.speed_tolerance),
        wtol=math.inf if task.spin_tolerance is None else float(task.spin_tolerance), pw=float(task.progress_weight), sc=float(task.speed_cost),
        cc=float(task.ctrl_cost), bonus=float(task.success_bonus), ir=float(task.impact_reward),
        goal=int(task.impacts_goal), R=float(scene.params["R"]), v_ref=scene.params["R"] * scene.obs_scale["theta_dot"],
        all_arc=bool(task.arc_half_width >= math.pi), cos_hw=math.cos(min(task.arc_half_width, math.pi)))


def on_arc(px, py, cb, sb, k: TaskConstants, xp=SCALAR):
    """Impact points (px, py) on the arc centred on direction (cb, sb) (a bool)."""
    if k.all_arc:  # every impact point counts (they are finite), as a bool of px's shape
        return xp.abs(px) < xp.inf
    return px * cb + py * sb >= k.cos_hw * xp.sqrt(px * px + py * py)


def step_reward(k: TaskConstants, d_prev, d, W, w, ctrl, n_arc, count, xp=SCALAR):
    """(reward, success) of one step; W, w: theta_dot and phi_dot after it."""
    if k.kind == IMPACTS:
        success = count >= k.goal
        return k.ir * n_arc - k.cc * ctrl + k.bonus * success, success
    progress = k.pw * (d_prev - d) / k.L
    if k.kind == REACH:
        success = d < k.tol
        return progress - k.cc * ctrl + k.bonus * success, success
    v = xp.abs(k.R * W)
    success = (d < k.tol) & (v < k.vtol) & (xp.abs(w) < k.wtol)
    r = progress - k.sc * (v / k.v_ref) * (d < k.tol2) - k.cc * ctrl + k.bonus * success
    return r, success
