"""Scalar (pure Python float) replica of the physics for one penny: the single environment's fast path.

numpy on size-1 arrays costs ~1 us per operation, so one penny through physics.advance() costs
~100 us per control period. This module repeats, for one penny and the built-in tables (ellipse,
circle, stadium) or the open plane, exactly the computations of penny_env.physics (flow.flow,
events.first_impact, advance.advance, laws.apply_law) in the same operation order with Python
floats (math.sin/cos/sqrt equal numpy's bitwise on IEEE machines; numpy's 16-term pairwise sum is reproduced). The results are therefore the
physics' results, bitwise (tests/test_fast_path.py checks it on random inputs). Tables of other
types (ConvexTable, user tables) are not handled here: :func:`scalar_table` returns None and the
caller falls back to physics.advance() with N = 1.

A state is a tuple (x, y, theta, phi, theta_dot, phi_dot).
"""
from __future__ import annotations

import math

import numpy as np

from ..physics.tables import Circle, Ellipse, Stadium

# the physics' constants (flow.py): 16-node Gauss-Legendre on [0, 1], <= 3 rad of phase per panel,
# and the series of j1 below |x| = 1
MAX_PHASE_PER_PANEL = 3.0
_nodes, _weights = np.polynomial.legendre.leggauss(16)
GL_U = tuple(float(u) for u in 0.5 * (_nodes + 1.0))
GL_W = tuple(float(w) for w in 0.5 * _weights)
_J1_COEFFS = []
_f = 6.0
for _k in range(10):
    _J1_COEFFS.append((-1) ** _k * (2 * _k + 2) / _f)
    _f *= (2 * _k + 4) * (2 * _k + 5)
_J1_LAST = _J1_COEFFS[-1]
_J1_REST = tuple(_J1_COEFFS[-2::-1])
_INF = math.inf


def sinc_kernels(x: float):
    """j0(x) = sin(x)/x and j1(x) = (sin x - x cos x)/x^2 (flow.sinc_kernels for one float)."""
    sn = math.sin(x)
    if abs(x) < 1.0:
        x2 = x * x
        series = _J1_LAST
        for c in _J1_REST:
            series = series * x2 + c
        j1 = x * series
    else:
        j1 = (sn - x * math.cos(x)) / (x * x)
    j0 = 1.0 if x == 0.0 else sn / x
    return j0, j1


def _pairwise16(v):
    """numpy's pairwise sum of 16 contiguous float64 values (8 accumulators)."""
    return (((v[0] + v[8]) + (v[1] + v[9])) + ((v[2] + v[10]) + (v[3] + v[11]))) + \
           (((v[4] + v[12]) + (v[5] + v[13])) + ((v[6] + v[14]) + (v[7] + v[15])))


def displacement(W, w, ph, acc1, acc2, t, R):
    """(dx, dy) of the contact point after time t (flow._displacement_closed / _quadrature)."""
    if acc1 == 0.0:
        half = 0.5 * w * t
        j0, j1 = sinc_kernels(half)
        mid = ph + half
        cm, sm = math.cos(mid), math.sin(mid)
        half_gain = 0.5 * acc2 * t
        br = W * j0 + half_gain * j0
        bi = half_gain * j1
        Rt = R * t
        return Rt * (cm * br - sm * bi), Rt * (sm * br + cm * bi)
    sweep = max(abs(w), abs(w + acc1 * t)) * abs(t) + 0.5 * abs(acc1) * t * t
    k = max(1, int(math.ceil(sweep / MAX_PHASE_PER_PANEL)))
    width = t / k
    ha = 0.5 * acc1
    dx = dy = 0.0
    cos, sin = math.cos, math.sin
    for p in range(k):
        fp = float(p)
        cx = []
        cy = []
        for u, gw in zip(GL_U, GL_W):
            s = (fp + u) * width
            phase = ph + s * (w + ha * s)
            amp = (W + acc2 * s) * gw
            cx.append(amp * cos(phase))
            cy.append(amp * sin(phase))
        dx += _pairwise16(cx) * width
        dy += _pairwise16(cy) * width
    return R * dx, R * dy


def flow(s, acc1, acc2, t, R):
    """State after time t with constant accelerations (flow.flow for one penny)."""
    x, y, th, ph, W, w = s
    dx, dy = displacement(W, w, ph, acc1, acc2, t, R)
    return (x + dx, y + dy, th + t * (W + 0.5 * acc2 * t), ph + t * (w + 0.5 * acc1 * t),
            W + acc2 * t, w + acc1 * t)


