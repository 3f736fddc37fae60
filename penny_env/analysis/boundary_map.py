"""The penny's boundary (Birkhoff) map and its tangent dynamics, from the exact physics.

Between impacts the uncontrolled penny's speeds are constant; in the scaled speeds
(u, w) = (sqrt(I + m R^2) theta_dot, sqrt(J) phi_dot) the kinetic energy is rho^2 / 2 and
scaling both speeds only rescales time. At an impact the end sigma (+1 front, -1 back) is on the
wall at the point p; the boundary map is the map from one post-impact state to the next, in the
coordinates (all three unchanged by relabelling the penny's ends, phi -> phi + pi, theta_dot ->
-theta_dot, sigma -> -sigma):

* s: arc length of p along the wall from the positive x axis (counter-clockwise), over the perimeter;
* beta: angle from the wall's outward normal at p to the direction sigma (cos phi, sin phi) from the
  contact point to the end on the wall, in [-pi/2, pi/2] (the end on the wall is the outermost point);
* psi = atan2(w, sigma u): the spin ratio, an angle on the energy circle (psi = 0: rolling towards
  the wall-side end without turning).

The end's outward normal speed is v_n = R rho (cos psi cos beta / sqrt(I + m R^2) - sin psi sin beta
/ sqrt(J)) (negative after an impact). :func:`iterate` runs many orbits impact by impact on the
batched compiled physics (penny_env.batch: first_impact, flow, impact_map), rescaling the speeds
to the starting metric speed after each impact (an exact symmetry: the orbit in (s, beta, psi) is
unchanged, only time is rescaled), so that dissipative laws can be followed for thousands of
impacts. :func:`tangent_maps` gives, per impact, the exact Jacobians (the flow's, penny_env's
sensitivity code: physics/sensitivity.py) of the flow map over one flight plus impact (saltation
matrix) and of the return map, reduced to (x, y, phi, theta_dot, phi_dot) (theta is cyclic).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import batch
from ..physics import PennyParams, make_law, make_table
from ..physics.scalar import flow_penny
from ..physics.sensitivity import GRAZING_SPEED, flow_jacobian, impact_linearisation, vector_field

REDUCED = [0, 1, 3, 4, 5]  # x, y, phi, theta_dot, phi_dot: theta never enters the dynamics
HORIZON = 1e3  # [s] longest flight searched: an orbit with no impact within it circles clear of the wall


def metric_speed(states, params) -> np.ndarray:
    """rho = sqrt((I + m R^2) theta_dot^2 + J phi_dot^2) of (N, 6) rows: the energy is rho^2 / 2."""
    S = np.asarray(states, dtype=float)
    return np.sqrt(params.rolling_inertia * S[..., 4] * S[..., 4] + params.J * S[..., 5] * S[..., 5])


class WallChart:
    """Normalised arc length along a star-shaped (about the origin) table's wall: s(p) in [0, 1)."""

    def __init__(self, table, n: int = 20000):
        self.table = make_table(table)
        self._ang = np.linspace(0.0, 2 * np.pi, n + 1)
        rho = self.table.wall_distance(np.cos(self._ang), np.sin(self._ang))
        pts = np.stack([rho * np.cos(self._ang), rho * np.sin(self._ang)], axis=1)
        arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
        self.perimeter = float(arc[-1])
        self._s = arc / self.perimeter

    def s(self, px, py) -> np.ndarray:
        return np.interp(np.mod(np.arctan2(py, px), 2 * np.pi), self._ang, self._s) % 1.0

    def point(self, s) -> tuple[np.ndarray, np.ndarray]:
        """The wall point at normalised arc length s (exact on the wall: along the ray at its angle)."""
        ang = np.interp(np.mod(s, 1.0), self._s, self._ang)
        rho = self.table.wall_distance(np.cos(ang), np.sin(ang))
        return rho * np.cos(ang), rho * np.sin(ang)


def wall_frame(states, ends, table, params):
    """(px, py, nx, ny): the end on the wall and the unit outward normal there, for (N, 6) rows."""
    S = np.asarray(states, dtype=float)
    sig = np.asarray(ends, dtype=float)
    px = S[:, 0] + sig * params.R * np.cos(S[:, 3])
    py = S[:, 1] + sig * params.R * np.sin(S[:, 3])
    hx, hy = table.grad(px, py)
    g = np.hypot(hx, hy)
    return px, py, hx / g, hy / g


