#!/usr/bin/env python3
r"""
High-precision (mpmath, 50 significant digits) reference data for the
"bouncing penny": a vertical disk rolling without slipping on a convex table
{h < 0} and bouncing off the table's edge.

Source: the paper in shared/seeds (sections "Example: The vertical rolling
disk" and "Numerical Results").  This script is written independently of the
float64 simulator package (penny_env): it imports nothing from it and shares
no code with it.  Only mpmath, json, argparse and the standard library are used.

Conventions
-----------
State s = (x, y, theta, phi, theta_dot, phi_dot); (x, y) contact point,
theta rolling angle, phi heading.  theta and phi are never wrapped.
Params R, m, I, J; Itot = I + m R^2.  Metric g = diag(m, m, I, J) on
(x, y, theta, phi).  Flow with constant controls (u1, u2):
    phi_ddot = u1 / J,  theta_ddot = u2 / Itot,
    x_dot = R theta_dot cos(phi),  y_dot = R theta_dot sin(phi).
Ends: sigma = +1 (front) at (x, y) + R e^{i phi}, sigma = -1 (back) at
(x, y) - R e^{i phi}.  An impact is the first time t > t_prev at which
h(end) = 0 with d/dt h(end) > 0 (a touch with zero normal velocity is not
counted).  The earliest impact over both ends wins.

Tables: Ellipse(a, b): h = x^2/a^2 + y^2/b^2 - 1 (circle: a = b).
Stadium(r, L): h = dist(p, [-L/2, L/2] x {0}) - r, grad h = unit vector
from the nearest segment point to p.
RoundedRect(W, H, r): h = dist(p, [-W/2+r, W/2-r] x [-H/2+r, H/2-r]) - r (four
corner circles and four straight sides, each a quadric piece for the polynomial
impact search).

Impact laws (configuration unchanged, only velocities jump)
-----------------------------------------------------------
dS = (hx, hy, 0, sigma R (hy cos phi - hx sin phi)) is the differential of
q -> h(end(q)) with (hx, hy) = grad h at the end.
* elastic: the paper's system var_impact solved directly:
  p+ = p- + l1 w1 + l2 w2 + alpha dS, p = g qdot,
  w1 = dx - R cos(phi) dtheta, w2 = dy - R sin(phi) dtheta,
  w_k(qdot+) = 0 and equal kinetic energy.  With <a, b> = a g^{-1} b the
  two linear equations l_k <w_k, w_l> + alpha <dS, w_l> = 0 give
  l = alpha mu; the energy equation (paper eq. "quad") becomes
  alpha (A1 + alpha A2) = 0; the nonzero root alpha = -A1/A2 is taken
  (paper's Proposition on uniqueness).  qdot+ = g^{-1} p+ (4-vector; the
  state keeps theta_dot+, phi_dot+; x_dot+, y_dot+ are checked against the
  constraints).
* plastic: the paper's formulas literally: eq. var_penny (with the
  R (hy cos - hx sin) term multiplied by sigma) then the pi_Delta matrix
  (eq. pi_delta).  Analytically (asserted in impact_map_cases): the end's
  normal velocity changes by the factor 1 - 2 (c^2/(1+i) + (1-c^2)/j) /
  (1 + (1-c^2)/j), c = cos(angle(heading, wall normal)), i = I/(mR^2),
  j = J/(mR^2); the end keeps moving outward iff 2c^2/(1+i) + (1-c^2)/j < 1,
  which is possible if I > mR^2 OR J > mR^2 (never for i = 1/2, j = 1/4).
  Such post states are stored as they come (flagged), no further treatment.
* restitution e: in the constraint distribution (theta_dot, phi_dot) with
  metric diag(Itot, J), n(v) = a theta_dot + b phi_dot,
  a = R (hx cos phi + hy sin phi), b = sigma R (hy cos phi - hx sin phi),
  v+ = v - (1 + e) n(v) / (a^2/Itot + b^2/J) (a/Itot, b/J).
  Self-test: e = 1 coincides with the elastic law (asserted at every
  elastic impact and every impact-map case).

Flows (exact, no time stepping)
-------------------------------
* u1 = 0 (any u2): the heading is linear in time, so
  z(t) = z0 + R e^{i phi0} [theta_dot0 E0(t) + alpha2 E1(t)] with
  E0(t) = int_0^t e^{i w s} ds = t e^{i w t/2} sinc(w t/2) (no cancellation
  for any w, including w = 0) and E1(t) = int_0^t s e^{i w s} ds evaluated
  by its power series for |w t| < 1 and by the closed form otherwise.
  With u2 = 0 this is the paper's closed form (circle arcs / lines).
* u1 != 0: z(t) = z0 + R int_0^t (theta_dot0 + alpha2 s)
  exp(i (phi0 + phi_dot0 s + alpha1 s^2/2)) ds with mpmath.quad
  (Gauss-Legendre, adaptive degree) at 50 (+10 guard) digits, the interval
  split into pieces with phase change < 1.5 rad.  Cross-checked against
  an exact formula through the complex error function (Fresnel integral)
  at 90+ digits (see flow_cases.json "crosscheck").

Impact times
------------
* Uncontrolled flight (u1 = u2 = 0), phi_dot != 0: both ends move on the
  same circle: with rho = R theta_dot / phi_dot, z = x + i y,
  end(t) = c + (sigma R - i rho) e^{i phi(t)}, c = z0 + i rho e^{i phi0}.
  Each smooth piece of the wall (ellipse: one quadric; stadium: two cap
  circles, two straight sides) is a quadratic form in (X, Y) = end, hence a
  Laurent polynomial of degree <= 2 in zeta = e^{i phi}; multiplied by
  zeta^2 (or zeta) it is a polynomial of degree <= 4 whose roots are found
  with mpmath.polyroots (50 extra digits, maxsteps 400).  Roots with
  ||zeta| - 1| < 1e-30 are converted to times t = (arg zeta - phi0)/phi_dot
  mod 2 pi/|phi_dot| (the earliest occurrence after t_prev), polished by
  Newton's method on the exact closed-form trajectory (70 digits), kept only
  if the end lies on the corresponding piece (stadium) and the end moves
  outward (dh/dt > 0).  phi_dot = 0: straight lines, polynomial in t.
* Controlled flight (or as an independent cross-check of the above):
  dense sampling of h(end) for both ends with steps such that the heading
  changes < 0.05 rad and each end moves < 1e-4 m per step; every sign
  change (-) -> (+) is bracketed and solved by mpmath.findroot (anderson,
  bracketing) and polished by safeguarded Newton (dh/dt is exact).  Between
  samples a local maximum (dh/dt changing + -> - with h < 0 at both
  samples) is also located and checked, so short excursions are not missed.
  Controls are piecewise constant; they change at interval boundaries and
  impacts may happen inside intervals.

Self-checks (all asserted; results summarized in each JSON "diagnostics")
  elastic energy conserved (|dE|/E < 1e-40), elastic qdot+ satisfies the
  constraints (< 1e-40), e = 1 restitution == elastic (< 1e-40), ends on
  the wall at impacts (|h| < 1e-40), both ends inside the table between
  impacts (sampled), polynomial impact times == sampled impact times for all
  uncontrolled scenes, results at 50 digits == results at 70 digits (paper
  and extra scenes), flows: quad vs. erf formula / closed forms.
Grazing: each scene lists the relative normal speed
(dh/dt)/(|grad h| |v_end|) just before each impact.  The plastic (and, more
slowly, the restitution) scenes converge to a grazing orbit: the relative
normal speed shrinks by a factor ~2.7 (circle) / ~3 (ellipse) per impact and
reaches 1e-10..1e-11 by impact 25; such impacts are still resolved here
(excursion depth ~ 1e-22 m >> 1e-50) but are below float64 resolution.
Additional information: "float64_input_sensitivity" gives the change of
each impact time when the scene inputs (0.01, pi/2, ...) are replaced by the
nearest binary64 numbers, i.e. the best agreement a float64 simulator that
reads these inputs can be expected to reach, before its own rounding errors.

Inputs: in the scene files (A, B) the inputs are the decimal numbers as
written (R = 0.01 etc.; phi0 = pi/2 to 50 digits).  In flow_cases.json and
impact_map_cases.json all inputs, except the constructed on-wall contact
point (x, y) of the impact-map cases, are exactly representable binary64
numbers.  All numbers are stored as decimal strings with 45 significant
digits.

Usage:  python tests/reference/make_reference.py [--out DIR] [--skip-checks]
"""

import argparse
import bisect
import json
import math
import os
import random
import time

import mpmath
from mpmath import mp, mpf, mpc

DPS = 50
mp.dps = DPS
NDIG = 45  # significant digits written to JSON



def S(x):
    """Decimal string with NDIG significant digits."""
    x = mpf(x)
    if x == 0:
        return "0.0"
    return mpmath.nstr(x, NDIG, strip_zeros=False, min_fixed=-5, max_fixed=5)


def SL(v):
    return [S(t) for t in v]


