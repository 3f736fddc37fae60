"""Multiple shooting over the control rows, with exact derivatives through impacts.

The K control rows are cut into segments of at most ``SEGMENT_ROWS`` rows. The decision vector is
z = (v, x_1, ..., x_{S-1}): the scaled torques v = u / torque_limit of every row, then the states at the
starts of segments 2..S (the first starts at the problem's start). Each segment is simulated from its node
state with its rows (``rollout``); the continuity defects x_{j+1} - F_j(x_j, v_j) = 0 are equality
constraints, and the terminal and path constraints act on the last segment's end and on every segment's
samples. The derivatives of F_j with respect to the node state and the torques come from
``penny_env.simulate(..., sensitivities=True)`` (saltation matrices through every impact) when impacts are
allowed, and from the exact free-flow Jacobians (physics/sensitivity.flow_jacobians) when they are
forbidden. Nodes start on the trajectory of the initial torques, so the first iterate has no defects.

An iterate that puts a node outside the table (where the hybrid flow is undefined) gets non-finite values,
which the constraint functions turn into a large violation: SLSQP's line search then steps back.
"""
from __future__ import annotations

import math

import numpy as np

import penny_env as pe
from penny_env.physics.kernels import SCALAR, end_point
from penny_env.physics.scalar import flow_penny
from penny_env.physics.sensitivity import flow_jacobians

SEGMENT_ROWS = 10   # control rows per shooting segment
SUBSAMPLES = 1      # impacts forbidden: wall-distance samples inside each row (plus its end); checked densely after


def wall_values(prob, s):
    """h(end) for the front and back end of state s."""
    R = prob.params.R
    out = []
    for sigma in (1.0, -1.0):
        px, py, _, _ = end_point(s[0], s[1], s[3], s[4], s[5], sigma, R, SCALAR)
        out.append(float(prob.table.h(px, py)))
    return out


def wall_gradient(prob, s, sigma):
    """(h(end), d h(end) / d state) for end sigma."""
    R = prob.params.R
    c, sn = math.cos(s[3]), math.sin(s[3])
    px, py = s[0] + sigma * R * c, s[1] + sigma * R * sn
    hx, hy = (float(v) for v in prob.table.grad(px, py))
    g = np.zeros(6)
    g[0], g[1], g[3] = hx, hy, sigma * R * (hy * c - hx * sn)
    return float(prob.table.h(px, py)), g


def rollout(prob, v, start=None):
    """One shooting segment from `start` (default: the problem's start) with the scaled torque rows v (L, 2):
    (final state, d final / d v (6 x 2L), d final / d start (6 x 6), path samples (h (n,), dh/dv (n, 2L),
    dh/dstart (n, 6)) or None, valid, reason)."""
    L = v.shape[0]
    start = prob.start if start is None else np.asarray(start, dtype=float)
    u = v * prob.limits[None, :]
    scale = np.tile(prob.limits, L)  # du / dv
    if prob.impacts:
        try:
            tr = pe.simulate(start, params=prob.params, table=prob.table, law=prob.law, controls=u,
                             control_dt=prob.dt, sensitivities=True)
        except ValueError as exc:  # a node outside the table: no flow there
            nan = np.full((6, 6), np.nan)
            return np.full(6, np.nan), np.full((6, 2 * L), np.nan), nan, None, False, str(exc)
        return (tr.final_state, tr.control_jacobian * scale[None, :], tr.jacobian, None, tr.jacobian_valid,
                tr.jacobian_reason)
    # impacts forbidden: the free flow, chained row by row, with wall samples inside each row
    R, J, Itot = prob.params.R, prob.params.J, prob.params.rolling_inertia
    s = tuple(start)
    C = np.zeros((6, 2 * L))
    A = np.eye(6)
    hs, dh, dhx = [], [], []
    taus = prob.dt * np.arange(1, SUBSAMPLES + 2) / (SUBSAMPLES + 1)
    dacc = np.array([1.0 / J, 1.0 / Itot])
    for k in range(L):
        a1, a2 = u[k, 0] / J, u[k, 1] / Itot
        Phi, B = flow_jacobians(np.array(s), a1, a2, taus, R)
        Cs = Phi @ C  # (n, 6, 2L)
        Cs[:, :, 2 * k:2 * k + 2] += B * dacc[None, None, :]
        As = Phi @ A  # (n, 6, 6)
        G = np.empty((len(taus), 2, 6))
        for j, tau in enumerate(taus):
            st = flow_penny(s, a1, a2, tau, R)
            for e, sigma in enumerate((1.0, -1.0)):
                h, G[j, e] = wall_gradient(prob, st, sigma)
                hs.append(h)
        dh.append(np.einsum("jei,jik->jek", G, Cs).reshape(-1, 2 * L))
        dhx.append(np.einsum("jei,jik->jek", G, As).reshape(-1, 6))
        s, C, A = st, Cs[-1], As[-1]
    samples = (np.array(hs), np.concatenate(dh) * scale[None, :], np.concatenate(dhx))
    return np.array(s), C * scale[None, :], A, samples, True, ""


