"""Truncation error of the n-node Gauss-Legendre rules used by physics/flows.py, by mpmath at 40 digits.

For each rule size n and phase sweep (as flow.phase_sweep measures it: max(|w|, |w + a|) + |a| / 2
on [0, 1]) the worst relative error of the rule on int_0^1 (c0 + c1 u) exp(i (w u + a u^2 / 2)) du,
over linear, mixed, quadratic and turning-point phases and over amplitudes 1, u and 1 - 2u,
relative to int_0^1 |c0 + c1 u| du. The nodes are Newton-polished in mpmath (independent of numpy's
float64 nodes). flow.RULE_SIZES keeps every rule where this error is below 5e-17.

    python tests/reference/quadrature_rules.py
"""
import mpmath as mp
import numpy as np

mp.mp.dps = 40
SWEEPS = (0.05, 0.1, 0.15, 0.2, 0.3, 0.5, 0.8, 1.0, 1.5, 2.0, 3.0)
SIZES = (6, 7, 8, 9, 10, 12)


def nodes(n):
    xs, ws = [], []
    for x0 in np.polynomial.legendre.leggauss(n)[0]:
        x = mp.mpf(float(x0))
        for _ in range(6):
            p = mp.legendre(n, x)
            x -= p / (n * (x * p - mp.legendre(n - 1, x)) / (x * x - 1))
        dp = n * (x * mp.legendre(n, x) - mp.legendre(n - 1, x)) / (x * x - 1)
        xs.append((x + 1) / 2)
        ws.append(1 / ((1 - x ** 2) * dp ** 2))
    return xs, ws


def worst_error(xs, ws, sweep):
    err = mp.mpf(0)
    for split in (1.0, 0.7, 0.3, 0.0, -0.5):
        w0, a0 = split, (1 - abs(split)) * 2
        k = sweep / (max(abs(w0), abs(w0 + a0)) + 0.5 * abs(a0))
        w, a = w0 * k, a0 * k
        for c0, c1 in ((1, 0), (0, 1), (1, -2)):
            f = lambda u: (c0 + c1 * u) * mp.expj(w * u + a * u * u / 2)  # noqa: E731
            exact = mp.quad(f, [0, 0.5, 1])
            rule = sum(wt * f(x) for x, wt in zip(xs, ws))
            err = max(err, abs(rule - exact) / mp.quad(lambda u: abs(c0 + c1 * u), [0, 0.5, 1]))
    return err


if __name__ == "__main__":
    print("n    " + " ".join(f"{s:>7}" for s in SWEEPS))
    for n in SIZES:
        xs, ws = nodes(n)
        print(f"{n:<4} " + " ".join(f"{float(worst_error(xs, ws, s)):7.0e}" for s in SWEEPS), flush=True)