# ---------------------------------------------------------------------------
# parameters and tables
# ---------------------------------------------------------------------------

class Params:
    def __init__(self, R, m, I, J):
        self.raw = (R, m, I, J)
        self.R, self.m, self.I, self.J = [mpf(v) for v in (R, m, I, J)]
        self.Itot = self.I + self.m * self.R ** 2

    def json(self):
        return {"R": S(self.R), "m": S(self.m), "I": S(self.I), "J": S(self.J)}


class Ellipse:
    def __init__(self, a, b):
        self.a, self.b = mpf(a), mpf(b)
        self.a2, self.b2 = self.a ** 2, self.b ** 2

    def h(self, x, y):
        return x * x / self.a2 + y * y / self.b2 - 1

    def grad(self, x, y):
        return (2 * x / self.a2, 2 * y / self.b2)

    def pieces(self):
        # (qxx, qyy, qx, qy, q0, valid(x, y))
        return [(1 / self.a2, 1 / self.b2, mpf(0), mpf(0), mpf(-1), lambda x, y: True)]

    def json(self):
        return {"type": "ellipse", "a": S(self.a), "b": S(self.b)}

    def max_extent(self):
        return max(self.a, self.b)


class Stadium:
    def __init__(self, r, L):
        self.r, self.L = mpf(r), mpf(L)
        self.hl = self.L / 2

    def _near(self, x):
        return min(max(x, -self.hl), self.hl)

    def h(self, x, y):
        sx = self._near(x)
        return mpmath.sqrt((x - sx) ** 2 + y ** 2) - self.r

    def grad(self, x, y):
        sx = self._near(x)
        d = mpmath.sqrt((x - sx) ** 2 + y ** 2)
        return ((x - sx) / d, y / d)

    def pieces(self):
        C, r, tol = self.hl, self.r, mpf("1e-30")
        return [
            (mpf(1), mpf(1), -2 * C, mpf(0), C * C - r * r, lambda x, y: x >= C - tol),   # right cap
            (mpf(1), mpf(1), 2 * C, mpf(0), C * C - r * r, lambda x, y: x <= -C + tol),   # left cap
            (mpf(0), mpf(0), mpf(0), mpf(1), -r, lambda x, y: abs(x) <= C + tol),         # top side
            (mpf(0), mpf(0), mpf(0), mpf(-1), -r, lambda x, y: abs(x) <= C + tol),        # bottom side
        ]

    def json(self):
        return {"type": "stadium", "radius": S(self.r), "length": S(self.L)}

    def max_extent(self):
        return self.hl + self.r


class RoundedRect:
    """|x| < W/2, |y| < H/2 with corners rounded to quarter circles of radius r:
    h = dist(p, inner rectangle [-ax, ax] x [-ay, ay]) - r, ax = W/2 - r, ay = H/2 - r."""

    def __init__(self, W, H, r):
        self.W, self.H, self.r = mpf(W), mpf(H), mpf(r)
        self.ax, self.ay = self.W / 2 - self.r, self.H / 2 - self.r

    def _offset(self, x, y):
        return x - min(max(x, -self.ax), self.ax), y - min(max(y, -self.ay), self.ay)

    def h(self, x, y):
        dx, dy = self._offset(x, y)
        return mpmath.sqrt(dx ** 2 + dy ** 2) - self.r

    def grad(self, x, y):
        dx, dy = self._offset(x, y)
        d = mpmath.sqrt(dx ** 2 + dy ** 2)
        if d == 0:  # inside the inner rectangle, far from the wall: only h is used there
            return (mpf(0), mpf(0))
        return (dx / d, dy / d)

    def pieces(self):
        ax, ay, r, tol = self.ax, self.ay, self.r, mpf("1e-30")
        out = []
        for sx in (1, -1):
            for sy in (1, -1):  # corner circles centred (sx ax, sy ay)
                out.append((mpf(1), mpf(1), -2 * sx * ax, -2 * sy * ay, ax * ax + ay * ay - r * r,
                            lambda x, y, sx=sx, sy=sy: sx * x >= ax - tol and sy * y >= ay - tol))
        for sx in (1, -1):  # sides x = +-(ax + r)
            out.append((mpf(0), mpf(0), mpf(sx), mpf(0), -(ax + r), lambda x, y: abs(y) <= ay + tol))
        for sy in (1, -1):  # sides y = +-(ay + r)
            out.append((mpf(0), mpf(0), mpf(0), mpf(sy), -(ay + r), lambda x, y: abs(x) <= ax + tol))
        return out

    def json(self):
        return {"type": "rounded_rectangle", "width": S(self.W), "height": S(self.H), "radius": S(self.r)}

    def max_extent(self):
        return max(self.W, self.H) / 2

    def piece_name(self, x, y):
        if abs(x) > self.ax and abs(y) > self.ay:
            return ("top" if y > 0 else "bottom") + "_" + ("right" if x > 0 else "left") + "_corner"
        return ("right_side" if x > 0 else "left_side") if abs(x) > self.ax else ("top_side" if y > 0 else "bottom_side")


def form_val(pc, X, Y):
    qxx, qyy, qx, qy, q0, _ = pc
    return qxx * X * X + qyy * Y * Y + qx * X + qy * Y + q0


def form_grad(pc, X, Y):
    qxx, qyy, qx, qy, q0, _ = pc
    return (2 * qxx * X + qx, 2 * qyy * Y + qy)


# ---------------------------------------------------------------------------
# kinematics
# ---------------------------------------------------------------------------

def end_pos(st, sigma, P):
    x, y, th, ph, thd, phd = st
    return (x + sigma * P.R * mpmath.cos(ph), y + sigma * P.R * mpmath.sin(ph))


def end_vel(st, sigma, P):
    x, y, th, ph, thd, phd = st
    c, s = mpmath.cos(ph), mpmath.sin(ph)
    return (P.R * thd * c - sigma * P.R * phd * s, P.R * thd * s + sigma * P.R * phd * c)


def h_and_hdot(st, sigma, table, P):
    ex, ey = end_pos(st, sigma, P)
    vx, vy = end_vel(st, sigma, P)
    gx, gy = table.grad(ex, ey)
    return table.h(ex, ey), gx * vx + gy * vy


def rel_normal_speed(st, sigma, table, P):
    """(dh/dt of the end) / (|grad h| |end velocity|): 1 = head-on, 0 = grazing."""
    ex, ey = end_pos(st, sigma, P)
    vx, vy = end_vel(st, sigma, P)
    gx, gy = table.grad(ex, ey)
    return (gx * vx + gy * vy) / (mpmath.sqrt(gx * gx + gy * gy) * mpmath.sqrt(vx * vx + vy * vy))


def energy(st, P):
    return (P.Itot * st[4] ** 2 + P.J * st[5] ** 2) / 2


def E1_unit(xx):
    """G(x) = int_0^1 u e^{i x u} du, stable for all real x."""
    if abs(xx) < 1:
        tot, term, n = mpc(0), mpc(1), 0
        eps = mpf(10) ** (-mp.dps - 5)
        while True:
            c = term / (n + 2)
            tot += c
            if abs(c) < eps and n > 3:
                break
            n += 1
            term = term * (1j * xx) / n
        return tot
    e = mpmath.expj(xx)
    return e / (1j * xx) + (e - 1) / (xx * xx)


class Flow:
    """Exact flow from state st0 with constant controls (u1, u2); s = time since start."""

    def __init__(self, st0, u1, u2, P):
        self.st0 = tuple(mpf(v) for v in st0)
        self.P = P
        self.u1, self.u2 = mpf(u1), mpf(u2)
        self.a1 = self.u1 / P.J
        self.a2 = self.u2 / P.Itot
        x, y = self.st0[0], self.st0[1]
        self.z0 = mpc(x, y)
        self.cks = [mpf(0)]      # checkpoints for the quad path
        self.ckz = [self.z0]

    def phi(self, s):
        return self.st0[3] + self.st0[5] * s + self.a1 * s * s / 2

    def _integrand(self, t):
        th0d, ph0, ph0d = self.st0[4], self.st0[3], self.st0[5]
        return self.P.R * (th0d + self.a2 * t) * mpmath.expj(ph0 + ph0d * t + self.a1 * t * t / 2)

    def _quad(self, a, b):
        if a == b:
            return mpc(0)
        ph0d = self.st0[5]
        wmax = max(abs(ph0d + self.a1 * a), abs(ph0d + self.a1 * b))
        n = int(mpmath.ceil(wmax * (b - a) / mpf("1.5")))
        n = max(n, 1)
        pts = [a + (b - a) * k / n for k in range(n + 1)]
        with mp.workdps(mp.dps + 10):
            val = mp.quad(self._integrand, pts, method="gauss-legendre")
        return val

    def z(self, s, checkpoint=False):
        s = mpf(s)
        R, th0d, ph0, w = self.P.R, self.st0[4], self.st0[3], self.st0[5]
        if self.a1 == 0:
            with mp.workdps(mp.dps + 10):
                E0 = s * mpmath.expj(w * s / 2) * mpmath.sinc(w * s / 2)
                acc = th0d * E0
                if self.a2 != 0:
                    acc += self.a2 * s * s * E1_unit(w * s)
                return self.z0 + R * mpmath.expj(ph0) * acc
        i = bisect.bisect_right(self.cks, s) - 1
        zs = self.ckz[i] + self._quad(self.cks[i], s)
        if checkpoint and s > self.cks[-1]:
            self.cks.append(s)
            self.ckz.append(zs)
        return zs

    def state(self, s, checkpoint=False):
        s = mpf(s)
        zz = self.z(s, checkpoint)
        x0, y0, th0, ph0, th0d, ph0d = self.st0
        return (zz.real, zz.imag,
                th0 + th0d * s + self.a2 * s * s / 2,
                ph0 + ph0d * s + self.a1 * s * s / 2,
                th0d + self.a2 * s,
                ph0d + self.a1 * s)


