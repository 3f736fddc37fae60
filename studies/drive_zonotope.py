"""The exact fewest control rows of a drive-only plan without impacts, with a validated certificate.

Drive only (u1 = 0) and no impact: phi_dot is the start's omega forever (theorem T3.1), so the heading is
phi(t) = phi0 + omega t whatever the rolling torque, and over K rows of length dt with scaled torques v_k in [-1, 1]
(theta'' = a v_k, a = u2_max / (I + m R^2)) the rolling speed is theta_dot(t) = w0 + a sum_k v_k r_k(t),
r_k(t) = clamp(t - k dt, 0, dt). The contact point at T = K dt is therefore **affine in the torques**:

    z(T) = c_K + sum_k v_k g_k,    c_K = z0 + R w0 E(0, T),    g_k = R a int_{k dt}^{(k+1) dt} E(s, T) ds,
    E(s, T) = int_s^T e(phi(t)) dt,

so the set of end points of K-row plans is the zonotope Z_K = c_K + sum_k [-1, 1] g_k, exactly. The distance from the
target g to it is max over unit d of d . (g - c_K) - sum_k |d . g_k| (support function); a K-row plan reaches the
terminal set (|z - g| <= tol) iff that distance is <= tol. On a table an impact-free plan moves exactly as on the
open plane, so **no impact-free plan reaches the set in fewer rows than the fewest K of the plane**: that K is the
exact answer for the relaxation without walls and a lower bound on the table.

:func:`fewest_rows` scans K = 1, 2, ... in float64 (the distance is maximised exactly over the direction: between
two consecutive angles where some d . g_k changes sign the objective is one sinusoid). For every K below the first
reachable one it **certifies** the distance with mpmath's interval arithmetic (:func:`certify_far`): the
generators, the centre, the direction's components and the support function are intervals that contain the exact
values (outward rounding), and the certificate holds only if the lower end of the interval of
(d . (g - c_K) - sum |d . g_k|) / |d| exceeds tol. A float64 near-tie can only make the certificate fail (then the
bound is the last certified K + 1, still valid); floating point never decides a claim here.
"""
from __future__ import annotations

import math

import numpy as np

GAUSS = np.polynomial.legendre.leggauss(8)  # float search only: E(s, T) is smooth in s, the rule is exact to ~1e-16


def _E(phi0, omega, s, T):
    """E(s, T) = int_s^T e(phi0 + omega t) dt (float64, stable for small omega): (T - s) sinc(omega (T - s) / 2)
    e(phi at the midpoint)."""
    L = T - s
    x = 0.5 * omega * L
    sinc = np.sinc(x / math.pi)  # np.sinc(y) = sin(pi y) / (pi y)
    mid = phi0 + omega * 0.5 * (s + T)
    return np.stack([L * sinc * np.cos(mid), L * sinc * np.sin(mid)], axis=-1)


def generators(z0, phi0, omega, w0, R, a, dt, K):
    """(centre c_K (2,), generators g (K, 2)) of the zonotope of K-row drive-only end points, float64."""
    T = K * dt
    c = np.asarray(z0, float)[:2] + R * w0 * _E(phi0, omega, 0.0, T)
    x, wq = GAUSS
    k = np.arange(K)[:, None]
    s = (k + 0.5 * (x[None, :] + 1.0)) * dt  # Gauss nodes inside each row
    Es = _E(phi0, omega, s, T)  # (K, 8, 2)
    g = R * a * 0.5 * dt * np.einsum("q,kqj->kj", wq, Es)
    return c, g


def distance(target, c, g):
    """(distance from target to the zonotope c + sum [-1, 1] g_k, the best direction's angle), float64: the max over
    unit d of d . (target - c) - sum |d . g_k|, piecewise sinusoidal in the angle, maximised piece by piece."""
    p = np.asarray(target, float)[:2] - c
    if len(g) == 0:
        return float(math.hypot(*p)), float(math.atan2(p[1], p[0]))
    # the angles where d . g_k = 0 split the circle into arcs with a fixed sign pattern
    ang = np.arctan2(g[:, 1], g[:, 0])
    cuts = np.sort(np.concatenate([ang + 0.5 * math.pi, ang - 0.5 * math.pi]) % (2 * math.pi))
    mids = 0.5 * (cuts + np.roll(cuts, -1))
    mids[-1] += math.pi  # the arc that wraps around
    best, best_t = -math.inf, 0.0
    cand = []
    for lo, hi, mid in zip(cuts, np.roll(cuts, -1), mids):
        d = np.array([math.cos(mid), math.sin(mid)])
        sgn = np.sign(g @ d)
        m = p - sgn @ g  # on this arc the objective is d . m
        t = math.atan2(m[1], m[0])
        hi = hi + 2 * math.pi if hi <= lo else hi
        tt = lo + ((t - lo) % (2 * math.pi))
        cand += [tt if tt <= hi else lo, hi, mid]
    cand = np.array(cand)
    D = np.stack([np.cos(cand), np.sin(cand)], axis=1)
    vals = D @ p - np.abs(D @ g.T).sum(axis=1)
    i = int(np.argmax(vals))
    best, best_t = float(vals[i]), float(cand[i])
    return best, best_t


def extremal_plan(g, angle, toward=True):
    """The bang-bang torques (K,) that move the end point farthest along d(angle) (toward=True) or against it: the
    vertex of the zonotope where d . z is largest, v_k = sign(d . g_k)."""
    d = np.array([math.cos(angle), math.sin(angle)])
    s = np.sign(g @ d)
    s[s == 0] = 1.0
    return s if toward else -s


