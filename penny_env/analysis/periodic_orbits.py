"""Periodic orbits of the penny's elastic boundary map and their linear stability, and finite-time Lyapunov
exponents on 2-D slices of the map (islands or their absence).

The boundary map F (penny_env.analysis.boundary_map) acts on z = (s, beta, psi): s the arc length of the impact
point over the perimeter, beta the incidence, psi the spin ratio; the energy is fixed (speeds rescaled after each
impact: an exact symmetry). :func:`step` evaluates F^p on many points at once (penny_env.batch underneath).

* :func:`find_periodic`: Newton's method (least squares: periodic orbits of this 3-D reversible map come in
  one-parameter families, so DF^p - I is singular along them) on F^p(z) - z from many seeds, with the Jacobian by
  central differences; a converged point is kept when the residual is below 1e-9 and no impact of its orbit is
  near grazing. :func:`classify`: the eigenvalues of DF^p, coordinate-free: hyperbolic (a real pair lambda,
  1/lambda with |lambda| > 1), elliptic (a pair on the unit circle, off the real axis), parabolic (all on the unit
  circle and real); the third eigenvalue is 1 (the family's direction).
* :func:`slice_ftle`: on a grid of (s, beta) at a fixed psi, the finite-time largest exponent per impact of each
  point over n impacts by the two-orbit method (a companion orbit renormalised to distance delta after every impact,
  the distance measured in (s x perimeter / table size, beta, psi)). Regular regions (islands) show as exponents at
  the level of the integrable circle's; chaotic ones well above.
"""
from __future__ import annotations

import numpy as np

from ..physics import PennyParams, make_table
from . import boundary_map as bm

RESIDUAL = 1e-9     # |F^p(z) - z| below this: a periodic point
MIN_NORMAL = 1e-3   # |v_n| / (R rho) at every impact of a kept orbit (no grazing impact: F is smooth there)


def _wrap(a):
    return (a + np.pi) % (2.0 * np.pi) - np.pi


def difference(z1, z0):
    """z1 - z0 in (s, beta, psi) with s taken modulo 1 and psi modulo 2 pi (the nearest representatives)."""
    d = np.asarray(z1, float) - np.asarray(z0, float)
    d[..., 0] = (d[..., 0] + 0.5) % 1.0 - 0.5
    d[..., 2] = _wrap(d[..., 2])
    return d


class SectionMap:
    """The elastic boundary map of one table at the metric speed rho, in z = (s, beta, psi)."""

    def __init__(self, table, params=None, rho=None, law="elastic"):
        self.params = params if params is not None else PennyParams()
        self.table = make_table(table)
        self.chart = bm.WallChart(self.table)
        self.rho = rho if rho is not None else float(bm.metric_speed(np.array([0, 0, 0, 0, 10.0, 0.2]), self.params))
        self.law = law

    def states(self, z):
        z = np.atleast_2d(z)
        return bm.section_states(z[:, 0], z[:, 1], z[:, 2], self.rho, self.table, self.params, self.chart)

    def valid(self, z):
        """Post-impact points: moving inward (v_n < 0) with the other end inside the table."""
        z = np.atleast_2d(z)
        dens = bm.normal_speed_density(z[:, 1], z[:, 2], self.params)
        S = self.states(z)
        R = self.params.R
        back = np.asarray(self.table.h(S[:, 0] - R * np.cos(S[:, 3]), S[:, 1] - R * np.sin(S[:, 3]))) < 0
        return (dens < 0) & back & (np.abs(z[:, 1]) < np.pi / 2)

    def step(self, z, p=1):
        """(F^p(z) (N, 3), the smallest |v_n| / (R rho) along the p impacts (N,), alive (N,)); rows that are not
        post-impact states (valid) or whose orbit stopped (grazing, no impact) are NaN and not alive."""
        z = np.atleast_2d(np.asarray(z, float))
        out = np.full(z.shape, np.nan)
        low = np.full(len(z), np.nan)
        alive = np.zeros(len(z), bool)
        ok = np.flatnonzero(np.all(np.isfinite(z), axis=1))
        ok = ok[self.valid(z[ok])] if ok.size else ok
        if ok.size:
            orb = bm.iterate(self.states(z[ok]), np.ones(ok.size), p, table=self.table, law=self.law,
                             params=self.params, rescale=True)
            s, b, q, dn = bm.coordinates(orb, self.chart)
            out[ok] = np.stack([s[-1], b[-1], q[-1]], axis=1)
            alive[ok] = orb.alive[-1]
            with np.errstate(invalid="ignore"):
                low[ok] = np.min(np.where(np.isfinite(dn[1:]), np.abs(dn[1:]), np.inf), axis=0)
        out[~alive] = np.nan
        return out, low, alive

    def jacobian(self, z, p, h=1e-6):
        """Central-difference DF^p at the points z (N, 3): (N, 3, 3)."""
        z = np.atleast_2d(z)
        n = len(z)
        pts = np.concatenate([z + h * e for e in np.eye(3)] + [z - h * e for e in np.eye(3)])
        img, _, _ = self.step(pts, p)
        J = np.empty((n, 3, 3))
        for j in range(3):
            J[:, :, j] = difference(img[j * n:(j + 1) * n], img[(j + 3) * n:(j + 4) * n]) / (2 * h)
        return J


