"""How far two correct computations of the penny's largest Lyapunov exponent can differ: a bound from the package's own
numbers, for the referee's finding that an independent code agrees within 2.6 standard errors on 4 orbits but is
lower on all 4.

    python -m studies.lyapunov_spread [--orbits 4] [--copies 3] [--impacts 20000] [--out docs/lyapunov_spread.md]
    python -m studies.lyapunov_spread --quick      # 2 orbits, 1 copy, 300 impacts, into a temporary folder

The orbits are the first `orbits` of the billiards report's elastic stadium orbits drawn from the invariant measure
(studies/billiards_answer.py: the same sampler, seed and count). Per orbit, three numbers against the batch-means
standard error (SE) of the report's own estimate:

* lambda1 as the report computes it: QR after every impact of the 5 x 5 section maps, started from the section
  chart, in the coordinates (x, y, phi, theta_dot, phi_dot) (boundary_map.qr_exponents);
* the norm's share: lambda1 from the same maps in the chart's own coordinates (s, phi, psi) (the 3 x 3 maps). Two
  norms change log|v_n| by at most the log of their ratio, so this part of any difference shrinks like 1/n;
* the orbit's share: lambda1 of `copies` orbits started 1e-12 rad away (the velocity's direction psi turned, the
  start on the wall kept). An independent integrator's round-off (1e-16 per step) separates its orbit from this one
  as much after a few hundred impacts; from there the two finite-time estimates are samples along different orbits
  of a mixed phase space, and their spread is what two correct codes can differ by.
"""
from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from penny_env.analysis import boundary_map as bm
from penny_env.physics import PennyParams, make_table
from studies.billiards_answer import CONFIGS, PAPER_STATE, TABLES, batch_se, increments

ROOT = Path(__file__).resolve().parents[1]
TABLE = "stadium"
SEED = list(TABLES).index(TABLE)  # the seed billiards_answer.run gives this table's orbits
TURN = 1e-12                      # [rad] the copies' start: psi turned by +-TURN, +-2 TURN, ...
REFEREE_SE = 2.6                  # the referee's largest difference on its 4 orbits, in the package's SE (issue text)


def turned(state, angle, params):
    """The state with the scaled velocity (sqrt(I + m R^2) theta_dot, sqrt(J) phi_dot) turned by angle (same energy,
    same place)."""
    s = np.array(state, float)
    u, w = math.sqrt(params.rolling_inertia) * s[4], math.sqrt(params.J) * s[5]
    c, sn = math.cos(angle), math.sin(angle)
    s[4], s[5] = (c * u - sn * w) / math.sqrt(params.rolling_inertia), (sn * u + c * w) / math.sqrt(params.J)
    return s


def exponents(orb, i, tab, params):
    """(lambda1 from the 5 x 5 section maps as billiards_answer computes it, its batch-means SE, lambda1 from the
    3 x 3 chart maps, impacts) of orbit i."""
    tm = bm.tangent_maps(orb, i)
    T0 = bm.section_chart(orb.post[0, i], orb.ends[0, i], tab, params)
    run5 = bm.qr_exponents(tm.section, T0)
    top = int(np.argmax(run5[-1]))
    run3 = bm.qr_exponents(tm.section3, np.eye(3))
    return float(run5[-1, top]), batch_se(increments(run5[:, top])), float(run3[-1].max()), len(tm.section)


