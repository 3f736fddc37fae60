"""Rewards and termination of the tasks, written twice with the same formulas in the same order:
batched over (N,) numpy arrays (PennyVectorEnv) and for Python floats (PennyEnv's fast path).

Notation: d = |target - contact point| [m], d_prev its value before the step, L the scene's
length scale, v = |R theta_dot| the rolling speed [m/s], a the clipped action in [-1, 1]^k,
ctrl = sum(a^2) / k, n_arc the impacts of the step on the marked arc, count their running total.

========  ==========================================================================  ==================================
task      reward per step                                                             success (terminates the episode)
========  ==========================================================================  ==================================
reach     progress_weight (d_prev - d) / L - ctrl_cost ctrl + success_bonus [success]  d < tolerance
park      progress_weight (d_prev - d) / L - speed_cost v / v_ref [d < 2 tolerance]    d < tolerance and v < speed_tolerance
          - ctrl_cost ctrl + success_bonus [success]   (v_ref = R obs_scale.theta_dot)
impacts   impact_reward n_arc - ctrl_cost ctrl + success_bonus [success]               count >= impacts_goal
========  ==========================================================================  ==================================

An impact is on the arc when its impact point p (the end on the wall) satisfies
p . (cos beta, sin beta) >= cos(arc_half_width) |p| (beta: the arc's centre direction, drawn each
episode); with arc_half_width >= pi every impact counts.
"""
from __future__ import annotations

import math

import numpy as np

REACH, PARK, IMPACTS = 0, 1, 2
KIND_CODE = {"reach": REACH, "park": PARK, "impacts": IMPACTS}


class TaskConstants:
    """The floats the formulas need, taken once from (Scene, Task)."""

    def __init__(self, scene, task, L):
        self.kind = KIND_CODE[task.kind]
        self.L = float(L)
        self.tol = task.tolerance
        self.tol2 = 2.0 * task.tolerance
        self.vtol = task.speed_tolerance
        self.pw = task.progress_weight
        self.sc = task.speed_cost
        self.cc = task.ctrl_cost
        self.bonus = task.success_bonus
        self.ir = task.impact_reward
        self.goal = task.impacts_goal
        self.R = scene.params["R"]
        self.v_ref = self.R * scene.obs_scale["theta_dot"]
        self.all_arc = task.arc_half_width >= math.pi
        self.cos_hw = math.cos(min(task.arc_half_width, math.pi))


# -- batched --------------------------------------------------------------------------------
def on_arc(px, py, cb, sb, k: TaskConstants):
    """Boolean array: impact points (px, py) on the arc centred on direction (cb, sb)."""
    if k.all_arc:
        return np.ones(np.shape(px), dtype=bool)
    return px * cb + py * sb >= k.cos_hw * np.sqrt(px * px + py * py)


def reward_batch(k: TaskConstants, d_prev, d, W, ctrl, n_arc, count):
    """(reward, success) arrays."""
    if k.kind == IMPACTS:
        success = count >= k.goal
        r = k.ir * n_arc - k.cc * ctrl + k.bonus * success
        return r, success
    progress = k.pw * (d_prev - d) / k.L
    if k.kind == REACH:
        success = d < k.tol
        return progress - k.cc * ctrl + k.bonus * success, success
    v = np.abs(k.R * W)
    success = (d < k.tol) & (v < k.vtol)
    r = progress - k.sc * (v / k.v_ref) * (d < k.tol2) - k.cc * ctrl + k.bonus * success
    return r, success


# -- scalar ---------------------------------------------------------------------------------
def on_arc1(px, py, cb, sb, k: TaskConstants) -> bool:
    if k.all_arc:
        return True
    return px * cb + py * sb >= k.cos_hw * math.sqrt(px * px + py * py)


def reward1(k: TaskConstants, d_prev, d, W, ctrl, n_arc, count):
    """(reward, success) for one env, the same formulas as :func:`reward_batch`."""
    if k.kind == IMPACTS:
        success = count >= k.goal
        return k.ir * n_arc - k.cc * ctrl + k.bonus * success, success
    progress = k.pw * (d_prev - d) / k.L
    if k.kind == REACH:
        success = d < k.tol
        return progress - k.cc * ctrl + k.bonus * success, success
    v = abs(k.R * W)
    success = d < k.tol and v < k.vtol
    r = progress - k.sc * (v / k.v_ref) * (d < k.tol2) - k.cc * ctrl + k.bonus * success
    return r, success