def flow_erf(st0, u1, u2, t, P):
    """Independent exact formula for u1 != 0 via the complex error function."""
    x0, y0, th0, ph0, th0d, ph0d = [mpf(v) for v in st0]
    t = mpf(t)
    extra = 40 + int(max(0, mpmath.log10(abs(ph0d) + 10))) * 3
    with mp.workdps(mp.dps + extra):
        a = (mpf(u1) / P.J) / 2
        b = ph0d
        a2 = mpf(u2) / P.Itot
        beta = b / (2 * a)
        k = mpmath.expj(-mpmath.pi / 4) * mpmath.sqrt(mpc(a))
        pref = mpmath.expj(-a * beta * beta) * mpmath.expj(mpmath.pi / 4) / mpmath.sqrt(mpc(a)) * mpmath.sqrt(mpmath.pi) / 2
        F = pref * (mpmath.erf(k * (t + beta)) - mpmath.erf(k * beta))
        G1 = (mpmath.expj(a * t * t + b * t) - 1) / (2j * a) - beta * F
        zz = mpc(x0, y0) + P.R * mpmath.expj(ph0) * (th0d * F + a2 * G1)
        a1 = 2 * a
        return (zz.real, zz.imag, th0 + th0d * t + a2 * t * t / 2, ph0 + ph0d * t + a1 * t * t / 2,
                th0d + a2 * t, ph0d + a1 * t)


# ---------------------------------------------------------------------------
# impact laws
# ---------------------------------------------------------------------------

def _geom(st, sigma, table, P):
    x, y, th, ph, thd, phd = st
    ex, ey = end_pos(st, sigma, P)
    hx, hy = table.grad(ex, ey)
    c, s = mpmath.cos(ph), mpmath.sin(ph)
    return hx, hy, c, s


def impact_elastic(st, sigma, table, P, info=None):
    x, y, th, ph, thd, phd = st
    R = P.R
    hx, hy, c, s = _geom(st, sigma, table, P)
    g = [P.m, P.m, P.I, P.J]
    qd = [R * thd * c, R * thd * s, thd, phd]
    w1 = [mpf(1), mpf(0), -R * c, mpf(0)]
    w2 = [mpf(0), mpf(1), -R * s, mpf(0)]
    dS = [hx, hy, mpf(0), sigma * R * (hy * c - hx * s)]

    def ip(a, b):  # <a, b> = a g^{-1} b for covectors
        return sum(a[i] * b[i] / g[i] for i in range(4))

    def pair(a, v):  # covector applied to a vector
        return sum(a[i] * v[i] for i in range(4))

    W = [w1, w2]
    G = mpmath.matrix([[ip(W[k], W[l]) for k in range(2)] for l in range(2)])  # row l, col k
    d = mpmath.matrix([ip(dS, W[l]) for l in range(2)])
    mu = mpmath.lu_solve(G, -d)  # lambda_k = alpha * mu_k
    p_minus = [g[i] * qd[i] for i in range(4)]
    # paper eq. (quad): 2 l_k <p-,w^k> + 2 a <p-,dS> + l_i l_j <w^i,w^j> + 2 l_k a <w^k,dS> + a^2 <dS,dS> = 0
    A1 = 2 * sum(mu[k] * ip(p_minus, W[k]) for k in range(2)) + 2 * ip(p_minus, dS)
    A2 = (sum(mu[i] * mu[j] * ip(W[i], W[j]) for i in range(2) for j in range(2))
          + 2 * sum(mu[k] * ip(W[k], dS) for k in range(2)) + ip(dS, dS))
    alpha = -A1 / A2
    lam = [alpha * mu[0], alpha * mu[1]]
    p_plus = [p_minus[i] + lam[0] * w1[i] + lam[1] * w2[i] + alpha * dS[i] for i in range(4)]
    qp = [p_plus[i] / g[i] for i in range(4)]
    if info is not None:
        E0 = sum(g[i] * qd[i] ** 2 for i in range(4)) / 2
        E1 = sum(g[i] * qp[i] ** 2 for i in range(4)) / 2
        scale = abs(qp[2]) * R + abs(qp[3]) * R + abs(qd[2]) * R + abs(qd[3]) * R
        info["energy_rel_err"] = abs(E1 - E0) / E0
        info["constraint_residual"] = max(abs(pair(w1, qp)), abs(pair(w2, qp))) / scale
        info["alpha"] = alpha
        info["normal_vel_before"] = pair(dS, qd)
        info["normal_vel_after"] = pair(dS, qp)
    return (x, y, th, ph, qp[2], qp[3])


def impact_plastic(st, sigma, table, P, info=None):
    x, y, th, ph, thd, phd = st
    R, m, I, J = P.R, P.m, P.I, P.J
    hx, hy, c, s = _geom(st, sigma, table, P)
    xd, yd = R * thd * c, R * thd * s
    tq = sigma * R * (hy * c - hx * s)
    C = -2 * (hx * xd + hy * yd + tq * phd) / ((hx * hx + hy * hy) / m + tq * tq / J)
    xd1 = xd + C / m * hx
    yd1 = yd + C / m * hy
    thd1 = thd
    phd1 = phd + C / J * tq
    It = I + m * R * R
    # (I + m R^2) pi_Delta = [[A, B], [C, D]] on (x_dot, y_dot, theta_dot, phi_dot)
    M = [[m * R * R * c * c, m * R * R * s * c, I * R * c, 0],
         [m * R * R * s * c, m * R * R * s * s, I * R * s, 0],
         [m * R * c, m * R * s, I, 0],
         [0, 0, 0, It]]
    v = [xd1, yd1, thd1, phd1]
    out = [sum(M[i][j] * v[j] for j in range(4)) / It for i in range(4)]
    if info is not None:
        info["constraint_residual"] = max(abs(out[0] - R * out[2] * c), abs(out[1] - R * out[2] * s)) / (
            R * abs(out[2]) + mpf("1e-300"))
        a = R * (hx * c + hy * s)
        info["normal_vel_before"] = a * thd + tq * phd
        info["normal_vel_after"] = a * out[2] + tq * out[3]
    return (x, y, th, ph, out[2], out[3])


def impact_restitution(st, sigma, table, P, e, info=None):
    x, y, th, ph, thd, phd = st
    R = P.R
    hx, hy, c, s = _geom(st, sigma, table, P)
    a = R * (hx * c + hy * s)
    b = sigma * R * (hy * c - hx * s)
    n = a * thd + b * phd
    k = (1 + mpf(e)) * n / (a * a / P.Itot + b * b / P.J)
    thd1 = thd - k * a / P.Itot
    phd1 = phd - k * b / P.J
    if info is not None:
        info["normal_vel_before"] = n
        info["normal_vel_after"] = a * thd1 + b * phd1
    return (x, y, th, ph, thd1, phd1)


def apply_law(law, e, st, sigma, table, P, checks):
    if law == "elastic":
        info = {}
        out = impact_elastic(st, sigma, table, P, info)
        alt = impact_restitution(st, sigma, table, P, 1)
        d = max(abs(out[4] - alt[4]) / (abs(out[4]) + abs(out[5]) + 1e-300),
                abs(out[5] - alt[5]) / (abs(out[4]) + abs(out[5]) + 1e-300))
        checks["max_elastic_energy_rel_err"] = max(checks.get("max_elastic_energy_rel_err", 0), info["energy_rel_err"])
        checks["max_elastic_constraint_residual"] = max(checks.get("max_elastic_constraint_residual", 0),
                                                        info["constraint_residual"])
        checks["max_elastic_vs_restitution1_rel_diff"] = max(
            checks.get("max_elastic_vs_restitution1_rel_diff", 0), d)
        tol = mpf(10) ** (-(mp.dps - 10))
        assert info["energy_rel_err"] < tol, info
        assert info["constraint_residual"] < tol, info
        assert d < tol, d
        assert info["normal_vel_after"] < 0
        return out
    if law == "plastic":
        info = {}
        out = impact_plastic(st, sigma, table, P, info)
        checks["max_plastic_post_normal_vel"] = max(checks.get("max_plastic_post_normal_vel", mpf("-inf")),
                                                    info["normal_vel_after"])
        return out
    if law == "restitution":
        return impact_restitution(st, sigma, table, P, e)
    raise ValueError(law)


