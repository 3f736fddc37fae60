"""Derivatives of a simulated trajectory through its impacts (sensitivities).

:func:`trajectory_jacobians` walks the event sequence that simulate() produced (its segments:
flows between impacts and control boundaries) and chains exact linearisations:

* a flow of duration tau with constant angular accelerations (acc1 = u1 / J on phi,
  acc2 = u2 / (I + m R^2) on theta): theta, phi, theta_dot, phi_dot are polynomials in t and
  x + i y = z0 + R int_0^tau (W0 + acc2 s) e^{i phi(s)} ds, so every derivative of (x, y) with
  respect to (phi0, theta_dot0, phi_dot0, acc1, acc2) is a moment int_0^tau s^k e^{i phi(s)} ds,
  k = 0..3 (:func:`phase_moments`: composite Gauss-Legendre, 24 nodes per panel of <= 3 rad);
* an impact of end sigma: the saltation matrix
  Xi = D Delta + (f+ - D Delta f-) (grad g)^T / (grad g . f-), g(s) = h(end(s)), D Delta the
  Jacobian of the impact law (laws.law_jacobian, the sticking rule of the plastic law
  included) and f-, f+ the vector field before and after;
* a control boundary: nothing (its time does not move).

When the run stops right after its n-th impact, the final time moves with that impact and the
final state's derivative is the post-impact state's (D Delta (I - f- grad g^T / grad g . f-)).
Otherwise final_time is held fixed.

Where the derivative does not exist the result says so (valid False with a reason, the matrices
NaN): a grazing impact (relative normal speed below GRAZING_SPEED), a Zeno accumulation brought
to rest (or a penny pinned against the wall), a run that stopped short of its n_impacts at a time
set by the state itself. The saltation matrix needs the wall's Hessian: a table without
hessian() (a plain ConvexTable) gets it from central differences of its gradient, accurate to
about 1e-10 relative rather than to round-off.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


X, Y, THETA, PHI, THETA_DOT, PHI_DOT = range(6)

# An impact whose normal speed is below this fraction of |grad h| |end velocity| is grazing: the
# saltation term grows like 1/(normal speed) and nearby trajectories miss the wall, so no derivative.
GRAZING_SPEED = 1e-6
MAX_PHASE_PER_PANEL = 3.0
_GL_NODES, _GL_WEIGHTS = np.polynomial.legendre.leggauss(24)
_GL_NODES = 0.5 * (_GL_NODES + 1.0)
_GL_WEIGHTS = 0.5 * _GL_WEIGHTS


@dataclass
class Sensitivities:
    """d final_state / d initial_state (6 x 6) and / d controls (6 x 2K, columns u1_0, u2_0, u1_1, ...),
    and d final_time / d initial state (6,) and / d controls (zero unless the run stopped at an impact)."""

    jacobian: np.ndarray
    control_jacobian: np.ndarray | None
    time_gradient: np.ndarray
    control_time_gradient: np.ndarray | None
    valid: bool
    reason: str
    normal_speeds: np.ndarray  # relative normal speed of the end before each impact (1 head-on, 0 grazing)


def phase_moments(phi0, w, acc1, tau, kmax=3):
    """(C, S): C[k] = int_0^tau s^k cos phi(s) ds, S[k] the same with sin, phi(s) = phi0 + w s + acc1 s^2 / 2.

    Composite Gauss-Legendre (24 nodes, panels of <= 3 rad of phase): the integrand is entire and the
    rule is exact to round-off for such panels, whatever acc1 (no Fresnel cancellation)."""
    if tau == 0.0:
        return np.zeros(kmax + 1), np.zeros(kmax + 1)
    sweep = max(abs(w), abs(w + acc1 * tau)) * tau + 0.5 * abs(acc1) * tau * tau
    n = max(1, math.ceil(sweep / MAX_PHASE_PER_PANEL))
    edges = np.linspace(0.0, tau, n + 1)
    width = np.diff(edges)
    s = (edges[:-1, None] + width[:, None] * _GL_NODES[None, :]).ravel()
    wt = (width[:, None] * _GL_WEIGHTS[None, :]).ravel()
    ph = phi0 + s * (w + 0.5 * acc1 * s)
    c, sn = np.cos(ph) * wt, np.sin(ph) * wt
    powers = s[None, :] ** np.arange(kmax + 1)[:, None]
    return powers @ c, powers @ sn


def flow_jacobian(state, acc1, acc2, tau, R):
    """(Phi, B): d s(tau) / d s0 (6 x 6) and d s(tau) / d (acc1, acc2) (6 x 2) for the exact flow."""
    W, w, ph = state[THETA_DOT], state[PHI_DOT], state[PHI]
    C, S = phase_moments(ph, w, acc1, tau)
    Phi = np.eye(6)
    Phi[X, PHI] = -R * (W * S[0] + acc2 * S[1])
    Phi[Y, PHI] = R * (W * C[0] + acc2 * C[1])
    Phi[X, THETA_DOT] = R * C[0]
    Phi[Y, THETA_DOT] = R * S[0]
    Phi[X, PHI_DOT] = -R * (W * S[1] + acc2 * S[2])
    Phi[Y, PHI_DOT] = R * (W * C[1] + acc2 * C[2])
    Phi[THETA, THETA_DOT] = tau
    Phi[PHI, PHI_DOT] = tau
    B = np.zeros((6, 2))
    B[X, 0] = -0.5 * R * (W * S[2] + acc2 * S[3])
    B[Y, 0] = 0.5 * R * (W * C[2] + acc2 * C[3])
    B[X, 1] = R * C[1]
    B[Y, 1] = R * S[1]
    B[PHI, 0] = 0.5 * tau * tau
    B[PHI_DOT, 0] = tau
    B[THETA, 1] = 0.5 * tau * tau
    B[THETA_DOT, 1] = tau
    return Phi, B


def flow_jacobians(state, acc1, acc2, taus, R):
    """:func:`flow_jacobian` at several increasing times taus (n,) at once: (Phi (n, 6, 6), B (n, 6, 2)).

    The moments are accumulated over the gaps between consecutive times, each gap with the panel count
    of the whole sweep (<= 3 rad of phase per panel), so every time gets the same accuracy."""
    taus = np.asarray(taus, dtype=float)
    W, w, ph = state[THETA_DOT], state[PHI_DOT], state[PHI]
    t_end = float(taus[-1])
    sweep = max(abs(w), abs(w + acc1 * t_end)) * t_end + 0.5 * abs(acc1) * t_end * t_end
    n = max(1, math.ceil(sweep / MAX_PHASE_PER_PANEL))
    lo = np.concatenate([[0.0], taus[:-1]])
    width = (taus - lo) / n  # (m,)
    start = lo[:, None] + width[:, None] * np.arange(n)[None, :]  # (m, n) panel starts
    s = start[:, :, None] + width[:, None, None] * _GL_NODES[None, None, :]
    wt = np.broadcast_to(width[:, None, None] * _GL_WEIGHTS[None, None, :], s.shape)
    phase = ph + s * (w + 0.5 * acc1 * s)
    c, sn = np.cos(phase) * wt, np.sin(phase) * wt
    powers = s[None] ** np.arange(4)[:, None, None, None]  # (4, m, n, nodes)
    C = np.cumsum((powers * c[None]).sum(axis=(2, 3)), axis=1)  # (4, m)
    S = np.cumsum((powers * sn[None]).sum(axis=(2, 3)), axis=1)
    m = taus.shape[0]
    Phi = np.broadcast_to(np.eye(6), (m, 6, 6)).copy()
    Phi[:, X, PHI] = -R * (W * S[0] + acc2 * S[1])
    Phi[:, Y, PHI] = R * (W * C[0] + acc2 * C[1])
    Phi[:, X, THETA_DOT] = R * C[0]
    Phi[:, Y, THETA_DOT] = R * S[0]
    Phi[:, X, PHI_DOT] = -R * (W * S[1] + acc2 * S[2])
    Phi[:, Y, PHI_DOT] = R * (W * C[1] + acc2 * C[2])
    Phi[:, THETA, THETA_DOT] = taus
    Phi[:, PHI, PHI_DOT] = taus
    B = np.zeros((m, 6, 2))
    B[:, X, 0] = -0.5 * R * (W * S[2] + acc2 * S[3])
    B[:, Y, 0] = 0.5 * R * (W * C[2] + acc2 * C[3])
    B[:, X, 1] = R * C[1]
    B[:, Y, 1] = R * S[1]
    B[:, PHI, 0] = 0.5 * taus * taus
    B[:, PHI_DOT, 0] = taus
    B[:, THETA, 1] = 0.5 * taus * taus
    B[:, THETA_DOT, 1] = taus
    return Phi, B


def vector_field(state, acc1, acc2, R):
    """ds/dt at a state under constant angular accelerations."""
    W, w, ph = state[THETA_DOT], state[PHI_DOT], state[PHI]
    return np.array([R * W * math.cos(ph), R * W * math.sin(ph), W, w, acc2, acc1])


def wall_hessian(table, px, py):
    """(hxx, hxy, hyy) at an end: the table's hessian() where it has one, else central differences of
    its gradient (accurate to about 1e-10 relative)."""
    hess = getattr(table, "hessian", None)
    if callable(hess):
        return tuple(float(np.asarray(v)) for v in hess(px, py))
    step = 6e-6 * table.size
    gxp, gyp = table.grad(px + step, py)
    gxm, gym = table.grad(px - step, py)
    gxq, gyq = table.grad(px, py + step)
    gxn, gyn = table.grad(px, py - step)
    hxx = float(gxp - gxm) / (2 * step)
    hyy = float(gyq - gyn) / (2 * step)
    hxy = 0.5 * (float(gyp - gym) + float(gxq - gxn)) / (2 * step)
    return hxx, hxy, hyy


def impact_linearisation(pre, sigma, params, table, law):
    """(post, D Delta (6 x 6), grad g (6,)) for end sigma of the state pre on the wall."""
    R = params.R
    ph = pre[PHI]
    c, sn = math.cos(ph), math.sin(ph)
    px, py = pre[X] + sigma * R * c, pre[Y] + sigma * R * sn
    hx, hy = (float(np.asarray(v)) for v in table.grad(px, py))
    hxx, hxy, hyy = wall_hessian(table, px, py)
    a = R * (hx * c + hy * sn)
    b = sigma * R * (hy * c - hx * sn)
    grad2 = hx * hx + hy * hy
    # derivatives of (hx, hy) w.r.t. (x, y, phi): the end moves by sigma R (-sin, cos) per radian
    dpx_dphi, dpy_dphi = -sigma * R * sn, sigma * R * c
    dh = np.array([[hxx, hxy, hxx * dpx_dphi + hxy * dpy_dphi],
                   [hxy, hyy, hxy * dpx_dphi + hyy * dpy_dphi]])  # rows hx, hy; columns x, y, phi
    da = R * (c * dh[0] + sn * dh[1])
    da[2] += R * (-hx * sn + hy * c)
    db = sigma * R * (c * dh[1] - sn * dh[0])
    db[2] += sigma * R * (-hy * sn - hx * c)
    dg2 = 2.0 * (hx * dh[0] + hy * dh[1])
    jacobian = law.record.jacobian
    if jacobian is None:  # (trajectory_jacobians reports it: jacobian_valid False)
        Wp, wp = law.update(pre[THETA_DOT], pre[PHI_DOT], a, b, grad2, law.e, params.rolling_inertia, params.J, params.m)
        L = np.full((2, 5), np.nan)
    else:
        (Wp, wp), L = jacobian(pre[THETA_DOT], pre[PHI_DOT], a, b, grad2, law.e, params.rolling_inertia, params.J,
                               params.m)
    # chain: (W, w, a, b, grad2) as functions of the state (x, y, phi, W, w)
    inner = np.zeros((5, 6))
    inner[0, THETA_DOT] = 1.0
    inner[1, PHI_DOT] = 1.0
    for row, d in ((2, da), (3, db), (4, dg2)):
        inner[row, X], inner[row, Y], inner[row, PHI] = d
    D = np.eye(6)
    D[THETA_DOT:] = L @ inner
    grad_g = np.zeros(6)
    grad_g[X], grad_g[Y], grad_g[PHI] = hx, hy, b  # dg/dphi = b: the end moves along sigma R (-sin, cos)
    post = np.array(pre, dtype=float)
    post[THETA_DOT], post[PHI_DOT] = Wp, wp
    return post, D, grad_g


def trajectory_jacobians(traj, table, law, controls=None, n_impacts=None, t_final=None,
                         params=None) -> Sensitivities:
    """The derivatives of traj.final_state along traj's event sequence (see the module docstring).

    traj: a Trajectory from simulate() (its segments and impacts); table, law: the physics objects it
    ran with; controls (K, 2), n_impacts and t_final as simulate() used them (t_final None: the run
    stops at its n_impacts-th impact). The control rows' times come from the trajectory's segments."""
    from .scalar import flow_penny

    params = traj.params if params is None else params
    R = params.R
    K = 0 if controls is None else int(np.asarray(controls).shape[0])
    u = None if controls is None else np.asarray(controls, dtype=float).reshape(K, 2)
    scale = np.array([1.0 / params.J, 1.0 / params.rolling_inertia])  # d(acc1, acc2) / d(u1, u2)
    S = np.eye(6)
    C = np.zeros((6, 2 * K)) if K else None
    n = len(traj._seg_t)
    invalid = []
    if traj.rest_times.size:
        invalid.append(f"a Zeno accumulation brought the penny to rest at t={traj.rest_times[0]:.6g} s "
                       "(its velocity is reset to zero: no derivative)")
    if traj.n_impacts and law.record.jacobian is None:
        invalid.append(f"the impact law {law.kind!r} was registered without a Jacobian (register_law(..., "
                       "jacobian=...)): no derivative through its impacts")
    if not traj.complete and n_impacts is not None and t_final is None:
        invalid.append("the run stopped before its n_impacts at a time set by the state itself "
                       "(complete=False without t_final): no derivative at a fixed time")
    stop_at_impact = (n_impacts is not None and traj.n_impacts >= n_impacts and traj.n_impacts > 0
                      and traj.final_time == traj.impact_times[-1])
    time_grad = np.zeros(6)
    ctime_grad = np.zeros(2 * K) if K else None
    speeds = []
    j = 0  # next impact
    k = 0  # control row
    for i in range(n):
        t0 = traj._seg_t[i]
        s0 = traj._seg_s[i]
        t1 = traj._seg_t[i + 1] if i + 1 < n else traj.final_time
        acc1 = acc2 = 0.0
        if u is not None and k < K:
            acc1, acc2 = u[k, 0] * scale[0], u[k, 1] * scale[1]
        tau = max(t1 - t0, 0.0)
        Phi, B = flow_jacobian(s0, acc1, acc2, tau, R)
        S = Phi @ S
        if C is not None:
            C = Phi @ C
            if k < K:
                C[:, 2 * k:2 * k + 2] += B * scale[None, :]
        if i + 1 >= n:
            break
        # what ends this segment: the next impact (same time and post state), or a control boundary
        if (j < traj.n_impacts and traj._seg_t[i + 1] == traj.impact_times[j]
                and np.array_equal(traj._seg_s[i + 1], traj.impact_states[j])):
            sigma = float(traj.impact_ends[j])
            pre = np.array(flow_penny(tuple(s0), acc1, acc2, tau, R))
            post, D, grad_g = impact_linearisation(pre, sigma, params, table, law)
            f_minus = vector_field(pre, acc1, acc2, R)
            f_plus = vector_field(traj._seg_s[i + 1], acc1, acc2, R)
            normal = float(grad_g @ f_minus)
            vx = R * pre[THETA_DOT] * math.cos(pre[PHI]) - sigma * R * pre[PHI_DOT] * math.sin(pre[PHI])
            vy = R * pre[THETA_DOT] * math.sin(pre[PHI]) + sigma * R * pre[PHI_DOT] * math.cos(pre[PHI])
            end_speed = math.hypot(vx, vy)
            gnorm = math.hypot(grad_g[X], grad_g[Y])
            speeds.append(normal / max(gnorm * end_speed, 1e-300))
            if not normal > GRAZING_SPEED * gnorm * end_speed:
                invalid.append(f"grazing impact {j} at t={traj.impact_times[j]:.6g} s (relative normal speed "
                               f"{speeds[-1]:.3g}): no derivative")
            dt_ds = -(grad_g @ S) / normal  # how the impact time moves
            last = stop_at_impact and j == traj.n_impacts - 1
            if last:  # the run ends at this impact: the final time moves with it
                S = D @ (S + np.outer(f_minus, dt_ds))
                time_grad = dt_ds
                if C is not None:
                    dt_du = -(grad_g @ C) / normal
                    C = D @ (C + np.outer(f_minus, dt_du))
                    ctime_grad = dt_du
            else:
                Xi = D + np.outer(f_plus - D @ f_minus, grad_g) / normal
                S = Xi @ S
                if C is not None:
                    C = Xi @ C
            j += 1
        else:
            k += 1
    valid = not invalid
    if not valid:
        S = np.full((6, 6), np.nan)
        C = None if C is None else np.full_like(C, np.nan)
        time_grad = np.full(6, np.nan)
        ctime_grad = None if ctime_grad is None else np.full_like(ctime_grad, np.nan)
    return Sensitivities(S, C, time_grad, ctime_grad, valid, "; ".join(invalid), np.array(speeds))