def study(orbits, copies, impacts):
    params = PennyParams()
    rho = float(bm.metric_speed(PAPER_STATE, params))
    tab = make_table(TABLES[TABLE])
    rng = np.random.default_rng(SEED)
    S, _, _, _ = bm.sample_invariant(CONFIGS["full"]["orbits"], tab, rng, params, rho, bm.WallChart(tab))
    S = S[:orbits]
    angles = [TURN * (k // 2 + 1) * (1 if k % 2 == 0 else -1) for k in range(copies)]
    states = [s for base in S for s in [base] + [turned(base, a, params) for a in angles]]
    orb = bm.iterate(np.array(states), np.ones(len(states)), impacts, table=tab, law="elastic", params=params,
                     rescale=True)
    rows = []
    for i in range(orbits):
        lam, se, lam3, n = exponents(orb, i * (copies + 1), tab, params)
        others = [exponents(orb, i * (copies + 1) + 1 + k, tab, params)[0] for k in range(copies)]
        rows.append({"orbit": i, "impacts": n, "lam": lam, "se": se, "chart": lam3 - lam,
                     "copies": [(x - lam) / se for x in others]})
    return rows


def report(rows, rep, seconds):
    z = [d for r in rows for d in r["copies"]]
    below = sum(d < 0 for d in z)
    quick = rep.quick
    lines = rep.header("Two correct computations of lambda1: how far apart") + [
        f"- run: {seconds:.0f} s wall" + (" (--quick: a smoke test, not the report's numbers)" if quick else ""), "",
        __doc__.split("\n\n", 1)[0].replace("\n", " "), "",
        f"Elastic {TABLE} orbits (the first {len(rows)} of the billiards report's invariant-measure orbits), "
        f"{rows[0]['impacts']} impacts each, copies started {TURN:g} rad away. SE: batch means of the per-impact "
        "log-stretch (20 batches), as the billiards report.", "",
        "| orbit | impacts | lambda1 per impact | SE | chart coordinates - report's (in SE) | copies - orbit (in SE) |",
        "| ---: | ---: | ---: | ---: | ---: | --- |"]
    for r in rows:
        lines.append(f"| {r['orbit']} | {r['impacts']} | {r['lam']:.4f} | {r['se']:.4f} | {r['chart'] / r['se']:+.3f} | "
                     + ", ".join(f"{d:+.2f}" for d in r["copies"]) + " |")
    sd = float(np.std(z, ddof=1)) if len(z) > 1 else float("nan")
    chart = max(abs(r["chart"] / r["se"]) for r in rows)
    lines += ["", f"The norm's share is at most {chart:.3f} SE on these orbits. Copies started {TURN:g} rad away end "
              f"{min(z):+.2f} to {max(z):+.2f} SE from their orbit's estimate (standard deviation {sd:.2f} SE over "
              f"{len(z)} copies, {below} of them below it, {len(z) - below} above). Two correct codes follow "
              "orbits that part after a few hundred impacts, so their estimates differ by such amounts, with either "
              f"sign: the referee's largest difference, {REFEREE_SE:g} SE, is {REFEREE_SE / sd:.1f} standard "
              f"deviations of these differences, and the same sign on all 4 orbits has probability 2 x (1/2)^4 = "
              f"{2 * 0.5 ** 4:.3f} for two unbiased codes (1/16 for the one sign named in advance). The SE of one "
              "finite-time estimate understates how far two of them can be apart: the billiards report calls its "
              "exponents finite-time estimates, not converged values, for this reason."]
    return lines


def main(argv=None):
    from lab.common import report_command

    def options(ap):
        ap.add_argument("--orbits", type=int, default=4)
        ap.add_argument("--copies", type=int, default=3)
        ap.add_argument("--impacts", type=int, default=CONFIGS["full"]["impacts"])
    rep = report_command("studies.lyapunov_spread", "lyapunov_spread.md", __doc__.split("\n\n")[0], argv,
                         options=options, quick="2 orbits, 1 copy, 300 impacts",
                         out_help="the report (docs/lyapunov_spread.md regenerates the committed one)")
    args = rep.args
    for name in ("orbits", "copies", "impacts"):
        if getattr(args, name) < 1:
            rep.error(f"--{name} must be >= 1, got {getattr(args, name)}")
    orbits, copies, impacts = (2, 1, 300) if args.quick else (args.orbits, args.copies, args.impacts)
    t0 = time.perf_counter()
    rows = study(orbits, copies, impacts)
    return rep.write(report(rows, rep, time.perf_counter() - t0)), rows


if __name__ == "__main__":
    main()