# ---------------------------------------------------------------------------
# impact detection: polynomial method (uncontrolled)
# ---------------------------------------------------------------------------

def lp_mul(A, B):
    out = {}
    for i, a in A.items():
        for j, b in B.items():
            out[i + j] = out.get(i + j, 0) + a * b
    return out


def lp_add(*terms):
    out = {}
    for coef, A in terms:
        for i, a in A.items():
            out[i] = out.get(i, 0) + coef * a
    return out


def form_poly(pc, X, Y):
    qxx, qyy, qx, qy, q0, _ = pc
    return lp_add((qxx, lp_mul(X, X)), (qyy, lp_mul(Y, Y)), (qx, X), (qy, Y), (q0, {0: mpf(1)}))


def poly_roots_of(lp):
    """Roots of a Laurent polynomial (dict power -> coeff), nonzero roots only."""
    if not lp:
        return []
    cmax = max(abs(v) for v in lp.values())
    if cmax == 0:
        return []
    thr = cmax * mpf(10) ** (-(mp.dps - 5))
    pw = [p for p, v in lp.items() if abs(v) > thr]
    hi, lo = max(pw), min(pw)
    if hi == lo:
        return []
    coeffs = [lp.get(p, 0) for p in range(hi, lo - 1, -1)]
    roots = mp.polyroots(coeffs, maxsteps=400, extraprec=mp.prec + 50)
    return roots


class Diag:
    def __init__(self):
        self.near_grazing = []       # polynomial roots just off the unit circle
        self.min_candidate_gap = None
        self.min_rel_normal_speed = None

    def note_gap(self, g):
        if self.min_candidate_gap is None or g < self.min_candidate_gap:
            self.min_candidate_gap = g


def next_impact_poly(st, table, P, diag=None):
    """Earliest impact time s > 0 (relative) for uncontrolled flight; returns (s, sigma) or None."""
    x, y, th, ph, thd, phd = st
    R = P.R
    tiny = mpf(10) ** (-(mp.dps - 10))
    fl = Flow(st, 0, 0, P)
    cands = []
    with mp.workdps(mp.dps + 20):
        for sigma in (1, -1):
            for pc in table.pieces():
                times = []
                if phd != 0:
                    rho = R * thd / phd
                    cz = mpc(x, y) + 1j * rho * mpmath.expj(ph)
                    w = sigma * R - 1j * rho
                    X = {0: cz.real, 1: w / 2, -1: mpmath.conj(w) / 2}
                    Y = {0: cz.imag, 1: w / 2j, -1: -mpmath.conj(w) / 2j}
                    T = 2 * mpmath.pi / abs(phd)
                    for zeta in poly_roots_of(form_poly(pc, X, Y)):
                        dev = abs(abs(zeta) - 1)
                        if dev > mpf("1e-30"):
                            if diag is not None and dev < mpf("1e-8"):
                                diag.near_grazing.append(dev)
                            continue
                        psi = mpmath.arg(zeta)
                        s0 = (psi - ph) / phd
                        s0 = s0 - mpmath.floor(s0 / T) * T
                        times.append(s0)
                else:
                    ex, ey = end_pos(st, sigma, P)
                    vx, vy = R * thd * mpmath.cos(ph), R * thd * mpmath.sin(ph)
                    X = {0: ex, 1: vx}
                    Y = {0: ey, 1: vy}
                    for r in poly_roots_of(form_poly(pc, X, Y)):
                        if abs(r.imag) > mpf("1e-30") * (1 + abs(r)):
                            continue
                        times.append(r.real)
                for s0 in times:
                    # Newton polish on the exact trajectory
                    s1 = s0
                    for _ in range(8):
                        stt = fl.state(s1)
                        X1, Y1 = end_pos(stt, sigma, P)
                        vx, vy = end_vel(stt, sigma, P)
                        gx, gy = form_grad(pc, X1, Y1)
                        f = form_val(pc, X1, Y1)
                        df = gx * vx + gy * vy
                        if df == 0:
                            break
                        ds = f / df
                        s1 -= ds
                        if abs(ds) < mpf(10) ** (-(mp.dps + 15)) * (1 + abs(s1)):
                            break
                    if s1 <= tiny:
                        continue
                    stt = fl.state(s1)
                    X1, Y1 = end_pos(stt, sigma, P)
                    if not pc[5](X1, Y1):
                        continue
                    hval, hd = h_and_hdot(stt, sigma, table, P)
                    if hd <= 0:
                        continue
                    vx, vy = end_vel(stt, sigma, P)
                    gx, gy = table.grad(X1, Y1)
                    rel = hd / (mpmath.sqrt(gx ** 2 + gy ** 2) * mpmath.sqrt(vx ** 2 + vy ** 2))
                    cands.append((s1, sigma, rel))
    if not cands:
        return None
    cands.sort(key=lambda c: c[0])
    best = cands[0]
    if diag is not None:
        others = [c for c in cands[1:] if c[0] - best[0] > mpf(10) ** (-(mp.dps - 15)) or c[1] != best[1]]
        if others:
            diag.note_gap(others[0][0] - best[0])
        if diag.min_rel_normal_speed is None or best[2] < diag.min_rel_normal_speed:
            diag.min_rel_normal_speed = best[2]
    return (+best[0], best[1])


# ---------------------------------------------------------------------------
# impact detection: dense sampling (controlled flight, and cross-check)
# ---------------------------------------------------------------------------

def _refine_root(fun, dfun, a, b):
    """Root of fun in [a, b] with fun(a) < 0 <= fun(b): findroot(anderson) + safeguarded Newton."""
    try:
        r = mp.findroot(fun, (a, b), solver="anderson", verify=False, maxsteps=200)
        r = mpf(r.real) if isinstance(r, mpc) else mpf(r)
        if not (a <= r <= b):
            raise ValueError
    except Exception:
        lo, hi = a, b
        for _ in range(60):
            mid = (lo + hi) / 2
            if fun(mid) < 0:
                lo = mid
            else:
                hi = mid
        r = (lo + hi) / 2
    lo, hi = a, b
    for _ in range(30):
        f = fun(r)
        if f < 0:
            lo = max(lo, r)
        else:
            hi = min(hi, r)
        d = dfun(r)
        rn = r - f / d if d != 0 else (lo + hi) / 2
        if not (lo <= rn <= hi):
            rn = (lo + hi) / 2
        if abs(rn - r) < mpf(10) ** (-(mp.dps + 5)) * (1 + abs(r)):
            r = rn
            break
        r = rn
    return r


def next_impact_sampling(traj, table, P, smax, diag=None, step_scale=1):
    """First impact in (0, smax] along traj (a Flow), by dense sampling. Returns (s, sigma) or None."""
    R = P.R
    a1, a2 = abs(traj.a1), abs(traj.a2)

    def vals(stt):
        return {sg: h_and_hdot(stt, sg, table, P) for sg in (1, -1)}

    s = mpf(0)
    st = traj.state(s)
    v0 = vals(st)
    while s < smax:
        thd, phd = abs(st[4]), abs(st[5])
        ds = mpf(smax - s)
        for _ in range(2):
            phmax = phd + a1 * ds
            thmax = thd + a2 * ds
            lim = []
            if phmax > 0:
                lim.append(mpf("0.05") / phmax)
            if thmax + phmax > 0:
                lim.append(mpf("1e-4") / (R * (thmax + phmax)))
            if lim:
                ds = min([ds] + lim)
        ds = ds * step_scale
        s1 = min(s + ds, smax)
        st1 = traj.state(s1, checkpoint=True)
        v1 = vals(st1)
        found = []
        for sg in (1, -1):
            h0, hd0 = v0[sg]
            h1, hd1 = v1[sg]

            def fun(t, sg=sg):
                return h_and_hdot(traj.state(t), sg, table, P)[0]

            def dfun(t, sg=sg):
                return h_and_hdot(traj.state(t), sg, table, P)[1]

            if h0 < 0 and h1 >= 0:
                found.append((_refine_root(fun, dfun, s, s1), sg))
            elif h0 < 0 and h1 < 0 and hd0 > 0 and hd1 < 0:
                # local maximum inside the step: is it above the wall?
                tm = _refine_root(lambda t: -dfun(t), lambda t: -(dfun(t + mpf("1e-30")) - dfun(t)) / mpf("1e-30"),
                                  s, s1)
                if fun(tm) >= 0:
                    found.append((_refine_root(fun, dfun, s, tm), sg))
                    if diag is not None:
                        diag.setdefault("intra_step_excursions", 0)
                        diag["intra_step_excursions"] += 1
        if found:
            found.sort(key=lambda c: c[0])
            r, sg = found[0]
            hd = h_and_hdot(traj.state(r), sg, table, P)[1]
            assert hd > 0, "tangential touch found by sampler"
            return (r, sg)
        s, st, v0 = s1, st1, v1
    return None


