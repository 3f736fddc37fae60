"""Dynamics of many pennies at once, on the batched physics (penny_env.batch): reachable sets under
piecewise-constant controls and finite-time Lyapunov exponents of the free penny.

* :func:`reachable_set`: the states reached at a horizon from one initial state by many random
  piecewise-constant torque sequences (one penny per sequence, all simulated together).
* :func:`lyapunov_exponents`: for many initial states, the growth rate of the distance between
  the penny and a copy perturbed by ``eps`` (both simulated together), fitted where the distance
  is still small (finite-time largest Lyapunov exponent).

The report (``python -m studies.dynamics``) tables the exponents on the circle, the paper's ellipse and a
stadium (elastic impacts) and draws reachable sets.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import batch
from ..physics import PennyParams, make_table

ACTUATIONS = {"both": (1.0, 1.0), "steer": (1.0, 0.0), "drive": (0.0, 1.0)}


@dataclass
class ReachableSet:
    """final_states (n, 6) reached at ``horizon``; impact_counts (n,); controls (K, n, 2) [N m]."""

    final_states: np.ndarray
    impact_counts: np.ndarray
    controls: np.ndarray
    horizon: float

    def speed_ranges(self) -> dict:
        """min and max of theta_dot and phi_dot over the set."""
        W, w = self.final_states[:, 4], self.final_states[:, 5]
        return {"theta_dot": (float(W.min()), float(W.max())), "phi_dot": (float(w.min()), float(w.max()))}


def random_controls(n: int, steps: int, *, actuation="both", torque_limits=(6.25e-7, 1.5e-5), seed=0) -> np.ndarray:
    """(steps, n, 2) torques, each held for one control period: +-limit at random (bang-bang), 0
    for the torques the actuation lacks ("both", "steer" = u1 only, "drive" = u2 only)."""
    if actuation not in ACTUATIONS:
        raise ValueError(f"actuation must be one of {sorted(ACTUATIONS)}, got {actuation!r}")
    limits = np.asarray(torque_limits, dtype=float)
    if limits.shape != (2,) or not np.all(np.isfinite(limits)) or np.any(limits < 0):
        raise ValueError(f"torque_limits must be two finite non-negative torques (u1, u2), got {torque_limits!r}")
    rng = np.random.default_rng(seed)
    signs = rng.choice((-1.0, 1.0), size=(steps, n, 2))
    return signs * limits * np.array(ACTUATIONS[actuation])


def reachable_set(state, horizon: float, *, table, law="elastic", actuation="both", torque_limits=(6.25e-7, 1.5e-5),
                  control_dt=0.05, n_samples=1000, seed=0, params=None) -> ReachableSet:
    """States reached at ``horizon`` from ``state`` by ``n_samples`` random bang-bang control
    sequences (:func:`random_controls`), simulated together with every impact."""
    state = np.asarray(state, dtype=float)
    if state.shape != (6,):
        raise ValueError(f"state must be one (x, y, theta, phi, theta_dot, phi_dot) row, got shape {state.shape}")
    if isinstance(n_samples, bool) or not isinstance(n_samples, (int, np.integer)) or n_samples < 1:
        raise ValueError(f"n_samples must be a positive integer, got {n_samples!r}")
    if not (np.isfinite(horizon) and horizon > 0):
        raise ValueError(f"horizon must be a positive number of seconds, got {horizon!r}")
    if not (np.isfinite(control_dt) and control_dt > 0):
        raise ValueError(f"control_dt must be a positive number of seconds, got {control_dt!r}")
    steps = int(np.ceil(horizon / control_dt - 1e-12))
    u = random_controls(int(n_samples), steps, actuation=actuation, torque_limits=torque_limits, seed=seed)
    res = batch.simulate(np.repeat(state[None, :], n_samples, axis=0), params=params, table=table, law=law,
                         t_final=horizon, controls=u, control_dt=control_dt)
    return ReachableSet(res.final_states, res.impact_counts, u, float(horizon))


@dataclass
class LyapunovResult:
    """times (T,); log_distance (T, N): log of the scaled distance between each penny and its
    perturbed copy; exponents (N,) [1/s] (NaN where fewer than ``min_points`` small distances)."""

    times: np.ndarray
    log_distance: np.ndarray
    exponents: np.ndarray


def state_distance(A, B, length, speed) -> np.ndarray:
    """Distance between (N, 6) rows in the coordinates that steer the motion: contact point / length,
    heading phi (wrapped) and the angular speeds / speed. theta, a cyclic coordinate, is left out."""
    dphi = np.angle(np.exp(1j * (A[:, 3] - B[:, 3])))
    d = np.stack([(A[:, 0] - B[:, 0]) / length, (A[:, 1] - B[:, 1]) / length, dphi,
                  (A[:, 4] - B[:, 4]) / speed, (A[:, 5] - B[:, 5]) / speed])
    return np.sqrt((d * d).sum(axis=0))


def lyapunov_exponents(states, t_final: float, *, table, law="elastic", eps=1e-10, n_checkpoints=60,
                       saturation=1e-4, min_points=8, seed=0, params=None) -> LyapunovResult:
    """Finite-time largest Lyapunov exponents of the free penny (no torques) from (N, 6) states.

    Each penny gets a copy whose angular speeds differ by ``eps`` (relative, random direction);
    both are simulated together to ``t_final`` and their distance (:func:`state_distance`) is
    sampled at ``n_checkpoints`` times. The exponent is the least-squares slope of log distance
    against time over the samples below ``saturation`` (before the copies separate macroscopically).
    Integrable motion (open plane, circle) gives exponents near 0 that shrink as t_final grows;
    chaotic motion a positive exponent."""
    params = params if params is not None else PennyParams()
    S = np.atleast_2d(np.asarray(states, dtype=float))
    if S.ndim != 2 or S.shape[1] != 6:
        raise ValueError(f"states must be (N, 6) rows, got shape {np.shape(states)}")
    if not (np.isfinite(t_final) and t_final > 0):
        raise ValueError(f"t_final must be a positive number of seconds, got {t_final!r}")
    if not (np.isfinite(eps) and 0 < eps < 1e-3):
        raise ValueError(f"eps must be in (0, 1e-3), got {eps!r}")
    if isinstance(n_checkpoints, bool) or not isinstance(n_checkpoints, (int, np.integer)) or n_checkpoints < 2:
        raise ValueError(f"n_checkpoints must be an integer >= 2, got {n_checkpoints!r}")
    n = S.shape[0]
    tab = make_table(table)
    length = tab.size if tab is not None else 1.0
    speed = np.maximum(np.hypot(S[:, 4], S[:, 5]), 1e-12)
    a = np.random.default_rng(seed).uniform(0, 2 * np.pi, n)
    P = S.copy()
    P[:, 4] += eps * speed * np.cos(a)
    P[:, 5] += eps * speed * np.sin(a)
    both = np.concatenate([S, P])
    times = np.linspace(0.0, t_final, n_checkpoints + 1)[1:]
    logd = np.empty((n_checkpoints, n))
    t = 0.0
    for k, tk in enumerate(times):
        both = batch.simulate(both, params=params, table=table, law=law, t_final=tk - t).final_states
        t = tk
        logd[k] = np.log(np.maximum(state_distance(both[:n], both[n:], length, speed), 1e-300))
    exps = np.full(n, np.nan)
    small = logd < np.log(saturation)
    for i in range(n):  # a line fit per penny (N small fits, not the physics)
        m = small[:, i]
        if m.sum() >= min_points:
            exps[i] = np.polyfit(times[m], logd[m, i], 1)[0]
    return LyapunovResult(times, logd, exps)


# -- report -------------------------------------------------------------------------------------------
def initial_states(table, n, rng, params):
    """n states inside the table near its centre, rolling at 5 to 15 rad/s, turning at -1 to 1 rad/s."""
    tab = make_table(table)
    r = 0.3 * (tab.inradius - params.R)
    ang = rng.uniform(0, 2 * np.pi, n)
    S = np.zeros((n, 6))
    S[:, 0], S[:, 1] = r * rng.uniform(0, 1, n) * np.cos(ang), r * rng.uniform(0, 1, n) * np.sin(ang)
    S[:, 2] = rng.uniform(-np.pi, np.pi, n)
    S[:, 3] = rng.uniform(-np.pi, np.pi, n)
    S[:, 4] = rng.uniform(5, 15, n) * rng.choice((-1, 1), n)
    S[:, 5] = rng.uniform(-1, 1, n)
    return S
