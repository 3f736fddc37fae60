"""A specular point billiard with a published Lyapunov exponent: the cross-check of the Lyapunov machinery.

The Sinai billiard (a disk of radius rho centred in the unit square, periodic boundary conditions: the unit torus
with one disk), its disk-to-disk map in the coordinates (r, phi) (arc length on the disk, angle of the outgoing
velocity with the outward normal), the map's exact Jacobian (Chernov and Markarian, *Chaotic billiards*, AMS 2006,
eq. (2.26)), and its largest Lyapunov exponent by the same QR iteration the penny's exponents use
(:func:`penny_env.analysis.boundary_map.qr_exponents`). The published answer (P. Dahlqvist, "The Lyapunov exponent
in the Sinai billiard in the small scatterer limit", Nonlinearity 10 (1997) 159, arXiv:chao-dyn/9601007) is

    lambda = -2 ln(rho) + C + O(rho ln^2 rho),   C = 1 - 4 ln 2 + 27 zeta(3) / (2 pi^2) = -0.12837...

per collision. The next collision is found by walking the unit cells the ray crosses (each holds one disk), so a
flight costs about 1 / (2 rho) cells; compiled with numba.
"""
from __future__ import annotations

import math

import numba
import numpy as np

ZETA3 = 1.2020569031595942
DAHLQVIST_C = 1.0 - 4.0 * math.log(2.0) + 27.0 * ZETA3 / (2.0 * math.pi ** 2)


def dahlqvist(rho):
    """The published small-scatterer exponent -2 ln(rho) + C (per collision), without the O(rho ln^2 rho) term."""
    return -2.0 * np.log(rho) + DAHLQVIST_C


@numba.njit(cache=True)
def _wrap(a):  # pragma: no cover - compiled
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@numba.njit(cache=True)
def sinai_step(theta, alpha, rho):  # pragma: no cover - compiled
    """One collision of the disk-to-disk map. theta: the point rho (cos theta, sin theta) on the disk at the origin;
    alpha: the direction of the outgoing unit velocity (pointing out of the disk). Returns (theta1, alpha1, tau,
    phi0, phi1): the next collision point and outgoing direction (relative to the disk hit), the free path, and the
    angles of the outgoing velocities with the outward normals before and after."""
    px, py = rho * math.cos(theta), rho * math.sin(theta)
    vx, vy = math.cos(alpha), math.sin(alpha)
    phi0 = _wrap(alpha - theta)
    # walk the unit cells [k - 1/2, k + 1/2]^2 the ray crosses, starting in the cell of the disk it leaves
    cx, cy = 0, 0
    sx = 1 if vx > 0 else -1
    sy = 1 if vy > 0 else -1
    tx = ((cx + 0.5 * sx) - px) / vx if vx != 0.0 else math.inf
    ty = ((cy + 0.5 * sy) - py) / vy if vy != 0.0 else math.inf
    dtx = abs(1.0 / vx) if vx != 0.0 else math.inf
    dty = abs(1.0 / vy) if vy != 0.0 else math.inf
    for _ in range(100000000):
        if tx < ty:
            cx += sx
            tx += dtx
        else:
            cy += sy
            ty += dty
        # the disk at (cx, cy): the ray p + v t meets it iff its distance to the centre is below rho
        qx, qy = cx - px, cy - py
        tk = qx * vx + qy * vy
        d2 = qx * qx + qy * qy - tk * tk
        if d2 < rho * rho and tk > 0.0:
            tau = tk - math.sqrt(rho * rho - d2)
            hx, hy = px + vx * tau - cx, py + vy * tau - cy
            theta1 = math.atan2(hy, hx)
            nx, nyy = hx / rho, hy / rho
            dot = vx * nx + vy * nyy
            wx, wy = vx - 2.0 * dot * nx, vy - 2.0 * dot * nyy
            alpha1 = math.atan2(wy, wx)
            return theta1, alpha1, tau, phi0, _wrap(alpha1 - theta1)
    return math.nan, math.nan, math.nan, phi0, math.nan


def jacobian(tau, phi0, phi1, rho):
    """The disk-to-disk map's Jacobian d(r1, phi1) / d(r0, phi0) (r = rho theta, the arc length; curvature 1/rho,
    dispersing), Chernov and Markarian (2006) eq. (2.26): -1/cos(phi1) [[tau K + cos phi0, tau],
    [tau K^2 + K (cos phi0 + cos phi1), tau K + cos phi1]]; det = cos(phi0) / cos(phi1)."""
    K = 1.0 / rho
    c0, c1 = math.cos(phi0), math.cos(phi1)
    return -np.array([[tau * K + c0, tau], [tau * K * K + K * (c0 + c1), tau * K + c1]]) / c1


def sinai_orbit(theta, alpha, rho, n):
    """n collisions from (theta, alpha): arrays theta, alpha, tau, phi0, phi1 (n,)."""
    out = np.empty((5, n))
    for k in range(n):
        theta, alpha, tau, p0, p1 = sinai_step(theta, alpha, rho)
        out[:, k] = theta, alpha, tau, p0, p1
    return out


def sinai_lyapunov(rho, n_orbits, n_impacts, seed=0):
    """Largest Lyapunov exponent per collision of the disk-to-disk map, per orbit (QR on the exact Jacobians,
    boundary_map.qr_exponents): (final exponents (n_orbits,), running exponents (n_orbits, n_impacts), mean free
    path over all flights). Starts: uniform theta, outgoing angle drawn from the invariant cos(phi) dphi."""
    from penny_env.analysis.boundary_map import qr_exponents

    rng = np.random.default_rng(seed)
    finals, runs, paths = [], [], []
    for _ in range(n_orbits):
        theta = rng.uniform(-math.pi, math.pi)
        phi = math.asin(rng.uniform(-1.0, 1.0))  # density cos(phi) / 2 on (-pi/2, pi/2)
        orb = sinai_orbit(theta, theta + phi, rho, n_impacts)
        maps = [jacobian(tau, p0, p1, rho) for tau, p0, p1 in orb[2:].T]
        run = qr_exponents(maps, np.eye(2))[:, 0]
        finals.append(run[-1])
        runs.append(run)
        paths.append(orb[2])
    return np.array(finals), np.array(runs), float(np.mean(np.concatenate(paths)))