# ---------------------------------------------------------------------------
# scenes
# ---------------------------------------------------------------------------

def check_inside(st, s_len, table, P, nsamp=40):
    """max of h over both ends on (0, s_len) (uncontrolled or controlled Flow given as st)."""
    worst = mpf("-inf")
    fl = st if isinstance(st, Flow) else Flow(st, 0, 0, P)
    for k in range(1, nsamp):
        stt = fl.state(s_len * k / nsamp)
        for sg in (1, -1):
            worst = max(worst, h_and_hdot(stt, sg, table, P)[0])
    return worst


def run_uncontrolled(st0, table, P, law, e, n_imp, t_final, method="poly", checks=None):
    """Simulate; returns dict with impacts (first n_imp), state at t_final, and counts."""
    if checks is None:
        checks = {}
    diag = Diag()
    t = mpf(0)
    st = tuple(mpf(v) for v in st0)
    times, ends, states = [], [], []
    n_before = 0
    st_final = None
    max_h_at_impact = mpf(0)
    max_inside = mpf("-inf")
    gaps = []
    reln = []
    while True:
        if method == "poly":
            nx = next_impact_poly(st, table, P, diag)
        else:
            # sample over at most a couple of periods / until t_final + margin
            horizon = max(mpf(t_final) - t, mpf(0)) + 10
            nx = next_impact_sampling(Flow(st, 0, 0, P), table, P, horizon)
        if st_final is None and (nx is None or t + nx[0] > t_final):
            st_final = Flow(st, 0, 0, P).state(mpf(t_final) - t)
        if nx is None or (len(times) >= n_imp and t + nx[0] > t_final):
            break
        s, sg = nx
        if method == "poly" and checks.get("inside_check", True):
            max_inside = max(max_inside, check_inside(st, s, table, P))
        pre = Flow(st, 0, 0, P).state(s)
        ex, ey = end_pos(pre, sg, P)
        max_h_at_impact = max(max_h_at_impact, abs(table.h(ex, ey)))
        post = apply_law(law, e, pre, sg, table, P, checks)
        if len(times) < n_imp:
            reln.append(rel_normal_speed(pre, sg, table, P))
        gaps.append(s)
        t = t + s
        st = post
        if t <= t_final:
            n_before += 1
        if len(times) < n_imp:
            times.append(t)
            ends.append(sg)
            states.append(post)
    return {"times": times, "ends": ends, "states": states, "state_final": st_final,
            "n_before_final": n_before, "max_abs_h_at_impact": max_h_at_impact,
            "max_h_between_impacts": max_inside, "gaps": gaps, "diag": diag, "checks": checks,
            "rel_normal_speed": reln}


def run_controlled(st0, table, P, law, e, controls, dt_ctrl, t_final, checks=None, step_scale=1):
    if checks is None:
        checks = {}
    t = mpf(0)
    st = tuple(mpf(v) for v in st0)
    times, ends, states = [], [], []
    max_h_at_impact = mpf(0)
    max_inside = mpf("-inf")
    sdiag = {}
    reln = []
    for k, (u1, u2) in enumerate(controls):
        t_end = dt_ctrl * (k + 1)
        while True:
            fl = Flow(st, u1, u2, P)
            nx = next_impact_sampling(fl, table, P, t_end - t, sdiag, step_scale)
            if nx is None:
                max_inside = max(max_inside, check_inside(fl, t_end - t, table, P, 10))
                st = fl.state(t_end - t)
                t = t_end
                break
            s, sg = nx
            max_inside = max(max_inside, check_inside(fl, s, table, P, 10))
            pre = fl.state(s)
            ex, ey = end_pos(pre, sg, P)
            max_h_at_impact = max(max_h_at_impact, abs(table.h(ex, ey)))
            st = apply_law(law, e, pre, sg, table, P, checks)
            reln.append(rel_normal_speed(pre, sg, table, P))
            t = t + s
            times.append(t)
            ends.append(sg)
            states.append(st)
    assert abs(t - t_final) < mpf("1e-40")
    return {"times": times, "ends": ends, "states": states, "state_final": st,
            "max_abs_h_at_impact": max_h_at_impact, "max_h_between_impacts": max_inside,
            "sampler": sdiag, "checks": checks, "rel_normal_speed": reln}


def maxdiff(a, b):
    return max([abs(mpf(x) - mpf(y)) for x, y in zip(a, b)] + [mpf(0)])


def fnum(x):
    return float(mpmath.nstr(mpf(x), 6)) if x is not None else None


def scene_json(name, P, table, law, e, st0, res, n_imp, t_final, final_name):
    d = {
        "name": name,
        "params": P.json(),
        "table": table.json(),
        "law": law,
        "restitution": S(e) if e is not None else None,
        "initial_state": SL(st0),
        "n_impacts_requested": n_imp,
        "n_impacts": len(res["times"]),
        "impact_times": SL(res["times"]),
        "impact_ends": list(res["ends"]),
        "impact_states": [SL(s) for s in res["states"]],
        "t_final": S(t_final),
        final_name: SL(res["state_final"]),
    }
    if "n_before_final" in res:
        d["n_impacts_before_t_final"] = res["n_before_final"]
    return d


def scene_diag(res, P, law):
    out = {
        "max_abs_h_at_impact": fnum(res["max_abs_h_at_impact"]),
        "max_h_of_ends_between_impacts_sampled": fnum(res["max_h_between_impacts"]),
        "impact_rel_normal_speed": [fnum(v) for v in res["rel_normal_speed"]],
        "impact_rel_normal_speed_note": "(dh/dt)/(|grad h| |v_end|) just before each impact; "
                                        "values << 1 are grazing impacts (ill-conditioned in float64)",
    }
    rn = res["rel_normal_speed"]
    for thr in ("1e-6", "1e-8"):
        idx = [k for k, v in enumerate(rn) if v < mpf(thr)]
        out[f"first_impact_index_0based_with_rel_normal_speed_below_{thr}"] = idx[0] if idx else None
    gaps = [b - a for a, b in zip(res["times"][:-1], res["times"][1:])]
    if gaps:
        out["min_time_between_impacts"] = fnum(min(gaps))
    for k, v in res["checks"].items():
        if k != "inside_check":
            out[k] = fnum(v)
    if "diag" in res:
        dg = res["diag"]
        out["min_gap_to_next_candidate_root"] = fnum(dg.min_candidate_gap)
        out["near_grazing_roots_off_circle"] = [fnum(v) for v in dg.near_grazing[:10]]
    return out


def compare_runs(r1, r2):
    n = min(len(r1["times"]), len(r2["times"]))
    dt = maxdiff(r1["times"][:n], r2["times"][:n])
    ds = mpf(0)
    for a, b in zip(r1["states"][:n], r2["states"][:n]):
        ds = max(ds, maxdiff(a, b))
    ds = max(ds, maxdiff(r1["state_final"], r2["state_final"]))
    same_ends = list(r1["ends"][:n]) == list(r2["ends"][:n]) and len(r1["times"]) == len(r2["times"])
    return dt, ds, same_ends


def record_crosscheck(dg, key, res, other, name=None):
    """Two runs of one scene agree (the same impacts, times within 1e-32): their largest differences go into the
    diagnostics dg under key."""
    dt, ds, same = compare_runs(res, other)
    assert same and dt < mpf("1e-32"), dt if name is None else (name, dt)
    dg[f"{key}_max_abs_diff_times"] = fnum(dt)
    dg[f"{key}_max_abs_diff_states"] = fnum(ds)


def f64(x):
    return mpf(float(mpf(x)))


# ---------------------------------------------------------------------------
# A. paper scenes
# ---------------------------------------------------------------------------

def default_params(exact=True):
    if exact:
        return Params(mpf("0.01"), mpf("0.0025"), mpf("1.25e-7"), mpf("6.25e-8"))
    return Params(mpf(0.01), mpf(0.0025), mpf(1.25e-7), mpf(6.25e-8))


def paper_scene_defs():
    defs = []
    for tname, (a, b) in (("circle", ("0.2", "0.2")), ("ellipse", ("0.15", "0.2"))):
        for law in ("elastic", "plastic"):
            defs.append((f"{tname}_{law}", (a, b), law))
    return defs


