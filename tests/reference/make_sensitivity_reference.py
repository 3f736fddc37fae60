#!/usr/bin/env python3
r"""
High-precision reference Jacobians of the bouncing penny's final state through impacts.

For each case (a state, a table, an impact law, optional piecewise-constant controls, a final
time) this script simulates the penny at 50 significant digits with the independent mpmath
simulator of make_reference.py (exact flows, impact times found by polynomial roots for
uncontrolled flight and by dense sampling + findroot with controls, the paper's impact laws),
and differentiates the final state by central differences at 50 digits:

    J[:, i] = (s(t_final; x + h e_i) - s(t_final; x - h e_i)) / (2 h),  h = 1e-16 * scale_i,

whose truncation error (~h^2) and round-off (~1e-50 / h) are both far below 1e-25 relative, so
the stored Jacobians are exact to the 20 digits written. The perturbed runs must have the same
impact sequence (same ends, same count) as the nominal one: this is asserted, so a case near a
grazing impact is refused rather than differentiated across it.

Like make_reference.py, nothing here imports penny_env: the float64 sensitivities
(penny_env/physics/sensitivity.py) are checked against an independent computation.

Usage:  python tests/reference/make_sensitivity_reference.py [--out FILE] [--only N]
Writes studies/reference_data/sensitivity_cases.json (a few minutes on one core).
"""

import argparse
import json
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import make_reference as ref  # noqa: E402
from make_reference import mp, mpf  # noqa: E402

mp.dps = 50
STEP = mpf("1e-16")
NDIG = 22


# (name, table spec, law, e, state, controls or None, control_dt, t_final)
# t_final None: len(controls) * control_dt (simulate()'s default horizon).
# All inputs are binary64-exact (they are written as float64 decimal strings and read back as is).
def case_defs():
    f = float
    ell, circ, stad = ("ellipse", 0.15, 0.2), ("ellipse", 0.2, 0.2), ("stadium", 0.1, 0.2)
    return [
        ("ellipse-elastic", ell, "elastic", 1.0, (f(0.01), f(-0.02), f(0.3), f(1.1), f(40.0), f(0.5)), None, None, f(0.6)),
        ("ellipse-plastic", ell, "plastic", 0.0, (f(-0.03), f(0.04), f(0.0), f(2.5), f(35.0), f(-1.5)), None, None, f(0.5)),
        ("circle-restitution", circ, "restitution", 0.6, (f(0.05), f(0.0), f(1.0), f(-0.7), f(-45.0), f(2.0)),
         None, None, f(0.7)),
        ("stadium-elastic", stad, "elastic", 1.0, (f(0.01), f(-0.02), f(0.3), f(1.1), f(40.0), f(0.5)), None, None, f(0.4)),
        ("stadium-plastic-back", stad, "plastic", 0.0, (f(0.1), f(0.03), f(0.0), f(0.4), f(-38.0), f(1.0)), None, None, f(0.8)),
        ("ellipse-controlled-elastic", ell, "elastic", 1.0, (f(0.0), f(0.05), f(0.0), f(0.9), f(30.0), f(0.0)),
         ((f(4e-8), f(1.5e-6)), (f(-6e-8), f(-1e-6)), (f(2e-8), f(5e-7))), f(0.2), None),
        ("circle-controlled-plastic", circ, "plastic", 0.0, (f(-0.02), f(0.0), f(0.0), f(-0.3), f(45.0), f(0.8)),
         ((f(-3e-8), f(2e-6)), (f(5e-8), f(-1.5e-6))), f(0.35), None),
        ("stadium-controlled-restitution", stad, "restitution", 0.8, (f(-0.05), f(-0.02), f(0.0), f(3.3), f(-50.0), f(-0.4)),
         ((f(2e-8), f(-1e-6)), (f(0.0), f(2e-6)), (f(-4e-8), f(0.0))), f(0.25), None),
    ]


def make_table(spec):
    kind, p, q = spec
    return ref.Ellipse(mpf(p), mpf(q)) if kind == "ellipse" else ref.Stadium(mpf(p), mpf(q))