class ScalarTable:
    """h and grad of a built-in table for floats (same formulas as tables.py)."""

    __slots__ = ("kind", "p0", "p1", "p2", "size", "L", "G")

    def __init__(self, table):
        if type(table) in (Ellipse, Circle):
            self.kind = 0
            self.p0, self.p1, self.p2 = table._ia2, table._ib2, table._half_c
        else:
            self.kind = 1
            self.p0, self.p1, self.p2 = table._half, table.radius, table.radius ** 2
        self.size = table.size
        self.L = table.hessian_bound
        self.G = table.grad_bound

    def h_grad(self, x, y):
        if self.kind == 0:
            ia2, ib2, hc = self.p0, self.p1, self.p2
            c2 = 2.0 * hc
            return (x * x * ia2 + y * y * ib2 - 1.0) * hc, c2 * x * ia2, c2 * y * ib2
        half, r, r2 = self.p0, self.p1, self.p2
        dx = x - min(max(x, -half), half)
        return (dx * dx + y * y - r2) / (2.0 * r), dx / r, y / r


def scalar_table(table):
    """A ScalarTable for the built-in tables, None for anything else (use physics.advance)."""
    if type(table) in (Ellipse, Circle, Stadium):
        return ScalarTable(table)
    return None


class ScalarPhysics:
    """advance() for one penny with Python floats. Built once per (params, table, law, settings)."""

    def __init__(self, params, table, law, settings):
        self.R = params.R
        self.m = params.m
        self.J = params.J
        self.Itot = params.rolling_inertia
        self.table = None if table is None else scalar_table(table)
        if table is not None and self.table is None:
            raise TypeError("ScalarPhysics handles the built-in tables only")
        self.plastic = law.kind == "plastic"
        self.e = law.e
        self.settings = settings
        self.delta = settings.contact_tol * table.size if table is not None else 0.0

    # -- helpers -------------------------------------------------------------------------
    def _wall2(self, s):
        """(g, g') for the front and the back end."""
        x, y, _, ph, W, w = s
        R = self.R
        c, sn = math.cos(ph), math.sin(ph)
        hg = self.table.h_grad
        out = []
        for sR in (R, -R):
            px, py = x + sR * c, y + sR * sn
            vx = R * W * c - sR * w * sn
            vy = R * W * sn + sR * w * c
            g, hx, hy = hg(px, py)
            out.append(g)
            out.append(hx * vx + hy * vy)
        return out

    def _wall(self, s, sigma):
        x, y, _, ph, W, w = s
        R = self.R
        c, sn = math.cos(ph), math.sin(ph)
        sR = sigma * R
        px, py = x + sR * c, y + sR * sn
        vx = R * W * c - sR * w * sn
        vy = R * W * sn + sR * w * c
        g, hx, hy = self.table.h_grad(px, py)
        return g, hx * vx + hy * vy

    @staticmethod
    def _safe_step(g, gd, M):
        gc = min(g, 0.0)
        if M > 0.0:
            sq = math.sqrt(gd * gd - 2.0 * M * gc)
            if gd <= 0.0:
                return (sq - gd) / M
            return -2.0 * gc / (gd + sq)
        return -gc / gd if gd > 0.0 else _INF

    def first_impact(self, s0, acc1, acc2, horizon):
        """(t_hit, end) as events.first_impact: end 0 = none (t_hit inf), +-1, or 2 (budget spent)."""
        R = self.R
        tb = self.table
        delta = self.delta
        W_end = s0[4] + acc2 * horizon
        w_end = s0[5] + acc1 * horizon
        aW_end, aw_end = abs(W_end), abs(w_end)
        a1, a2 = abs(acc1), abs(acc2)
        L, G = tb.L, tb.G
        t = 0.0
        for _ in range(self.settings.max_search_steps):
            st = flow(s0, acc1, acc2, t, R) if t != 0.0 else s0
            gf, gdf, gb, gdb = self._wall2(st)
            hit_f = gf >= -delta and gdf > 0.0
            hit_b = gb >= -delta and gdb > 0.0
            Wm = max(abs(st[4]), aW_end)
            wm = max(abs(st[5]), aw_end)
            a_par = a2 + wm * wm
            a_perp = a1 + wm * Wm
            M = L * (R * R * (Wm * Wm + wm * wm)) + G * (R * math.sqrt(a_par * a_par + a_perp * a_perp))
            tau_min = math.sqrt(2.0 * delta / M) if M > 0.0 else _INF
            if hit_f or hit_b:
                front = hit_f and (not hit_b or gdf >= gdb)
                g, gd = (gf, gdf) if front else (gb, gdb)
                newton = min(-g / gd, tau_min) if g < 0.0 else 0.0
                return min(t + newton, horizon), (1 if front else -1)
            tau = max(min(self._safe_step(gf, gdf, M), self._safe_step(gb, gdb, M)), tau_min)
            t_next = t + tau
            t = t_next
            if not t_next < horizon:
                return _INF, 0
        return t, 2

    def relocate_inside(self, s):
        x, y, th, ph, W, w = s
        R = self.R
        c, sn = math.cos(ph), math.sin(ph)
        hg = self.table.h_grad
        for sR in (R, -R):
            g, hx, hy = hg(x + sR * c, y + sR * sn)
            if g > 0.0:
                k = g / (hx * hx + hy * hy)
                x -= k * hx
                y -= k * hy
        return (x, y, th, ph, W, w)

    def apply_law(self, s, sigma):
        x, y, th, ph, W, w = s
        R = self.R
        c, sn = math.cos(ph), math.sin(ph)
        sR = sigma * R
        _, hx, hy = self.table.h_grad(x + sR * c, y + sR * sn)
        a = R * (hx * c + hy * sn)
        b = sigma * R * (hy * c - hx * sn)
        g2 = hx * hx + hy * hy
        Itot, J = self.Itot, self.J
        vn = a * W + b * w
        metric = a * a / Itot + b * b / J
        if self.plastic:
            k = 2.0 * vn / (g2 / self.m + b * b / J)
            if vn > 0 and vn - k * metric > 0:
                k = vn / metric
        else:
            k = (1.0 + self.e) * vn / metric
        return (x, y, th, ph, W - k * a / Itot, w - k * b / J)

    def _pushes_out(self, s, acc1, acc2, delta):
        x, y, _, ph, _, _ = s
        R = self.R
        c, sn = math.cos(ph), math.sin(ph)
        for sigma in (1.0, -1.0):
            sR = sigma * R
            g, hx, hy = self.table.h_grad(x + sR * c, y + sR * sn)
            ax = R * (acc2 * c - sigma * acc1 * sn)
            ay = R * (acc2 * sn + sigma * acc1 * c)
            if g >= -delta and hx * ax + hy * ay > 0.0:
                return True
        return False

    def advance(self, s, acc1, acc2, dt):
        """(new_state, events, rests) over one interval of length dt (advance.advance for N = 1).

        events: list of (time since interval start, end, post-impact state tuple);
        rests: list of (time, pinned) where an accumulation brought the penny to rest."""
        R = self.R
        if self.table is None:
            return flow(s, acc1, acc2, dt, R), (), ()
        st = self.settings
        elapsed = 0.0
        n_events = 0
        streak = 0
        events = []
        rests = []
        if not dt > 0.0:
            return s, events, rests
        while True:
            rem = dt - elapsed
            t_hit, end = self.first_impact(s, acc1, acc2, rem)
            if end == 0:
                return flow(s, acc1, acc2, rem, R), events, rests
            if end == 2:
                s = self.relocate_inside(flow(s, acc1, acc2, t_hit, R))
                elapsed += t_hit
                continue
            pre = self.relocate_inside(flow(s, acc1, acc2, t_hit, R))
            if self._wall(pre, float(end))[1] <= 0.0:  # grazing touch, no impact
                s = pre
                elapsed += t_hit
                continue
            post = self.apply_law(pre, float(end))
            elapsed += t_hit
            t_impact = elapsed
            n_events += 1
            streak = streak + 1 if t_hit < st.zeno_window else 0
            done = False
            if streak >= st.zeno_impacts or n_events >= st.max_events_per_interval:
                post = post[:4] + (0.0, 0.0)
                streak = 0
                pinned = self._pushes_out(post, acc1, acc2, 64 * self.delta)
                done = pinned
                rests.append((t_impact, pinned))
                if pinned:
                    elapsed = dt
            events.append((t_impact, end, post))
            s = post
            if done:
                return s, events, rests