def boundary_coordinates(states, ends, table, params, chart=None):
    """(s, beta, psi, v_n / (R rho)) of (N, 6) states whose end ``ends`` (+1/-1) is on the wall (module
    docstring); v_n / (R rho) is the normal speed per unit metric speed, negative after an impact."""
    tab = make_table(table)
    chart = chart if chart is not None else WallChart(tab)
    S = np.asarray(states, dtype=float)
    sig = np.asarray(ends, dtype=float)
    px, py, nx, ny = wall_frame(S, sig, tab, params)
    ex, ey = sig * np.cos(S[:, 3]), sig * np.sin(S[:, 3])  # from the contact point to the end on the wall
    beta = np.arctan2(nx * ey - ny * ex, nx * ex + ny * ey)
    u, w = np.sqrt(params.rolling_inertia) * S[:, 4], np.sqrt(params.J) * S[:, 5]
    psi = np.arctan2(w, sig * u)
    return chart.s(px, py), beta, psi, normal_speed_density(beta, psi, params)


def normal_speed_density(beta, psi, params) -> np.ndarray:
    """v_n / (R rho): the end's outward normal speed per unit metric speed at (beta, psi); |.| is the
    density of the elastic boundary map's invariant measure in (s, beta, psi) (docs/billiards.md)."""
    return (np.cos(psi) * np.cos(beta) / np.sqrt(params.rolling_inertia)
            - np.sin(psi) * np.sin(beta) / np.sqrt(params.J))


def section_states(s, beta, psi, rho, table, params, chart=None) -> np.ndarray:
    """(N, 6) post-impact states with the front end (sigma = +1) on the wall at (s, beta, psi) and metric
    speed rho (theta = 0). They must move inwards (normal_speed_density < 0)."""
    tab = make_table(table)
    chart = chart if chart is not None else WallChart(tab)
    px, py = chart.point(np.asarray(s, dtype=float))
    hx, hy = tab.grad(px, py)
    phi = np.arctan2(hy, hx) + beta
    S = np.zeros((px.size, 6))
    S[:, 0], S[:, 1] = px - params.R * np.cos(phi), py - params.R * np.sin(phi)
    S[:, 3] = phi
    S[:, 4] = rho * np.cos(psi) / np.sqrt(params.rolling_inertia)
    S[:, 5] = rho * np.sin(psi) / np.sqrt(params.J)
    return S


def sample_invariant(n, table, rng, params, rho, chart=None, max_spin=None):
    """n states drawn from the elastic boundary map's invariant measure |v_n| ds dbeta dpsi (rejection from
    uniform (s, beta, psi); only inward-moving states with the other end inside the table): (states, s, beta, psi).
    max_spin: the measure restricted to |sin psi| <= max_spin (rolling-dominated states)."""
    tab = make_table(table)
    chart = chart if chart is not None else WallChart(tab)
    top = 1.0 / np.sqrt(params.J) + 1.0 / np.sqrt(params.rolling_inertia)
    out = []
    got = 0
    while got < n:
        m = (4 if max_spin is None else 400) * (n - got) + 64
        s, beta, psi = rng.uniform(0, 1, m), rng.uniform(-np.pi / 2, np.pi / 2, m), rng.uniform(-np.pi, np.pi, m)
        dens = normal_speed_density(beta, psi, params)
        keep = (dens < 0) & (rng.uniform(0, top, m) < -dens)
        if max_spin is not None:
            keep &= np.abs(np.sin(psi)) <= max_spin
        s, beta, psi = s[keep], beta[keep], psi[keep]
        S = section_states(s, beta, psi, rho, tab, params, chart)
        back = np.asarray(tab.h(S[:, 0] - params.R * np.cos(S[:, 3]), S[:, 1] - params.R * np.sin(S[:, 3]))) < 0
        out.append((S[back], s[back], beta[back], psi[back]))
        got += int(back.sum())
    S, s, beta, psi = (np.concatenate(x)[:n] for x in zip(*out))
    return S, s, beta, psi


@dataclass
class Orbits:
    """n orbits of the boundary map, impact by impact. Index k = 0 is the start (a state on the wall,
    end ends[0]); k >= 1 the state right after the k-th impact, rescaled to the start's metric speed.

    post (K+1, N, 6); ends (K+1, N); flight (K, N): flight time before impact k+1 at the rescaled speed;
    speed_ratio (K, N): metric speed after / before impact k+1 (1 elastic); restitution (K, N): -v_n after /
    v_n before impact k+1 (the law's effective coefficient); alive (K+1, N): False from the first state that
    never reaches the wall again (an orbit circling clear of the wall) or a grazing impact on (no derivative)."""

    post: np.ndarray
    ends: np.ndarray
    flight: np.ndarray
    speed_ratio: np.ndarray
    restitution: np.ndarray
    alive: np.ndarray
    table: object
    law: object
    params: PennyParams