def build_A(do_checks, log):
    scenes = []
    for name, (a, b), law in paper_scene_defs():
        t0 = time.time()
        P = default_params()
        table = Ellipse(mpf(a), mpf(b))
        st0 = (mpf(0), mpf(0), mpf(0), mpmath.pi / 2, mpf(10), mpf("0.2"))
        res = run_uncontrolled(st0, table, P, law, None, 25, mpf(5), checks={})
        d = scene_json(name, P, table, law, None, st0, res, 25, mpf(5), "state_at_5")
        dg = scene_diag(res, P, law)
        if do_checks:
            # (1) independent sampler
            r2 = run_uncontrolled(st0, table, P, law, None, 25, mpf(5), method="sample", checks={})
            record_crosscheck(dg, "crosscheck_sampler", res, r2, name)
            # (2) 70 digits
            with mp.workdps(70):
                P70 = default_params()
                st70 = (mpf(0), mpf(0), mpf(0), mpmath.pi / 2, mpf(10), mpf("0.2"))
                r3 = run_uncontrolled(st70, Ellipse(mpf(a), mpf(b)), P70, law, None, 25, mpf(5),
                                      checks={"inside_check": False})
            record_crosscheck(dg, "precision_check_vs_70_digits", res, r3, name)
            # (3) float64-rounded inputs
            P64 = default_params(exact=False)
            st64 = tuple(f64(v) for v in st0)
            r4 = run_uncontrolled(st64, Ellipse(f64(a), f64(b)), P64, law, None, 25, mpf(5),
                                  checks={"inside_check": False})
            n = min(len(res["times"]), len(r4["times"]))
            d["float64_input_sensitivity"] = {
                "description": "abs difference of each impact time when all inputs are rounded to binary64",
                "abs_diff_impact_times": [fnum(abs(p - q)) for p, q in zip(res["times"][:n], r4["times"][:n])],
                "abs_diff_state_at_final": fnum(maxdiff(res["state_final"], r4["state_final"])),
                "same_end_sequence": list(res["ends"][:n]) == list(r4["ends"][:n]),
            }
        d["diagnostics"] = dg
        scenes.append(d)
        log(f"  A {name}: {len(res['times'])} impacts (n before 5 s: {res['n_before_final']}), "
            f"{time.time() - t0:.1f}s")
    return {
        "description": "Paper scenes (circle a=b=0.2 and ellipse a=0.15,b=0.2; elastic and plastic laws). "
                       "impact_states = state right after each impact (theta, phi continuous). "
                       "state_at_5 = state at t = 5.0 s.",
        "state_order": ["x", "y", "theta", "phi", "theta_dot", "phi_dot"],
        "scenes": scenes,
    }


# ---------------------------------------------------------------------------
# B. extra scenes
# ---------------------------------------------------------------------------

def build_B(do_checks, log):
    out = []
    P = default_params()
    # (i) stadium
    t0 = time.time()
    table = Stadium(mpf("0.1"), mpf("0.2"))
    st0 = (mpf("0.0"), mpf("0.02"), mpf(0), mpf("0.3"), mpf("8.0"), mpf("1.5"))
    res = run_uncontrolled(st0, table, P, "elastic", None, 20, mpf(3), checks={})
    d = scene_json("stadium_elastic", P, table, "elastic", None, st0, res, 20, mpf(3), "state_at_3")
    dg = scene_diag(res, P, "elastic")
    if do_checks:
        r2 = run_uncontrolled(st0, table, P, "elastic", None, 20, mpf(3), method="sample", checks={})
        record_crosscheck(dg, "crosscheck_sampler", res, r2)
        with mp.workdps(70):
            r3 = run_uncontrolled(st0, Stadium(mpf("0.1"), mpf("0.2")), default_params(), "elastic", None, 20,
                                  mpf(3), checks={"inside_check": False})
        record_crosscheck(dg, "precision_check_vs_70_digits", res, r3)
    # which piece of the wall was hit
    hits = []
    for s, sg in zip(res["states"], res["ends"]):
        ex, ey = end_pos(s, sg, P)
        hits.append("right_cap" if ex > table.hl else "left_cap" if ex < -table.hl else
                    ("top_side" if ey > 0 else "bottom_side"))
    d["impact_wall_pieces"] = hits
    d["diagnostics"] = dg
    out.append(d)
    log(f"  B stadium: {len(res['times'])} impacts, {time.time() - t0:.1f}s")

    # (ii) restitution
    t0 = time.time()
    table = Ellipse(mpf("0.2"), mpf("0.12"))
    st0 = (mpf("0.01"), mpf("-0.02"), mpf(0), mpf("1.0"), mpf("12.0"), mpf("-0.7"))
    e = mpf("0.6")
    res = run_uncontrolled(st0, table, P, "restitution", e, 15, mpf(3), checks={})
    d = scene_json("ellipse_restitution_0.6", P, table, "restitution", e, st0, res, 15, mpf(3), "state_at_3")
    dg = scene_diag(res, P, "restitution")
    if do_checks:
        r2 = run_uncontrolled(st0, table, P, "restitution", e, 15, mpf(3), method="sample", checks={})
        record_crosscheck(dg, "crosscheck_sampler", res, r2)
        with mp.workdps(70):
            r3 = run_uncontrolled(st0, Ellipse(mpf("0.2"), mpf("0.12")), default_params(), "restitution",
                                  mpf("0.6"), 15, mpf(3), checks={"inside_check": False})
        record_crosscheck(dg, "precision_check_vs_70_digits", res, r3)
    d["energy_after_each_impact"] = SL([energy(s, P) for s in res["states"]])
    d["diagnostics"] = dg
    out.append(d)
    log(f"  B restitution: {len(res['times'])} impacts, {time.time() - t0:.1f}s")

    # (iii) controlled
    t0 = time.time()
    table = Ellipse(mpf("0.2"), mpf("0.15"))
    controls = [(mpf("2e-8") * mpmath.sin(mpf("0.7") * k + mpf("0.3")), mpf("3e-8") * mpmath.cos(mpf("1.3") * k))
                for k in range(20)]
    dtc = mpf("0.1")
    note = None
    for thd0 in (mpf("5.0"), mpf("10.0"), mpf("15.0"), mpf("20.0"), mpf("30.0")):
        st0 = (mpf(0), mpf(0), mpf(0), mpf("0.4"), thd0, mpf("0.5"))
        res = run_controlled(st0, table, P, "elastic", None, controls, dtc, mpf(2), checks={})
        if len(res["times"]) >= 3:
            break
        log(f"    controlled scene: theta_dot0={mpmath.nstr(thd0, 4)} gives {len(res['times'])} impacts")
    if thd0 != 5:
        note = (f"theta_dot0 increased from 5.0 (fewer than 3 impacts in 2 s) to {mpmath.nstr(thd0, 6)}")
    d = {
        "name": "ellipse_elastic_controlled",
        "params": P.json(),
        "table": table.json(),
        "law": "elastic",
        "restitution": None,
        "initial_state": SL(st0),
        "controls": [SL(u) for u in controls],
        "control_formula": "u1_k = 2e-8*sin(0.7*k+0.3), u2_k = 3e-8*cos(1.3*k), k = 0..19, "
                           "applied on [0.1 k, 0.1 (k+1))",
        "control_interval": S(dtc),
        "theta_dot0_note": note,
        "n_impacts": len(res["times"]),
        "impact_times": SL(res["times"]),
        "impact_ends": list(res["ends"]),
        "impact_states": [SL(s) for s in res["states"]],
        "t_final": S(2),
        "state_at_2": SL(res["state_final"]),
    }
    dg = scene_diag(res, P, "elastic")
    dg["sampler"] = res["sampler"]
    if do_checks:
        with mp.workdps(60):
            ctr = [(mpf("2e-8") * mpmath.sin(mpf("0.7") * k + mpf("0.3")), mpf("3e-8") * mpmath.cos(mpf("1.3") * k))
                   for k in range(20)]
            st60 = (mpf(0), mpf(0), mpf(0), mpf("0.4"), mpf(mpmath.nstr(thd0, 10)), mpf("0.5"))
            r3 = run_controlled(st60, Ellipse(mpf("0.2"), mpf("0.15")), default_params(), "elastic", None, ctr,
                                mpf("0.1"), mpf(2), checks={}, step_scale=mpf("0.5"))
        record_crosscheck(dg, "crosscheck_60_digits_half_step", res, r3)
        # how much does the path curve? heading range
    d["heading_change_0_to_2"] = S(res["state_final"][3] - st0[3])
    d["diagnostics"] = dg
    out.append(d)
    log(f"  B controlled: {len(res['times'])} impacts, {time.time() - t0:.1f}s")
    return {
        "description": "Extra scenes: stadium (elastic), ellipse with restitution e=0.6, ellipse with "
                       "piecewise-constant controls (elastic).",
        "state_order": ["x", "y", "theta", "phi", "theta_dot", "phi_dot"],
        "scenes": out,
    }


# ---------------------------------------------------------------------------
# E. rounded rectangle scenes
# ---------------------------------------------------------------------------

def _rounded_rectangle():
    return RoundedRect(mpf("0.3"), mpf("0.2"), mpf("0.04"))