def segment_bounds(K: int, segment_rows: int | None = SEGMENT_ROWS) -> list[int]:
    """Row indices where the segments start, and K: [0, 10, 20, 25] for K = 25 and 10 rows a segment;
    segment_rows None: one segment (single shooting)."""
    L = K if segment_rows is None else segment_rows
    if isinstance(L, bool) or not isinstance(L, (int, np.integer)) or L < 1:
        raise ValueError(f"segment_rows must be a positive integer or None, got {segment_rows!r}")
    return list(range(0, K, L)) + [K]


class MultipleShooting:
    """The shooting functions of one problem over K rows, as functions of z = (v (2K), nodes (6 (S - 1))).
    segment_rows None (or >= K): one segment, i.e. single shooting, with no nodes and no defects."""

    def __init__(self, prob, K: int, segment_rows: int | None = SEGMENT_ROWS):
        self.prob, self.K = prob, K
        self.bounds_rows = segment_bounds(K, segment_rows)
        self.S = len(self.bounds_rows) - 1
        self.nv = 2 * K
        self.n = self.nv + 6 * (self.S - 1)
        self._key, self._val = None, None

    def initial(self, v):
        """z from scaled torques v (K, 2): nodes on the trajectory those torques give from the start (on the
        table; with impacts forbidden too, which is what any guess should look like)."""
        v = np.asarray(v, dtype=float).reshape(self.K, 2)
        nodes = []
        if self.S > 1:
            p = self.prob
            tr = pe.simulate(p.start, params=p.params, table=p.table, law=p.law, controls=v * p.limits[None, :],
                             control_dt=p.dt)
            nodes = [tr.states_at(np.array([b * p.dt]))[0] for b in self.bounds_rows[1:-1]]
        return np.concatenate([v.ravel()] + nodes)

    def node(self, z, j):
        return self.prob.start if j == 0 else z[self.nv + 6 * (j - 1): self.nv + 6 * j]

    def evaluate(self, z):
        """(final state, d final / dz, defects, d defects / dz, path h or None, d h / dz, valid, reason), cached
        for the last z."""
        key = z.tobytes()
        if key == self._key:
            return self._val
        S, n, b = self.S, self.n, self.bounds_rows
        defects, ddef = np.zeros(6 * (S - 1)), np.zeros((6 * (S - 1), n))
        hs, dhs = [], []
        valid, reason = True, ""
        for j in range(S):
            a, e = b[j], b[j + 1]
            F, Fv, Fx, samples, ok, why = rollout(self.prob, z[2 * a:2 * e].reshape(e - a, 2), self.node(z, j))
            if not ok and valid:
                valid, reason = False, why
            D = np.zeros((6, n))
            D[:, 2 * a:2 * e] = Fv
            if j > 0:
                D[:, self.nv + 6 * (j - 1): self.nv + 6 * j] = Fx
            if samples is not None:
                H = np.zeros((len(samples[0]), n))
                H[:, 2 * a:2 * e] = samples[1]
                if j > 0:
                    H[:, self.nv + 6 * (j - 1): self.nv + 6 * j] = samples[2]
                hs.append(samples[0])
                dhs.append(H)
            if j < S - 1:
                r = slice(6 * j, 6 * j + 6)
                defects[r] = self.node(z, j + 1) - F
                ddef[r] = -D
                ddef[r, self.nv + 6 * j: self.nv + 6 * j + 6] += np.eye(6)
            else:
                final, dfinal = F, D
        path = (np.concatenate(hs), np.concatenate(dhs)) if hs else (None, None)
        self._key, self._val = key, (final, dfinal, defects, ddef, path[0], path[1], valid, reason)
        return self._val