def iterate(states, ends, n_impacts, *, table, law, params=None, rescale=True) -> Orbits:
    """Follow the boundary map from (N, 6) post-impact states (end ``ends`` on the wall) for n_impacts
    impacts, all orbits together on the batched compiled physics. rescale: bring the speeds back to the
    start's metric speed after each impact (exact symmetry; without it a dissipative orbit's flights grow
    without bound)."""
    params = params if params is not None else PennyParams()
    tab = make_table(table)
    law = make_law(law)
    S = np.array(states, dtype=float)
    n = S.shape[0]
    rho0 = metric_speed(S, params)
    K = int(n_impacts)
    post = np.empty((K + 1, n, 6))
    end_arr = np.zeros((K + 1, n), dtype=np.int8)
    flight = np.full((K, n), np.nan)
    ratio = np.full((K, n), np.nan)
    rest = np.full((K, n), np.nan)
    alive = np.ones((K + 1, n), dtype=bool)
    post[0] = S
    end_arr[0] = ends
    search = _searcher(params, tab)
    for k in range(K):
        live = alive[k]
        if not live.any():  # every orbit has stopped
            post[k + 1:] = S
            break
        t_hit, end = search(S[live])
        idx = np.flatnonzero(live)
        hit = end != 0
        alive[k + 1:, idx[~hit]] = False
        idx, t_hit, end = idx[hit], t_hit[hit], end[hit]
        pre = batch.flow(S[idx], (0.0, 0.0), t_hit, params=params)
        new = batch.impact_map(pre, end, params=params, table=tab, law=law)
        _, _, _, vn_pre = boundary_coordinates(pre, end, tab, params, chart=_NoChart())
        _, _, _, vn_post = boundary_coordinates(new, end, tab, params, chart=_NoChart())
        ok = params.R * vn_pre * metric_speed(pre, params) > GRAZING_SPEED * np.hypot(*_end_velocity(pre, end, params))
        alive[k + 1:, idx[~ok]] = False
        before, after = metric_speed(pre, params), metric_speed(new, params)
        flight[k, idx], ratio[k, idx] = t_hit, after / before
        rest[k, idx] = -(vn_post * after) / (vn_pre * before)
        if rescale:
            new[:, 4:] *= (rho0[idx] / after)[:, None]
        S[idx] = new
        post[k + 1] = S
        end_arr[k + 1, idx] = end
    return Orbits(post, end_arr, flight, ratio, rest, alive, tab, law, params)


def _searcher(params, tab):
    """The first-impact search for (N, 6) rows within HORIZON: the compiled batch kept for the whole run
    (batch.first_impact builds and warms up a new one per call, about 10 ms) where numba is installed."""
    from ..backends.batch import CompiledBatch
    from ..backends.choice import choose_backend
    from ..physics.params import DEFAULT_SETTINGS
    from ..backends.pennies import FIRST_IMPACT_ROUNDS

    law = make_law("elastic")  # the search does not depend on the law
    if choose_backend("auto", tab, python="python") != "numba":
        return lambda S: batch.first_impact(S, (0.0, 0.0), HORIZON, params=params, table=tab)
    cb = CompiledBatch(params, tab, law, DEFAULT_SETTINGS)

    def search(S):
        zero = np.zeros(S.shape[0])
        return cb.first_impacts(S.T, zero, zero, np.full(S.shape[0], HORIZON), FIRST_IMPACT_ROUNDS)
    return search


class _NoChart:
    """boundary_coordinates without arc length (the iteration needs only the normal speeds)."""

    def s(self, px, py):
        return np.zeros_like(px)


def _end_velocity(S, ends, params):
    R = params.R
    c, sn = np.cos(S[:, 3]), np.sin(S[:, 3])
    return R * S[:, 4] * c - ends * R * S[:, 5] * sn, R * S[:, 4] * sn + ends * R * S[:, 5] * c


def coordinates(orb: Orbits, chart=None):
    """(s, beta, psi, v_n / (R rho)) (K+1, N) arrays of an Orbits (NaN where not alive)."""
    chart = chart if chart is not None else WallChart(orb.table)
    K1, n = orb.ends.shape
    out = [np.full((K1, n), np.nan) for _ in range(4)]
    for k in range(K1):
        m = orb.alive[k]
        vals = boundary_coordinates(orb.post[k, m], orb.ends[k, m], orb.table, orb.params, chart)
        for o, v in zip(out, vals):
            o[k, m] = v
    return tuple(out)


def _reduce(A):
    return A[np.ix_(REDUCED, REDUCED)]