def find_periodic(smap: SectionMap, p: int, seeds, iterations: int = 30):
    """Periodic points of period p from the seeds (N, 3): list of (z, J = DF^p(z), residual, smallest normal speed
    along the orbit), one per converged seed (duplicates included)."""
    z = np.array(seeds, float)
    for _ in range(iterations):
        ok = smap.valid(z)
        z = z[ok]
        if not len(z):
            return []
        img, _, alive = smap.step(z, p)
        r = difference(img, z)
        J = smap.jacobian(z, p)
        good = alive & np.all(np.isfinite(J), axis=(1, 2)) & np.all(np.isfinite(r), axis=1)
        z, r, J = z[good], r[good], J[good]
        dz = np.array([-np.linalg.lstsq(Jk - np.eye(3), rk, rcond=None)[0] for Jk, rk in zip(J, r)]) if len(z) else z
        scale = np.minimum(1.0, 0.2 / np.maximum(np.abs(dz).max(axis=1), 1e-300))  # damped steps
        z = z + scale[:, None] * dz
        z[:, 0] %= 1.0
        z[:, 2] = _wrap(z[:, 2])
    out = []
    if not len(z):
        return out
    ok = smap.valid(z)
    z = z[ok]
    img, low, alive = smap.step(z, p)
    res = np.abs(difference(img, z)).max(axis=1)
    keep = alive & (res < RESIDUAL) & (low > MIN_NORMAL)
    J = smap.jacobian(z[keep], p) if keep.any() else np.zeros((0, 3, 3))
    for zk, Jk, rk, lk in zip(z[keep], J, res[keep], low[keep]):
        out.append((zk, Jk, float(rk), float(lk)))
    return out


def classify(J, tol=1e-3) -> tuple[str, np.ndarray]:
    """('hyperbolic' | 'elliptic' | 'parabolic', eigenvalues sorted by modulus) of DF^p."""
    ev = np.linalg.eigvals(J)
    # by modulus, then imaginary part: a complex pair ties in modulus, and the order of ties is the CPU sort kernel's
    ev = ev[np.lexsort((-ev.imag, -np.abs(ev)))]
    if np.abs(ev[0]) > 1 + tol:
        return "hyperbolic", ev
    if np.any(np.abs(ev.imag) > tol):
        return "elliptic", ev
    return "parabolic", ev


def distinct(found, p, smap, tol=1e-6):
    """The found periodic points, one per orbit (points of the same orbit, the p images, merged)."""
    kept, orbits = [], []
    for item in found:
        z = item[0]
        pts = [z]
        cur = z[None, :]
        for _ in range(p - 1):
            cur = smap.step(cur, 1)[0]
            pts.append(cur[0])
        if any(min(np.abs(difference(q, z)).max() for q in orb) < tol for orb in orbits):
            continue
        orbits.append(pts)
        kept.append(item)
    return kept


def slice_ftle(smap: SectionMap, psi: float, n_s: int, n_beta: int, n_impacts: int, delta: float = 1e-7, seed: int = 0):
    """Finite-time largest exponents per impact on the slice psi = const: (s grid (n_s,), beta grid (n_beta,),
    FTLE (n_beta, n_s) with NaN where the point is not a post-impact state or its orbit stopped)."""
    rng = np.random.default_rng(seed)
    s = (np.arange(n_s) + 0.5) / n_s
    beta = np.linspace(-np.pi / 2, np.pi / 2, n_beta + 2)[1:-1]
    S, B = np.meshgrid(s, beta)
    z = np.stack([S.ravel(), B.ravel(), np.full(S.size, psi)], axis=1)
    out = np.full(len(z), np.nan)
    ok = smap.valid(z)
    idx = np.flatnonzero(ok)
    z = z[ok]
    scale = np.array([smap.chart.perimeter / smap.table.size, 1.0, 1.0])
    d = rng.normal(size=z.shape)
    d /= np.linalg.norm(d * scale, axis=1)[:, None]
    twin = z + delta * d
    total = np.zeros(len(z))
    live = np.ones(len(z), bool)
    for _ in range(n_impacts):
        both, _, alive = smap.step(np.concatenate([z, twin]), 1)
        n = len(z)
        zn, tn = both[:n], both[n:]
        live &= alive[:n] & alive[n:]
        diff = difference(tn, zn) * scale
        dist = np.linalg.norm(diff, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            total += np.where(live, np.log(dist / delta), 0.0)
            unit = diff / dist[:, None] / scale
        z = np.where(live[:, None], zn, z)
        unit = np.where(np.all(np.isfinite(unit), axis=1)[:, None], unit, d)
        twin = z + delta * unit
        flip = ~smap.valid(twin)  # (near the edge of the accessible region: the other side)
        twin[flip] = z[flip] - delta * unit[flip]
        live &= smap.valid(twin)
        twin[:, 0] %= 1.0
    out[idx] = np.where(live, total / n_impacts, np.nan)
    return s, beta, out.reshape(len(beta), len(s))