def build_E(do_checks, log):
    out = []
    P = default_params()
    for name, law, e, st0, n_imp in (
            ("rounded_rectangle_elastic", "elastic", None,
             (mpf("0.01"), mpf("0.02"), mpf(0), mpf("0.5"), mpf("9.0"), mpf("1.1")), 20),
            ("rounded_rectangle_plastic", "plastic", None,
             (mpf("-0.02"), mpf("0.01"), mpf(0), mpf("2.3"), mpf("12.0"), mpf("-0.8")), 15),
            ("rounded_rectangle_restitution_0.5", "restitution", mpf("0.5"),
             (mpf("0.03"), mpf("-0.01"), mpf(0), mpf("0.9"), mpf("15.0"), mpf("0.4")), 15)):
        t0 = time.time()
        table = _rounded_rectangle()
        res = run_uncontrolled(st0, table, P, law, e, n_imp, mpf(3), checks={})
        d = scene_json(name, P, table, law, e, st0, res, n_imp, mpf(3), "state_at_3")
        dg = scene_diag(res, P, law)
        if do_checks:
            r2 = run_uncontrolled(st0, table, P, law, e, n_imp, mpf(3), method="sample", checks={})
            record_crosscheck(dg, "crosscheck_sampler", res, r2)
            with mp.workdps(70):
                r3 = run_uncontrolled(st0, _rounded_rectangle(), default_params(), law, e, n_imp, mpf(3),
                                      checks={"inside_check": False})
            record_crosscheck(dg, "precision_check_vs_70_digits", res, r3)
        d["impact_wall_pieces"] = [table.piece_name(*end_pos(s, sg, P)) for s, sg in zip(res["states"], res["ends"])]
        d["diagnostics"] = dg
        out.append(d)
        log(f"  E {name}: {len(res['times'])} impacts, {time.time() - t0:.1f}s")
    return {
        "description": "Rounded rectangle 0.3 x 0.2 m, corner radius 0.04 m: elastic, plastic and "
                       "restitution 0.5 scenes (impacts on the sides and on the corners).",
        "state_order": ["x", "y", "theta", "phi", "theta_dot", "phi_dot"],
        "scenes": out,
    }


# ---------------------------------------------------------------------------
# C. flow cases
# ---------------------------------------------------------------------------

def flow_case_defs():
    base = (0.013, -0.021, 0.7, 1.1, 10.0)
    dP = (0.01, 0.0025, 1.25e-7, 6.25e-8)
    cases = []

    def add(tag, thd, phd, u1, u2, t, st=None, params=dP):
        s = list(st) if st is not None else [base[0], base[1], base[2], base[3], thd, phd]
        cases.append({"tag": tag, "state0": s, "u1": u1, "u2": u2, "t": t, "params": params})

    for phd in (0.0, 1e-12, 1e-8, 1e-3, 1.0, 1e4):
        add(f"free_phidot_{phd:g}", 10.0, phd, 0.0, 0.0, 0.7)
    for u1 in (1e-20, 1e-16, 1e-12):
        add(f"tiny_u1_{u1:g}_phidot0", 10.0, 0.0, u1, 0.0, 1.0)
        add(f"tiny_u1_{u1:g}_phidot0.8", 10.0, 0.8, u1, 0.0, 1.0)
    for u2 in (1e-20, 1e-16, 1e-12):
        add(f"tiny_u2_{u2:g}_phidot0", 10.0, 0.0, 0.0, u2, 1.0)
    add("tiny_u2_1e-16_phidot0.8", 10.0, 0.8, 0.0, 1e-16, 1.0)
    add("tiny_u2_1e-12_phidot0.8", 10.0, 0.8, 0.0, 1e-12, 1.0)
    add("large_u1_1e-5", 10.0, 0.5, 1e-5, 0.0, 1.0)
    add("large_u1_-1e-4", 10.0, 0.5, -1e-4, 0.0, 1.0)
    add("large_u1_1e-4_u2_1e-5", 10.0, 0.5, 1e-4, 1e-5, 1.0)
    add("long_free_t100", 10.0, 0.3, 0.0, 0.0, 100.0)
    add("long_free_t1000", 10.0, 0.3, 0.0, 0.0, 1000.0)
    add("long_u2_t100", 10.0, 0.3, 0.0, 1e-9, 100.0)
    add("long_u1_t100", 10.0, 0.3, 1e-10, 0.0, 100.0)
    add("long_u1_u2_t1000", 10.0, 0.3, 1e-12, -1e-12, 1000.0)
    add("fast_spin_u1_t0.05", 10.0, 1e4, 1e-8, 0.0, 0.05)
    add("fast_spin_u1_t1", 10.0, 1e4, 1e-8, 0.0, 1.0)
    add("fast_spin_u1_u2_t0.05", 10.0, 1e4, 1e-8, 1e-8, 0.05)
    add("theta_dot_1e3_free", 1e3, 2.0, 0.0, 0.0, 0.5)
    add("theta_dot_1e3_controlled", 1e3, -3.0, 1e-7, -1e-7, 0.5)
    add("theta_dot_sign_change_u2", 3.0, 0.0, 0.0, -1e-6, 2.0)
    add("theta_dot_sign_change_u1_u2", 3.0, 0.4, 3e-8, -1e-6, 2.0)
    rng = random.Random(20240611)
    while len(cases) < 40:
        R = 10 ** rng.uniform(-3, -1)
        m = 10 ** rng.uniform(-3, 0)
        I = 10 ** rng.uniform(-3, 1) * m * R * R
        J = 10 ** rng.uniform(-3, 1) * m * R * R
        st = [rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3), rng.uniform(-10, 10), rng.uniform(-10, 10),
              rng.uniform(-30, 30), rng.uniform(-20, 20)]
        kind = len(cases) % 3
        u1 = 0.0 if kind == 1 else rng.uniform(-1, 1) * J * 10 ** rng.uniform(-2, 2)
        u2 = 0.0 if kind == 2 else rng.uniform(-1, 1) * (I + m * R * R) * 10 ** rng.uniform(-2, 2)
        t = rng.uniform(0.01, 3.0)
        add(f"random_{len(cases)}", None, None, u1, u2, t, st=st, params=(R, m, I, J))
    return cases


def build_C(do_checks, log):
    out = []
    for c in flow_case_defs():
        t0 = time.time()
        P = Params(*[mpf(v) for v in c["params"]])
        st0 = tuple(mpf(v) for v in c["state0"])
        u1, u2, t = mpf(c["u1"]), mpf(c["u2"]), mpf(c["t"])
        fl = Flow(st0, u1, u2, P)
        stt = fl.state(t)
        d = {"tag": c["tag"], "params": P.json(), "state0": SL(st0), "u1": S(u1), "u2": S(u2), "t": S(t),
             "state_t": SL(stt)}
        if do_checks:
            cc = {}
            if u1 != 0:
                tol = mpf("1e-42") * (1 + abs(st0[4]) * P.R * t)
                a1 = u1 / P.J
                if abs(a1) * t * t > mpf("1e-6"):
                    # exact erf (Fresnel) formula
                    alt = flow_erf(st0, u1, u2, t, P)
                    cc["method"] = "erf formula (Fresnel integral), 90+ digits"
                    cc["max_abs_diff"] = fnum(maxdiff(stt, alt))
                    assert maxdiff(stt, alt) < tol, (c["tag"], maxdiff(stt, alt))
                else:
                    # the erf formula is ill-conditioned for tiny alpha1 (huge arguments); instead:
                    # z(t) = z_{u1=0}(t) + R int (th_dot0 + alpha2 s) e^{i phi_lin(s)} (e^{i alpha1 s^2/2} - 1) ds
                    # with e^{iq} - 1 = 2 i sin(q/2) e^{iq/2} (no cancellation), quad on pieces.
                    alt2 = Flow(st0, 0, u2, P).state(t)
                    R_, th0d, ph0, ph0d, al2 = P.R, st0[4], st0[3], st0[5], u2 / P.Itot

                    def dint(s_):
                        q = a1 * s_ * s_ / 2
                        return (R_ * (th0d + al2 * s_) * mpmath.expj(ph0 + ph0d * s_)
                                * 2j * mpmath.sin(q / 2) * mpmath.expj(q / 2))
                    n = max(1, int(mpmath.ceil(abs(ph0d) * t / mpf("1.5"))))
                    with mp.workdps(mp.dps + 10):
                        D = mp.quad(dint, [t * k / n for k in range(n + 1)], method="gauss-legendre")
                    dd = max(abs(stt[0] - alt2[0] - D.real), abs(stt[1] - alt2[1] - D.imag))
                    assert dd < tol, (c["tag"], dd)
                    cc["method"] = ("u1=0 closed form + quad of the (tiny) difference integrand "
                                    "R (th_dot0 + alpha2 s) e^{i phi_lin} (e^{i alpha1 s^2/2} - 1)")
                    cc["max_abs_diff"] = fnum(dd)
                    cc["size_of_u1_effect_on_position"] = fnum(abs(D))
            else:
                # quad on the same integrand (independent of the closed form)
                wt = abs(st0[5]) * t
                if wt < 2e4:
                    fq = Flow(st0, u1, u2, P)
                    fq.a1 = mpf(0)
                    R = P.R
                    z = fq.z0
                    n = max(1, int(mpmath.ceil(wt / mpf("1.5"))))
                    pts = [t * k / n for k in range(n + 1)]
                    with mp.workdps(mp.dps + 10):
                        z = z + mp.quad(fq._integrand, pts, method="gauss-legendre")
                    dz = max(abs(z.real - stt[0]), abs(z.imag - stt[1]))
                    cc["method"] = "mpmath.quad of the velocity"
                    cc["max_abs_diff"] = fnum(dz)
                    assert dz < mpf("1e-42") * (1 + abs(st0[4]) * R * t), (c["tag"], dz)
            d["crosscheck"] = cc
        out.append(d)
        log(f"  C {c['tag']}: {time.time() - t0:.2f}s")
    return {
        "description": "Open-plane flows with constant controls (u1, u2) for time t. "
                       "phi_ddot = u1/J, theta_ddot = u2/(I+mR^2), x_dot = R theta_dot cos phi, "
                       "y_dot = R theta_dot sin phi. All inputs are exact binary64 numbers.",
        "state_order": ["x", "y", "theta", "phi", "theta_dot", "phi_dot"],
        "cases": out,
    }