def run(state, table, P, law, e, controls, cdt, t_final):
    """(final state, impact ends) at 50 digits."""
    if controls is None:
        res = ref.run_uncontrolled(state, table, P, law, e, 0, mpf(t_final), method="poly")
        # run_uncontrolled keeps only the first n_imp impacts: recount the ends up to t_final
        ends = _uncontrolled_ends(state, table, P, law, e, mpf(t_final))
        return res["state_final"], ends
    ctl = [(mpf(u1), mpf(u2)) for u1, u2 in controls]
    res = ref.run_controlled(state, table, P, law, e, ctl, mpf(cdt), mpf(cdt) * len(ctl), step_scale=4)
    return res["state_final"], list(res["ends"])


def _uncontrolled_ends(state, table, P, law, e, t_final):
    t, st, ends = mpf(0), tuple(mpf(v) for v in state), []
    while True:
        nx = ref.next_impact_poly(st, table, P)
        if nx is None or t + nx[0] > t_final:
            return ends
        s, sg = nx
        st = ref.apply_law(law, e, ref.Flow(st, 0, 0, P).state(s), sg, table, P, {})
        t += s
        ends.append(sg)


def jacobians(case):
    name, tspec, law, e, state, controls, cdt, t_final = case
    P = ref.default_params(exact=False)  # the binary64 values of the package's defaults
    table = make_table(tspec)
    x0 = [mpf(v) for v in state]
    final, ends = run(x0, table, P, law, e, controls, cdt, t_final)
    scales = [mpf("0.1"), mpf("0.1"), mpf(1), mpf(1), mpf(10), mpf(1)]
    J = [[None] * 6 for _ in range(6)]
    for i in range(6):
        h = STEP * scales[i]
        cols = []
        for sgn in (1, -1):
            x = list(x0)
            x[i] += sgn * h
            fin, en = run(x, table, P, law, e, controls, cdt, t_final)
            assert en == ends, (name, "state", i, en, ends)
            cols.append(fin)
        for r in range(6):
            J[r][i] = (cols[0][r] - cols[1][r]) / (2 * h)
    CJ = None
    if controls is not None:
        CJ = [[None] * (2 * len(controls)) for _ in range(6)]
        for k in range(len(controls)):
            for c in range(2):
                h = STEP * (mpf("1e-7") if c == 0 else mpf("1e-6"))
                cols = []
                for sgn in (1, -1):
                    u = [list(map(mpf, row)) for row in controls]
                    u[k][c] += sgn * h
                    fin, en = run(x0, table, P, law, e, u, cdt, t_final)
                    assert en == ends, (name, "control", k, c, en, ends)
                    cols.append(fin)
                for r in range(6):
                    CJ[r][2 * k + c] = (cols[0][r] - cols[1][r]) / (2 * h)
    out = {
        "name": name, "table": {"kind": tspec[0], "a" if tspec[0] == "ellipse" else "radius": repr(tspec[1]),
                                "b" if tspec[0] == "ellipse" else "length": repr(tspec[2])},
        "law": law, "e": repr(e), "state": [repr(v) for v in state],
        "controls": None if controls is None else [[repr(a), repr(b)] for a, b in controls],
        "control_dt": None if cdt is None else repr(cdt), "t_final": None if t_final is None else repr(t_final),
        "impact_ends": [int(s) for s in ends],
        "final_state": [mp.nstr(v, NDIG) for v in final],
        "jacobian": [[mp.nstr(v, NDIG) for v in row] for row in J],
        "control_jacobian": None if CJ is None else [[mp.nstr(v, NDIG) for v in row] for row in CJ],
    }
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    ap.add_argument("--out", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), os.pardir, os.pardir,
                                                  "studies", "reference_data", "sensitivity_cases.json"))
    ap.add_argument("--only", type=int, default=None, help="compute only case N (for timing)")
    args = ap.parse_args()
    defs = case_defs()
    if args.only is not None:
        defs = [defs[args.only]]
    cases = []
    start = time.time()
    for case in defs:
        t0 = time.time()
        cases.append(jacobians(case))
        print(f"{case[0]}: {len(cases[-1]['impact_ends'])} impacts, {time.time() - t0:.1f} s", flush=True)
    meta = {"digits": mp.dps, "fd_step": str(STEP), "params": "PennyParams() defaults (binary64)",
            "seconds": round(time.time() - start, 1),
            "script": "tests/reference/make_sensitivity_reference.py"}
    with open(args.out, "w") as fh:
        json.dump({"meta": meta, "cases": cases}, fh, indent=1)
    print("wrote", args.out)


if __name__ == "__main__":
    main()
