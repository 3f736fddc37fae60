"""Batched event loop: advance many pennies over one control interval, impacts included.

Each round finds every active penny's first impact (events.first_impact), flows the ones
without an impact to the end of the interval, and for the others flows to the impact, relocates
the ends onto the wall if round-off left them a hair outside, applies the impact law and goes
on. Rounds run over the shrinking set of pennies that still have impacts to process: the loop
is over events, never over pennies.

Degenerate cases end in a defined state (documented in docs/physics.md):
* an end on the wall still moving outward after the law (plastic with I > m R^2): the normal
  velocity is removed (laws.apply_law);
* accumulation (Zeno), including both ends wedged against the wall: zeno_impacts consecutive
  impacts each within max(zeno_window, 8 sqrt(2 delta / M)) of the previous one (a few time
  resolutions of the search, below which impact gaps cannot shrink in float64), or
  max_events_per_interval impacts in one interval, bring the penny to rest (theta_dot = phi_dot = 0). If the controls then push an
  end that touches the wall outward, the penny stays pinned until the interval ends.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .flow import X, Y, PHI, THETA_DOT, PHI_DOT, flow, end_kinematics
from .events import first_impact, wall_value
from .kernels import acceleration_bound, time_resolution
from .laws import apply_law


@dataclass
class EventLog:
    """Impacts of a batch over one interval, sorted by penny then time.

    env: penny index; time: time since the interval start; end: +1 front / -1 back;
    state: (k, 6) states right after each impact; rest_env / rest_time / rest_pinned: pennies brought to rest (and held by the controls).
    """

    env: np.ndarray
    time: np.ndarray
    end: np.ndarray
    state: np.ndarray
    rest_env: np.ndarray
    rest_time: np.ndarray
    rest_pinned: np.ndarray

    @staticmethod
    def empty() -> "EventLog":
        return EventLog(np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int8), np.zeros((0, 6)),
                        np.zeros(0, np.int64), np.zeros(0), np.zeros(0, bool))

    def counts(self, n: int) -> np.ndarray:
        return np.bincount(self.env, minlength=n)


def relocate_inside(s, params, table):
    """Move contact points so that neither end is outside the wall (round-off repairs only)."""
    for sigma in (1.0, -1.0):
        px, py, _, _ = end_kinematics(s, sigma, params.R)
        g = table.h(px, py)
        out = g > 0.0
        if out.any():
            hx, hy = table.grad(px[out], py[out])
            k = g[out] / (hx * hx + hy * hy)
            s[X, out] -= k * hx
            s[Y, out] -= k * hy
    return s


def _pushes_out(s, acc1, acc2, params, table, delta):
    """At rest, would the controls drive an end that touches the wall outward?"""
    c, sn = np.cos(s[PHI]), np.sin(s[PHI])
    res = np.zeros(s.shape[1], dtype=bool)
    for sigma in (1.0, -1.0):
        px, py, _, _ = end_kinematics(s, sigma, params.R)
        hx, hy = table.grad(px, py)
        ax = params.R * (acc2 * c - sigma * acc1 * sn)
        ay = params.R * (acc2 * sn + sigma * acc1 * c)
        res |= (table.h(px, py) >= -delta) & (hx * ax + hy * ay > 0.0)
    return res


def advance(s, acc1, acc2, dt, params, table, law, settings, stop_after=None):
    """Advance (6, N) states by dt (scalar or (N,)) with constant angular accelerations.

    Returns (new_states, log, elapsed): elapsed equals dt except for pennies stopped early by
    stop_after (a per-call impact count at which a penny stops right after its impact).
    """
    s = np.array(s, dtype=float)
    n = s.shape[1]
    acc1 = np.broadcast_to(np.asarray(acc1, dtype=float), (n,))
    acc2 = np.broadcast_to(np.asarray(acc2, dtype=float), (n,))
    dt = np.broadcast_to(np.asarray(dt, dtype=float), (n,)).copy()
    if table is None:
        return flow(s, acc1, acc2, dt, params.R), EventLog.empty(), dt
    elapsed = np.zeros(n)
    n_events = np.zeros(n, dtype=np.int64)
    streak = np.zeros(n, dtype=np.int64)
    delta = settings.contact_tol * table.size
    logs = []
    rests = []
    act = np.flatnonzero(dt > 0.0)
    while act.size:
        rem = dt[act] - elapsed[act]
        t_hit, end = first_impact(s[:, act], acc1[act], acc2[act], rem, params, table, settings)
        free = end == 0
        if free.any():
            i = act[free]
            s[:, i] = flow(s[:, i], acc1[i], acc2[i], rem[free], params.R)
            elapsed[i] = dt[i]
        resume = end == 2  # search budget spent on a tangency: continue from the certified time
        if resume.any():
            i = act[resume]
            s[:, i] = relocate_inside(flow(s[:, i], acc1[i], acc2[i], t_hit[resume], params.R), params, table)
            elapsed[i] += t_hit[resume]
        hit = (end == 1) | (end == -1)
        if not hit.any():
            act = act[resume]
            continue
        j = act[hit]
        th = t_hit[hit]
        pre = relocate_inside(flow(s[:, j], acc1[j], acc2[j], th, params.R), params, table)
        hit_end = end[hit]
        # a grazing touch whose normal velocity has turned inward by the impact time is no impact
        touch = wall_value(pre, hit_end.astype(float), params, table)[1] <= 0.0
        if touch.any():
            i = j[touch]
            s[:, i] = pre[:, touch]
            elapsed[i] += th[touch]
            keep = ~touch
            j, th, pre, hit_end = j[keep], th[keep], pre[:, keep], hit_end[keep]
        post = apply_law(pre, hit_end.astype(float), params, table, law)
        elapsed[j] += th
        t_impact = elapsed[j].copy()
        n_events[j] += 1
        M = acceleration_bound(pre[THETA_DOT], pre[THETA_DOT] + acc2[j] * (dt[j] - elapsed[j]), pre[PHI_DOT],
                               pre[PHI_DOT] + acc1[j] * (dt[j] - elapsed[j]), acc1[j], acc2[j], params.R,
                               table.grad_bound, table.hessian_bound)
        window = np.maximum(settings.zeno_window, 8.0 * time_resolution(delta, M))
        streak[j] = np.where(th < window, streak[j] + 1, 0)
        stuck = (streak[j] >= settings.zeno_impacts) | (n_events[j] >= settings.max_events_per_interval)
        done = np.zeros(j.shape[0], dtype=bool)
        if stuck.any():
            post[THETA_DOT, stuck] = 0.0
            post[PHI_DOT, stuck] = 0.0
            streak[j[stuck]] = 0
            pinned = stuck & _pushes_out(post, acc1[j], acc2[j], params, table, 64 * delta)
            done |= pinned
            rests.append((j[stuck], t_impact[stuck], pinned[stuck]))
            elapsed[j[pinned]] = dt[j[pinned]]
        logs.append((j, t_impact, hit_end.copy(), post.T.copy()))
        if stop_after is not None:
            done |= n_events[j] >= stop_after
        s[:, j] = post
        act = np.concatenate([act[resume], act[hit][touch], j[~done]])
        act.sort()
    if not logs:
        log = EventLog.empty()
    else:
        env = np.concatenate([l[0] for l in logs])
        order = np.argsort(env, kind="stable")
        log = EventLog(env[order], np.concatenate([l[1] for l in logs])[order],
                       np.concatenate([l[2] for l in logs])[order], np.concatenate([l[3] for l in logs])[order],
                       *(np.concatenate([r[k] for r in rests]) for k in range(3)) if rests else
                       (np.zeros(0, np.int64), np.zeros(0), np.zeros(0, bool)))
    return s, log, elapsed