# ---------------------------------------------------------------------------
# D. impact map cases
# ---------------------------------------------------------------------------

def build_D(do_checks, log):
    rng = random.Random(7351)
    out = []
    for k in range(30):
        R = 10 ** rng.uniform(-3, -1)
        m = 10 ** rng.uniform(-3, 0)
        if k % 4 == 0:
            ri = 10 ** rng.uniform(0.05, 1)       # I > m R^2
        else:
            ri = 10 ** rng.uniform(-3, 1)
        rj = 10 ** rng.uniform(-3, 1)
        I, J = ri * m * R * R, rj * m * R * R
        P = Params(mpf(R), mpf(m), mpf(I), mpf(J))
        if k % 3 == 0:
            r = R * rng.uniform(5, 100)
            a = b = r
        else:
            a, b = R * rng.uniform(5, 100), R * rng.uniform(5, 100)
        table = Ellipse(mpf(a), mpf(b))
        sigma = 1 if rng.random() < 0.5 else -1
        tpar = rng.uniform(-math.pi, math.pi)
        phi = rng.uniform(-math.pi, math.pi)
        # outward normal at the wall point (float estimate only used to orient phi)
        wx, wy = a * math.cos(tpar), b * math.sin(tpar)
        nx, ny = wx / a ** 2, wy / b ** 2
        nn = math.hypot(nx, ny)
        if sigma * (math.cos(phi) * nx + math.sin(phi) * ny) / nn < 0.05:
            phi = phi + math.pi
            if sigma * (math.cos(phi) * nx + math.sin(phi) * ny) / nn < 0.05:
                phi = math.atan2(ny, nx) if sigma > 0 else math.atan2(-ny, -nx)
        thd = 10 ** rng.uniform(-1, 2) * (1 if rng.random() < 0.5 else -1)
        phd = rng.uniform(-50, 50)
        Wx, Wy = mpf(a) * mpmath.cos(mpf(tpar)), mpf(b) * mpmath.sin(mpf(tpar))
        ph = mpf(phi)
        x = Wx - sigma * P.R * mpmath.cos(ph)
        y = Wy - sigma * P.R * mpmath.sin(ph)
        st = (x, y, mpf(rng.uniform(-5, 5)), ph, mpf(thd), mpf(phd))
        h, hd = h_and_hdot(st, sigma, table, P)
        if hd < 0:
            st = st[:4] + (-st[4], -st[5])
            h, hd = h_and_hdot(st, sigma, table, P)
        assert hd > 0 and abs(h) < mpf("1e-45")
        checks = {}
        post_el = apply_law("elastic", None, st, sigma, table, P, checks)
        info = {}
        post_pl = impact_plastic(st, sigma, table, P, info)
        post_e3 = impact_restitution(st, sigma, table, P, mpf(0.3))
        # analytic check of the plastic law: with c = n_hat . e_phi, s'^2 = 1 - c^2, i = I/(mR^2),
        # j = J/(mR^2): n+/n- = 1 - 2 (c^2/(1+i) + s'^2/j) / (1 + s'^2/j); outward iff 2c^2/(1+i) + s'^2/j < 1
        gx_, gy_ = table.grad(*end_pos(st, sigma, P))
        cc_ = (gx_ * mpmath.cos(st[3]) + gy_ * mpmath.sin(st[3])) / mpmath.sqrt(gx_ ** 2 + gy_ ** 2)
        ii_, jj_ = P.I / (P.m * P.R ** 2), P.J / (P.m * P.R ** 2)
        ratio_formula = 1 - 2 * (cc_ ** 2 / (1 + ii_) + (1 - cc_ ** 2) / jj_) / (1 + (1 - cc_ ** 2) / jj_)
        ratio = info["normal_vel_after"] / info["normal_vel_before"]
        assert abs(ratio - ratio_formula) < mpf("1e-40"), (ratio, ratio_formula)
        if do_checks:
            # e = 1 equal to elastic asserted in apply_law; e = 0.3 energy must not increase
            assert energy(post_e3, P) <= energy(st, P) * (1 + mpf("1e-45"))
            assert energy(post_pl, P) <= energy(st, P) * (1 + mpf("1e-45"))
        def nv(s_):
            return h_and_hdot(s_, sigma, table, P)[1]
        d = {
            "case": k,
            "params": P.json(),
            "I_over_mR2": S(P.I / (P.m * P.R ** 2)),
            "J_over_mR2": S(P.J / (P.m * P.R ** 2)),
            "table": table.json(),
            "end": sigma,
            "pre_state": SL(st),
            "post_elastic": SL(post_el),
            "post_plastic": SL(post_pl),
            "restitution_e": S(mpf(0.3)),
            "post_restitution": SL(post_e3),
            "end_normal_velocity_dh_dt": {
                "pre": S(nv(st)), "elastic": S(nv(post_el)), "plastic": S(nv(post_pl)),
                "restitution": S(nv(post_e3))},
            "kinetic_energy": {"pre": S(energy(st, P)), "elastic": S(energy(post_el, P)),
                               "plastic": S(energy(post_pl, P)), "restitution": S(energy(post_e3, P))},
            "plastic_end_still_moving_outward": bool(nv(post_pl) > 0),
            "plastic_normal_velocity_ratio": S(ratio),
            "cos_angle_heading_normal": S(cc_),
            "checks": {k2: fnum(v) for k2, v in checks.items()},
        }
        out.append(d)
    log(f"  D: {len(out)} cases, {sum(d['plastic_end_still_moving_outward'] for d in out)} with plastic outward")
    return {
        "description": "Single impacts: pre_state has the given end ('end': +1 front, -1 back) exactly on the "
                       "wall moving outward. Post states for elastic, plastic (paper formulas) and restitution "
                       "e=0.3. Params/table/theta/phi/velocities are exact binary64 numbers; (x, y) is "
                       "wall point - sigma R e^{i phi} at 50 digits. The plastic post state may still move "
                       "outward (plastic_end_still_moving_outward); analytically (checked) "
                       "n+/n- = 1 - 2 (c^2/(1+i) + (1-c^2)/j) / (1 + (1-c^2)/j) with c = cos(angle between "
                       "heading and wall normal), i = I/(mR^2), j = J/(mR^2), so outward motion happens iff "
                       "2 c^2/(1+i) + (1-c^2)/j < 1, possible when I > mR^2 OR J > mR^2 (never for the "
                       "paper's i = 1/2, j = 1/4).",
        "state_order": ["x", "y", "theta", "phi", "theta_dot", "phi_dot"],
        "cases": out,
    }


# ---------------------------------------------------------------------------

def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[1])
    ap.add_argument("--out", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "studies",
                                                 "reference_data"))
    ap.add_argument("--skip-checks", action="store_true", help="skip the (slower) cross-checks")
    ap.add_argument("--only", default="ABCDE")
    args = ap.parse_args()
    mp.dps = DPS
    os.makedirs(args.out, exist_ok=True)
    do_checks = not args.skip_checks
    t_all = time.time()

    def log(msg):
        print(msg, flush=True)

    meta = {"generator": "tests/reference/make_reference.py", "mpmath_version": mpmath.__version__,
            "working_digits": DPS, "stored_significant_digits": NDIG, "cross_checks_run": do_checks}
    for key, fname, fn in (("A", "paper_scenes.json", build_A), ("B", "extra_scenes.json", build_B),
                           ("C", "flow_cases.json", build_C), ("D", "impact_map_cases.json", build_D),
                           ("E", "rounded_rectangle_scenes.json", build_E)):
        if key not in args.only:
            continue
        t0 = time.time()
        log(f"building {fname}")
        data = fn(do_checks, log)
        data["meta"] = dict(meta, seconds=round(time.time() - t0, 1))
        with open(os.path.join(args.out, fname), "w") as f:
            json.dump(data, f, indent=1)
        log(f"wrote {fname} ({time.time() - t0:.1f}s)")
    log(f"total {time.time() - t_all:.1f}s")


if __name__ == "__main__":
    main()