def nearest_plan(target, c, g, iters=4000):
    """Torques v in [-1, 1]^K whose end point c + g^T v is (nearly) the zonotope's nearest to the target: projected
    gradient on the box (float64; used only to exhibit a plan, which is then simulated)."""
    p = np.asarray(target, float)[:2] - c
    v = np.zeros(len(g))
    L = max(float(np.linalg.norm(g, 2) ** 2), 1e-300)
    for _ in range(iters):
        r = g.T @ v - p
        v = np.clip(v - (g @ r) / L, -1.0, 1.0)
    return v


# -- the validated certificate ---------------------------------------------------------------------------
def certify_far(z0, phi0, omega, w0, R, a, dt, K, target, tol, angle, rel_a=1e-12):
    """True if, with interval arithmetic (mpmath.iv), every K-row drive-only plan without impacts ends farther than
    tol from the target: the lower end of (d . (target - c_K) - sum_k |d . g_k|) / |d| exceeds tol, d = (cos angle,
    sin angle) as intervals. The inputs are float64 numbers taken exactly; a is widened by rel_a (the simulator's
    float64 torque / inertia), dt and R enter as the float64 values the simulator uses."""
    from mpmath import iv, mpf

    dps = 30 + int(max(0.0, -math.log10(abs(omega)))) * 2 if omega != 0.0 else 30
    old = iv.dps
    iv.dps = dps
    try:
        return _certify(iv, mpf, z0, phi0, omega, w0, R, a, dt, K, target, tol, angle, rel_a)
    finally:
        iv.dps = old


def interval_zonotope(iv, z0, phi0, omega, w0, R, a, dt, K, rel_a=1e-12):
    """(centre (cx, cy), generators [(gx, gy)] * K) of the K-row zonotope as mpmath intervals, from the closed forms
    (module docstring): they contain the exact values for the float64 inputs."""
    dt_, R_, w0_, om = iv.mpf(dt), iv.mpf(R), iv.mpf(w0), iv.mpf(omega)
    a_ = iv.mpf(a) * iv.mpf([1 - rel_a, 1 + rel_a])
    T = dt_ * K
    ph0 = iv.mpf(phi0)

    def F(t):  # (sin phi(t), -cos phi(t))
        ph = ph0 + om * t
        return iv.sin(ph), -iv.cos(ph)

    def H(t):  # (cos phi(t), sin phi(t))
        ph = ph0 + om * t
        return iv.cos(ph), iv.sin(ph)

    if omega == 0.0:
        ex, ey = iv.cos(ph0), iv.sin(ph0)
        E0 = (T * ex, T * ey)
        gen = [(ex * dt_ * (T - dt_ * k - dt_ / 2), ey * dt_ * (T - dt_ * k - dt_ / 2)) for k in range(K)]
    else:
        FT, F0 = F(T), F(iv.mpf(0))
        E0 = ((FT[0] - F0[0]) / om, (FT[1] - F0[1]) / om)
        gen = []
        for k in range(K):
            ha, hb = H(dt_ * k), H(dt_ * (k + 1))
            # int_a^b E(s, T) ds = (dt F(T) - int_a^b F(s) ds) / omega, int_a^b F = (H(a) - H(b)) / omega
            gen.append(((dt_ * FT[0] - (ha[0] - hb[0]) / om) / om, (dt_ * FT[1] - (ha[1] - hb[1]) / om) / om))
    centre = (iv.mpf(z0[0]) + R_ * w0_ * E0[0], iv.mpf(z0[1]) + R_ * w0_ * E0[1])
    return centre, [(R_ * a_ * gx, R_ * a_ * gy) for gx, gy in gen]


def _certify(iv, mpf, z0, phi0, omega, w0, R, a, dt, K, target, tol, angle, rel_a):
    (cx, cy), gen = interval_zonotope(iv, z0, phi0, omega, w0, R, a, dt, K, rel_a)
    dx, dy = iv.cos(iv.mpf(angle)), iv.sin(iv.mpf(angle))
    val = dx * (iv.mpf(target[0]) - cx) + dy * (iv.mpf(target[1]) - cy)
    for gx, gy in gen:
        val -= abs(dx * gx + dy * gy)
    q = val / iv.sqrt(dx * dx + dy * dy)  # the distance is at least this for any nonzero d
    return bool(mpf(q.a) > mpf(tol) * (1 + 1e-12))  # (1e-12: the terminal set's float hypot, a few ulp off)


def fewest_rows(z0, phi0, omega, w0, R, a, dt, target, tol, max_rows=400):
    """(K, exact): K the fewest rows of a drive-only impact-free plan ending within tol of the target, as far as
    certified: every K' < K is certified unreachable (:func:`certify_far`); exact is True when K itself is reachable
    in float64 (the zonotope's distance <= tol), i.e. K is the fewest rows of the open plane, not only a bound.
    (max_rows + 1, False) when none of max_rows rows reaches it."""
    for K in range(1, max_rows + 1):
        c, g = generators(z0, phi0, omega, w0, R, a, dt, K)
        dist, angle = distance(target, c, g)
        if dist <= tol:
            return K, True
        if not certify_far(z0, phi0, omega, w0, R, a, dt, K, target, tol, angle):
            return K, False  # a float64 near-tie: K is not certified unreachable, so it is the (valid) bound
    return max_rows + 1, False