def section_chart(state, end, table, params) -> np.ndarray:
    """(5, 3) tangent vectors (d/ds [per metre of wall], d/dphi, d/dpsi_raw) of the energy shell within the
    impact section at an on-wall state, in (x, y, phi, theta_dot, phi_dot); psi_raw = atan2(w, u)."""
    R = params.R
    px, py = state[0] + end * R * np.cos(state[3]), state[1] + end * R * np.sin(state[3])
    hx, hy = (float(np.asarray(v)) for v in table.grad(px, py))
    g = np.hypot(hx, hy)
    rho = float(metric_speed(state, params))
    psi = np.arctan2(np.sqrt(params.J) * state[5], np.sqrt(params.rolling_inertia) * state[4])
    T = np.zeros((5, 3))
    T[0, 0], T[1, 0] = -hy / g, hx / g
    T[0, 1], T[1, 1], T[2, 1] = end * R * np.sin(state[3]), -end * R * np.cos(state[3]), 1.0
    T[3, 2] = -rho * np.sin(psi) / np.sqrt(params.rolling_inertia)
    T[4, 2] = rho * np.cos(psi) / np.sqrt(params.J)
    return T


@dataclass
class TangentMaps:
    """Per impact k (k = 1..K) of one orbit, reduced to (x, y, phi, theta_dot, phi_dot):

    flow (K, 5, 5): d(state just after impact k) / d(state just after impact k-1) at fixed times (flight
    flow, then the saltation matrix); det = (effective restitution)^2.
    section (K, 5, 5): the return map's Jacobian followed by the rescaling to the start's metric speed (maps
    the section's energy-shell tangent space at post k-1 into the one at post k).
    section3 (K, 3, 3): section in the chart (s [m], phi, psi_raw) (section_chart), so log|det| is
    coordinate-stated."""

    flow: np.ndarray
    section: np.ndarray
    section3: np.ndarray
    flight: np.ndarray


def tangent_maps(orb: Orbits, i: int) -> TangentMaps:
    """The exact tangent maps of orbit i, impact by impact, while it is alive."""
    params, tab, law = orb.params, orb.table, orb.law
    R = params.R
    K = int(np.argmin(orb.alive[:, i])) - 1 if not orb.alive[:, i].all() else orb.alive.shape[0] - 1
    F = np.empty((K, 5, 5))
    P = np.empty((K, 5, 5))
    P3 = np.empty((K, 3, 3))
    tau = orb.flight[:K, i]
    T0 = section_chart(orb.post[0, i], orb.ends[0, i], tab, params)
    for k in range(K):
        x0 = orb.post[k, i]
        Phi, _ = flow_jacobian(x0, 0.0, 0.0, tau[k], R)
        pre = np.array(flow_penny(tuple(x0), 0.0, 0.0, tau[k], R))
        sigma = float(orb.ends[k + 1, i])
        post, D, grad_g = impact_linearisation(pre, sigma, params, tab, law)
        f_minus = vector_field(pre, 0.0, 0.0, R)
        f_plus = vector_field(post, 0.0, 0.0, R)
        normal = float(grad_g @ f_minus)
        Xi = D + np.outer(f_plus - D @ f_minus, grad_g) / normal
        F[k] = _reduce(Xi @ Phi)
        Ret = D @ (np.eye(6) - np.outer(f_minus, grad_g) / normal) @ Phi  # the impact time moves
        # rescaling v -> v rho0 / rho(v): Jacobian (rho0 / rho) (I - v grad(rho)^T / rho) on the speeds
        rho1 = float(metric_speed(post, params))
        rho0 = float(metric_speed(x0, params))
        v = post[4:]
        grad_rho = np.array([params.rolling_inertia * v[0], params.J * v[1]]) / rho1
        N = np.eye(6)
        N[4:, 4:] = (rho0 / rho1) * (np.eye(2) - np.outer(v, grad_rho) / rho1)
        P[k] = _reduce(N @ Ret)
        post_scaled = post.copy()
        post_scaled[4:] *= rho0 / rho1
        T1 = section_chart(post_scaled, sigma, tab, params)
        P3[k] = np.linalg.lstsq(T1, P[k] @ T0, rcond=None)[0]
        T0 = T1
    return TangentMaps(F, P, P3, tau)


def qr_exponents(maps, q0, times=None):
    """Lyapunov exponents of the product maps[-1] ... maps[0] on the span of q0's columns (QR after every map):
    (running exponents (K, m): per map, or per unit time if times (K,) [s] are given; the last row is the
    estimate)."""
    Q = np.linalg.qr(np.asarray(q0, dtype=float))[0]
    sums = np.zeros(Q.shape[1])
    run = np.empty((len(maps), Q.shape[1]))
    clock = np.cumsum(times) if times is not None else np.arange(1, len(maps) + 1)
    for k, A in enumerate(maps):
        Q, Rm = np.linalg.qr(A @ Q)
        d = np.diag(Rm)
        sums += np.log(np.abs(d))
        Q = Q * np.sign(d)[None, :]
        run[k] = sums / clock[k]
    return run
