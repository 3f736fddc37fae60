"""The penny as a nonholonomic billiard: boundary maps, Lyapunov spectra, volume, ergodicity.

    python -m studies.billiards [--quick] [--out docs/billiards.md]

For the circle, the paper's ellipse, a stadium and a rounded rectangle, and the elastic, restitution
(e = 0.9, 0.5) and the paper's plastic law, uncontrolled:

1. boundary-map portraits (s, beta, psi) of many orbits (penny_env.analysis.boundary_map), and what is
   conserved (energy for elastic walls; on the circle |beta| for every law and the normal speed for
   elastic walls);
2. Lyapunov spectra of the return map (3-D, per impact) and of the flow (5-D, per second; elastic) from
   the exact tangent maps with QR re-orthonormalisation, their convergence, cross-checks (sum of the
   exponents = mean log-determinant; the largest flow exponent against the return map's over the mean
   flight time and against the two-trajectory estimate of penny_env.analysis.dynamics);
3. the volume question: log-determinants per impact in stated coordinates against the laws' formulas,
   and the elastic map's invariant measure |v_n| ds dbeta dpsi (pointwise along orbits, and one map
   step of a large sample);
4. ergodicity indicators for elastic walls: coverage of the accessible region and decay of correlations;
5. the paper's Figure 5 experiment (100 copies perturbed by < 0.005) on every table and law.

--quick runs a few short orbits (for the tests) and writes into a temporary directory unless --out
is given.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from penny_env import batch
from penny_env.physics import PennyParams, make_law, make_table
from penny_env.analysis import boundary_map as bm
from lab.stats import clopper_pearson

TABLES = {"circle": {"kind": "circle", "radius": 0.2},
          "ellipse": {"kind": "ellipse", "a": 0.15, "b": 0.2},
          "stadium": {"kind": "stadium", "radius": 0.1, "length": 0.15},
          "rounded rectangle": {"kind": "rounded_rectangle", "width": 0.3, "height": 0.2, "radius": 0.04}}
LAWS = {"elastic": "elastic", "e = 0.9": 0.9, "e = 0.5": 0.5, "plastic": "plastic"}
# elastic orbits from the invariant measure restricted to rolling-dominated states (|sin psi| <= ROLLING_SPIN:
# the contact point's arcs have radii R sqrt(J / (I + m R^2)) |cot psi| >= 0.1 m, table-sized), like the paper's
ROLLING = "elastic, rolling starts"
ROLLING_SPIN = 0.04
RUNS = [*LAWS, ROLLING]


def law_of(name):
    """The impact law of a run name (LAWS, or ROLLING: elastic)."""
    return LAWS.get(name, "elastic")
PAPER_STATE = np.array([0.0, 0.0, 0.0, np.pi / 2, 10.0, 0.2])
CONFIGS = {
    "quick": dict(orbits=3, impacts=24, tangent=2, push=1500, fig5_n=10, fig5_t=1.0, fig5_steps=3, two_traj_t=5.0,
                  bins=8),
    "full": dict(orbits=32, impacts=1200, tangent=8, push=20000, fig5_n=100, fig5_t=20.0, fig5_steps=40,
                 two_traj_t=100.0, bins=16),
}


def plastic_coefficient(beta, params) -> np.ndarray:
    """The paper's plastic law as a restitution: e_p(beta) = 2 (cos^2 b / (I + m R^2) + sin^2 b / J) /
    (1 / (m R^2) + sin^2 b / J) - 1 (physics/laws.py with a unit wall gradient); for the thin penny
    (I = m R^2 / 2, J = m R^2 / 4) it is (cos^2 b / 3 + 3 sin^2 b) / (1 + 4 sin^2 b)."""
    c2, s2 = np.cos(beta) ** 2, np.sin(beta) ** 2
    mr2 = params.m * params.R ** 2
    return 2 * (c2 / params.rolling_inertia + s2 / params.J) / (1 / mr2 + s2 / params.J) - 1


@dataclass
class Case:
    """One table and law: orbits and their boundary coordinates; per tangent orbit the running section
    exponents (K, 3) [per impact], flow exponents (K, 5) [1/s] (elastic), log|det| of the flow's tangent map
    per impact, the pointwise invariant-measure residual, the law's coefficient and the speed ratio."""

    table_name: str
    law_name: str
    orbits: bm.Orbits
    coords: tuple
    section_runs: list = field(default_factory=list)
    flow_runs: list = field(default_factory=list)
    flow_logdet: list = field(default_factory=list)
    section_logdet: list = field(default_factory=list)
    measure_residual: list = field(default_factory=list)
    sum_residual: list = field(default_factory=list)
    flights: list = field(default_factory=list)
    seconds: float = 0.0


def run_case(tname, lname, cfg, params, rho, seed) -> Case:
    t0 = time.perf_counter()
    tab = make_table(TABLES[tname])
    law = make_law(law_of(lname))
    chart = bm.WallChart(tab)
    rng = np.random.default_rng(seed)
    S, _, _, _ = bm.sample_invariant(cfg["orbits"], tab, rng, params, rho, chart,
                                     max_spin=ROLLING_SPIN if lname == ROLLING else None)
    orb = bm.iterate(S, np.ones(len(S)), cfg["impacts"], table=tab, law=law, params=params,
                     rescale=law.kind != "elastic")
    case = Case(tname, lname, orb, bm.coordinates(orb, chart))
    dens = case.coords[3]
    for i in range(cfg["tangent"]):
        tm = bm.tangent_maps(orb, i)
        K = len(tm.flow)
        if K < 2:
            continue
        T0 = bm.section_chart(orb.post[0, i], orb.ends[0, i], tab, params)
        case.section_runs.append(bm.qr_exponents(tm.section, T0))
        if law.kind == "elastic":
            case.flow_runs.append(bm.qr_exponents(tm.flow, np.eye(5), tm.flight))
        case.flights.append(tm.flight)
        e, k = orb.restitution[:K, i], orb.speed_ratio[:K, i]
        case.flow_logdet.append(np.log(np.abs(np.linalg.det(tm.flow))) - 2 * np.log(e))
        ld3 = np.log(np.abs(np.linalg.det(tm.section3)))
        case.section_logdet.append(ld3)
        # QR volume growth = sum of ln|det| in the chart + the chart's volume at the ends (exact identity)
        TK = bm.section_chart(orb.post[K, i], orb.ends[K, i], tab, params)
        chart_vol = 0.5 * (np.linalg.slogdet(TK.T @ TK)[1] - np.linalg.slogdet(T0.T @ T0)[1])
        case.sum_residual.append(K * case.section_runs[-1][-1].sum() - ld3.sum() - chart_vol)
        case.measure_residual.append(ld3 + np.log(np.abs(dens[1:K + 1, i])) - np.log(np.abs(dens[:K, i]))
                                     - (2 * np.log(e) - 3 * np.log(k)))
    case.seconds = time.perf_counter() - t0
    return case


def _finite_mean(a):
    a = np.asarray(a, dtype=float)
    a = a[np.isfinite(a)]
    return float(a.mean()) if a.size else np.nan


def pushforward_distance(tname, n, bins, params, rho, seed):
    """Total-variation distances on a bins^3 grid of (s, beta, psi): (n states drawn from the candidate invariant
    measure pushed one elastic impact on vs n fresh ones, two fresh samples (the sampling noise), the pushed
    sample vs n states uniform in (s, beta, psi) on the accessible region (the check's resolution))."""
    tab = make_table(TABLES[tname])
    chart = bm.WallChart(tab)
    rng = np.random.default_rng(seed)

    def hist(s, b, p):
        h, _ = np.histogramdd(np.stack([s, b, p], 1), bins=bins, range=[(0, 1), (-np.pi / 2, np.pi / 2), (-np.pi, np.pi)])
        return h / h.sum()

    def push(S):
        orb = bm.iterate(S, np.ones(len(S)), 1, table=tab, law="elastic", params=params, rescale=False)
        s, b, p, _ = bm.coordinates(orb, chart)
        m = orb.alive[1]
        return s[1, m], b[1, m], p[1, m]

    S, s, b, p = bm.sample_invariant(n, tab, rng, params, rho, chart)
    _, s2, b2, p2 = bm.sample_invariant(n, tab, rng, params, rho, chart)
    tv = lambda h1, h2: 0.5 * float(np.abs(h1 - h2).sum())  # noqa: E731
    h_pushed = hist(*push(S))
    pushed = tv(h_pushed, hist(s2, b2, p2))
    noise = tv(hist(s, b, p), hist(s2, b2, p2))
    # the resolution of the check: the same histograms tell the invariant density from the uniform one on the
    # accessible region (so a map that moved the density by that much would show)
    su, bu, pu = rng.uniform(0, 1, 4 * n), rng.uniform(-np.pi / 2, np.pi / 2, 4 * n), rng.uniform(-np.pi, np.pi, 4 * n)
    keep = bm.normal_speed_density(bu, pu, params) < 0
    Su = bm.section_states(su[keep], bu[keep], pu[keep], rho, tab, params, chart)
    inside = np.asarray(tab.h(Su[:, 0] - params.R * np.cos(Su[:, 3]), Su[:, 1] - params.R * np.sin(Su[:, 3]))) < 0
    uniform = tv(h_pushed, hist(su[keep][inside][:n], bu[keep][inside][:n], pu[keep][inside][:n]))
    return pushed, noise, uniform


def coverage_curve(case, bins, checkpoints, reference):
    """Median over orbits of the fraction of the accessible cells (cells the reference sample of the invariant
    measure visits) that an orbit's first n impacts visit, at n in checkpoints; and the same expected for n
    independent draws from the invariant measure."""
    s, b, p, _ = case.coords

    def cell(s, b, p):
        i = np.clip((s * bins).astype(int), 0, bins - 1)
        j = np.clip(((b + np.pi / 2) / np.pi * bins).astype(int), 0, bins - 1)
        k = np.clip(((p + np.pi) / (2 * np.pi) * bins).astype(int), 0, bins - 1)
        return (i * bins + j) * bins + k

    ref = np.bincount(cell(*reference), minlength=bins ** 3)
    acc = ref > 0
    prob = ref[acc] / ref.sum()
    fr = []
    for i in range(s.shape[1]):
        m = np.isfinite(s[:, i])
        c = cell(s[m, i], b[m, i], p[m, i])
        row = []
        for n in checkpoints:
            seen = np.zeros(bins ** 3, bool)
            seen[c[:n]] = True
            row.append((seen & acc).sum() / acc.sum() if n <= c.size else np.nan)
        fr.append(row)
    iid = [float(np.mean(1 - (1 - prob) ** n)) for n in checkpoints]
    return np.nanmedian(np.array(fr), axis=0), np.array(iid)


def autocorrelation(x, lags):
    """Normalised autocorrelation of an observable along orbits (K, N), pooled over the orbits."""
    x = x - np.nanmean(x)
    var = np.nanmean(x * x)
    return np.array([np.nanmean(x[lag:] * x[:x.shape[0] - lag]) / var for lag in lags])


def figure5_spread(tname, lname, cfg, params, seed=0):
    """The paper's Figure 5 experiment on one table and law: cfg['fig5_n'] copies of the paper's state whose
    theta_dot and phi_dot are perturbed by less than 0.005, simulated together. Returns (times, spread: the
    largest distance of the copies' contact points from their mean, linear: the same spread predicted by the
    exact Jacobian d(x, y) / d(theta_dot, phi_dot) of the unperturbed penny (simulate(..., sensitivities=True);
    NaN where it has none), growth: ln of the largest singular value of the reduced Jacobian d(x, y, phi,
    theta_dot, phi_dot)(t) / d(same)(0) in dynamics.state_distance's units (positions over the table's size,
    speeds over the paper's speed), whose slope is the finite-time largest exponent along the paper's orbit)."""
    import penny_env as pe

    rng = np.random.default_rng(seed)
    n = cfg["fig5_n"]
    delta = np.zeros((n, 6))
    delta[:, 4] = rng.uniform(-0.005, 0.005, n)
    delta[:, 5] = rng.uniform(-0.005, 0.005, n)
    S = PAPER_STATE[None, :] + delta
    times = np.linspace(0, cfg["fig5_t"], cfg["fig5_steps"] + 1)
    spread, linear, growth = [0.0], [0.0], [0.0]
    tab = make_table(TABLES[tname])
    # dynamics.state_distance's units: positions over the table's size, speeds over the paper's speed
    speed = float(np.hypot(PAPER_STATE[4], PAPER_STATE[5]))
    scale = np.array([1 / tab.size, 1 / tab.size, 1.0, 1 / speed, 1 / speed])

    def widest(xy):
        return float(np.hypot(*(xy - xy.mean(axis=0)).T).max())
    for t0, t1 in zip(times[:-1], times[1:]):
        S = batch.simulate(S, params=params, table=tab, law=LAWS[lname], t_final=float(t1 - t0)).final_states
        spread.append(widest(S[:, :2]))
        tr = pe.simulate(PAPER_STATE, params=params, table=tab, law=LAWS[lname], t_final=float(t1), sensitivities=True)
        Jac = tr.jacobian
        linear.append(widest(delta @ Jac[:2].T) if tr.jacobian_valid else np.nan)
        red = scale[:, None] * Jac[np.ix_(bm.REDUCED, bm.REDUCED)] / scale[None, :]
        growth.append(float(np.log(np.linalg.norm(red, 2))) if tr.jacobian_valid else np.nan)
    return times, np.array(spread), np.array(linear), np.array(growth)


CHAOS_FACTOR = 5.0  # an orbit looks chaotic where its lambda1 exceeds this many times the circle's largest


def summary_rows(cases, erg_rows, fmt):
    """Per table, elastic walls: the largest return-map exponent over the orbits, how many orbits exceed
    CHAOS_FACTOR times the circle's largest finite-time exponent (the integrable control at the same number of
    impacts), with a 95 % Clopper-Pearson interval for the invariant measure's share of such orbits."""
    rows, counts = [], {}
    for run, label in (("elastic", "invariant measure"), (ROLLING, f"rolling-dominated (|sin psi| <= {ROLLING_SPIN:g})")):
        l1 = {t: _sorted_final(cases[(t, run)].section_runs)[:, 0] for t in TABLES}
        null = float(np.max(l1["circle"])) if l1["circle"].size else np.nan
        for (tname, lam), erg in zip(l1.items(), erg_rows):
            k = int(np.sum(lam > CHAOS_FACTOR * null))
            lo, hi = clopper_pearson(k, lam.size)
            counts[(tname, run)] = (k, int(lam.size), lo, hi)
            rows.append([tname, label, fmt(null, 3), fmt(_med(lam), 3), f"{fmt(lam.min(), 3)} .. {fmt(lam.max(), 3)}",
                         f"{k} / {lam.size}", f"{lo:.2f} .. {hi:.2f}",
                         *((erg[1], erg[2], erg[4]) if run == "elastic" else ("-", "-", "-"))])
    return rows, answers(counts)


SPECULAR = {"circle": "integrable", "ellipse": "integrable (Joachimsthal's integral)",
            "stadium": "ergodic and mixing (Bunimovich)", "rounded rectangle": "of Bunimovich's type"}


def answers(counts) -> list[str]:
    """One sentence per table from the chaotic-looking counts (summary_rows), next to the specular billiard."""
    out = []
    for tname in TABLES:
        k, n, lo, hi = counts[(tname, "elastic")]
        kr, nr, lor, hir = counts[(tname, ROLLING)]
        text = (f"* {tname} (specular: {SPECULAR[tname]}): {k} of {n} invariant-measure orbits and {kr} of {nr} "
                "rolling-dominated ones look chaotic")
        if tname == "circle":
            text += "; its elastic map is integrable and |beta| is kept by every law (section 1): the null level."
        elif k + kr == 0:
            text += f"; no evidence of chaos at this length (the chaotic-looking share is below {hi:.2f} of the measure)."
        else:
            text += (f": evidence (finite-time exponents, not a proof) of chaos; the chaotic-looking share of the "
                     f"invariant measure is {lo:.2f} to {hi:.2f}, of its rolling part {lor:.2f} to {hir:.2f}")
            text += (", so regular-looking orbits keep a share of at least "
                     f"{1 - hi:.2f} of the measure." if hi < 1 else ".")
        out.append(text)
    return out


def _sorted_final(runs):
    """(orbits, m) final exponents of running-exponent arrays, each row sorted largest first."""
    return np.array([np.sort(r[-1])[::-1] for r in runs]) if runs else np.zeros((0, 0))


def _med(a):
    a = np.asarray(a, dtype=float)
    return float(np.nanmedian(a)) if a.size and np.isfinite(a).any() else np.nan


def conserved_rows(cases, params, fmt):
    """Rows of the conservation table (a row per table and law)."""
    rows = []
    for (tname, lname), c in cases.items():
        orb = c.orbits
        s, b, p, dn = c.coords
        alive = orb.alive
        E = bm.metric_speed(orb.post, params) ** 2
        drift = np.abs(E / E[:1] - 1)[alive]
        ab = np.where(alive, np.abs(b), np.nan)
        spread_beta = np.nanmax(np.nanmax(ab, 0) - np.nanmin(ab, 0))
        nu = np.where(alive, np.abs(dn), np.nan)
        spread_nu = np.nanmax((np.nanmax(nu, 0) - np.nanmin(nu, 0)) / np.nanmax(nu, 0))
        elastic = law_of(lname) == "elastic"
        two = np.nanmax(np.abs(np.angle(np.exp(1j * (p[2:] - p[:-2]))))) if elastic else np.nan
        rows.append([tname, lname, fmt(drift.max()) if elastic else "-", fmt(spread_beta),
                     fmt(spread_nu) if elastic else "-", fmt(two)])
    return rows


def volume_rows(cases, params, fmt):
    rows = []
    for (tname, lname), c in cases.items():
        orb = c.orbits
        K = [len(x) for x in c.flow_logdet]
        if not K:
            continue
        e = np.concatenate([orb.restitution[:k, i] for i, k in enumerate(K)])
        beta = np.concatenate([c.coords[1][1:k + 1, i] for i, k in enumerate(K)])
        ratio = np.concatenate([orb.speed_ratio[:k, i] for i, k in enumerate(K)])
        law = law_of(lname)
        expect = (plastic_coefficient(beta, params) if law == "plastic" else
                  np.ones_like(e) if law == "elastic" else np.full_like(e, law))
        dev = np.concatenate(c.flow_logdet)
        ld = dev + 2 * np.log(e)
        ld3 = np.concatenate(c.section_logdet)
        rows.append([tname, lname, sum(K), fmt(ld.mean(), 4), fmt(2 * np.log(expect).mean(), 4), fmt(np.abs(dev).max()),
                     fmt(np.abs(e - expect).max()), fmt(ld3.mean(), 4), fmt(np.mean(2 * np.log(e) - 3 * np.log(ratio)), 4),
                     fmt(np.abs(np.concatenate(c.measure_residual)).max())])
    return rows


def spectra_rows(cases, two_traj, fmt):
    rows, flow_rows = [], []
    for (tname, lname), c in cases.items():
        sec = _sorted_final(c.section_runs)
        if sec.size == 0:
            continue
        K = [len(r) for r in c.section_runs]
        ld3 = [x.mean() for x in c.section_logdet]
        rows.append([tname, lname, len(K), int(np.median(K)), *(fmt(_med(sec[:, j]), 3) for j in range(3)),
                     f"{fmt(sec[:, 0].min(), 3)} .. {fmt(sec[:, 0].max(), 3)}", fmt(_med(sec.sum(1)), 3),
                     fmt(_med(ld3), 3), fmt(np.max(np.abs(c.sum_residual)))])
        if c.flow_runs:
            fl = _sorted_final(c.flow_runs)
            abramov = [np.max(r[-1]) / np.mean(t) for r, t in zip(c.section_runs, c.flights)]
            ratio = [np.max(r[-1]) / a for r, a in zip(c.flow_runs, abramov)]
            flow_rows.append([tname, lname, len(fl), *(fmt(_med(fl[:, j]), 3) for j in range(5)), fmt(_med(fl.sum(1))),
                              fmt(_med(abramov), 3), f"{fmt(min(ratio), 3)} .. {fmt(max(ratio), 3)}",
                              fmt(_med(two_traj.get((tname, lname), [np.nan])), 3),
                              fmt(_med(np.concatenate(c.flights)), 3)])
    return rows, flow_rows


def _answer_block(out) -> list[str]:
    """The question-2 answer between its markers: billiards_answer's block from its stored summary
    (billiards_answer.json beside the report) where there is one, else the block the report already has (its
    command writes it), else the markers with a pointer."""
    import json

    from studies.billiards_answer import README_BEGIN, README_END, answer_block

    stored = out.with_name("billiards_answer.json")
    if stored.is_file():
        return [README_BEGIN, answer_block(json.loads(stored.read_text()), base=""), README_END]
    old = out.read_text() if out.is_file() else ""
    if README_BEGIN in old and README_END in old:
        return [README_BEGIN + old.split(README_BEGIN, 1)[1].split(README_END, 1)[0].rstrip("\n"), README_END]
    return [README_BEGIN, "(not computed yet: run python -m studies.billiards_answer)", README_END]


def main(argv=None):
    from lab.common import fmt, header, report_command, table

    rep = report_command("studies.billiards", "billiards.md", __doc__, argv, quick="few short orbits (for tests)")
    args, argv = rep.args, rep.argv
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from penny_env.analysis.dynamics import lyapunov_exponents

    cfg = CONFIGS["quick" if args.quick else "full"]
    out = rep.out
    params = PennyParams()
    rho = float(bm.metric_speed(PAPER_STATE, params))  # every orbit at the paper's energy
    t_start = time.perf_counter()
    cases = {}
    for ti, tname in enumerate(TABLES):
        for lname in RUNS:
            c = run_case(tname, lname, cfg, params, rho, seed=ti)  # the same starts for every law on a table
            cases[(tname, lname)] = c
            print(f"{tname}, {lname}: {c.seconds:.1f} s", flush=True)
    two_traj = {}
    for tname, run in ((t, r) for t in TABLES for r in ("elastic", ROLLING)):
        S0 = cases[(tname, run)].orbits.post[0, :cfg["tangent"]]
        two_traj[(tname, run)] = lyapunov_exponents(S0, cfg["two_traj_t"], table=TABLES[tname], law="elastic",
                                             n_checkpoints=200 if not args.quick else 20, params=params).exponents
    push = {tname: pushforward_distance(tname, cfg["push"], cfg["bins"] // 2 if args.quick else 8, params, rho, seed=7)
            for tname in TABLES}
    fig5 = {(t, law): figure5_spread(t, law, cfg, params) for t in TABLES for law in LAWS}
    compute_s = time.perf_counter() - t_start

    # -- figures --------------------------------------------------------------------------------------
    names = list(TABLES)
    laws = list(LAWS)
    colors = dict(zip(RUNS, ("tab:blue", "tab:green", "tab:orange", "tab:red", "tab:purple")))
    pngs = {}

    def save(fig, key, dpi=100):  # the dense figures at a lower resolution (about 0.3 MB each)
        pngs[key] = rep.figure(fig, f"_{key}.png", dpi=dpi).name

    for key, coord, label, ylim in (("beta", 1, "beta [rad]", (-np.pi / 2, np.pi / 2)),
                                    ("psi", 2, "psi [rad]", (-np.pi, np.pi))):
        fig, axes = plt.subplots(4, 5, figsize=(16, 11.5), sharex=True, sharey=True)
        for r, tname in enumerate(names):
            for q, lname in enumerate(RUNS):
                ax = axes[r, q]
                co = cases[(tname, lname)].coords
                other = co[2] if coord == 1 else co[1]
                ax.scatter(co[0].ravel(), co[coord].ravel(), c=other.ravel(), s=0.3,
                           cmap="twilight" if coord == 1 else "coolwarm",
                           vmin=-np.pi if coord == 1 else -np.pi / 2, vmax=np.pi if coord == 1 else np.pi / 2, rasterized=True)
                ax.set_ylim(*ylim)
                ax.set_title(f"{tname}, {lname}", fontsize=8)
                if r == 3:
                    ax.set_xlabel("s (arc length / perimeter)")
                if q == 0:
                    ax.set_ylabel(label)
        save(fig, f"portrait_{key}", dpi=60)

    fig, axes = plt.subplots(1, 3, figsize=(15, 4))
    for tname in names:
        c = cases[(tname, "elastic")]
        E = bm.metric_speed(c.orbits.post, params) ** 2
        d = np.where(c.orbits.alive, np.abs(E / E[:1] - 1), np.nan)
        axes[0].semilogy(np.arange(d.shape[0]), np.maximum(np.nanmax(d, 1), 1e-18), label=tname)
    axes[0].set(xlabel="impact", ylabel="max over orbits |E / E0 - 1|", title="elastic walls: energy")
    axes[0].legend(fontsize=8)
    for lname in laws:
        b = cases[("circle", lname)].coords[1]
        for j in range(min(4, b.shape[1])):
            axes[1].plot(np.abs(b[:, j]), color=colors[lname], lw=0.8, label=f"circle, {lname}" if j == 0 else None)
    axes[1].plot(np.abs(cases[("ellipse", "elastic")].coords[1][:, 0]), color="0.5", lw=0.6, ls=":",
                 label="ellipse, elastic (not conserved)")
    axes[1].set(xlabel="impact", ylabel="|beta| [rad]", title="circle: |beta| conserved by every law")
    axes[1].legend(fontsize=7)
    for tname, st in (("circle", "-"), ("ellipse", ":")):
        dn = cases[(tname, "elastic")].coords[3]
        axes[2].plot(np.abs(dn[:, :4]), ls=st, lw=0.8, color="tab:blue" if tname == "circle" else "0.5")
    axes[2].set(xlabel="impact", ylabel="|nu| = |v_n| / (R rho) [1 / sqrt(kg m^2)]",
                title="elastic: normal speed, circle (solid) vs ellipse (dotted)")
    save(fig, "conserved")

    fig, axes = plt.subplots(2, 2, figsize=(12, 8), sharex=False)
    for ax, tname in zip(axes.flat, names):
        for lname in RUNS:
            for k, run in enumerate(cases[(tname, lname)].section_runs):
                ax.semilogx(np.arange(1, len(run) + 1), run.max(1), color=colors[lname], lw=0.7,
                            label=lname if k == 0 else None)
        finals = [run[-1].max() for lname in RUNS for run in cases[(tname, lname)].section_runs]
        ax.set_ylim(-0.02, 3 * max(finals + [0.05]))  # the first impacts' transient runs far off the scale
        ax.axhline(0, color="0.6", lw=0.5)
        ax.set(xlabel="impacts", ylabel="running largest exponent [1/impact]", title=tname)
        ax.legend(fontsize=7)
    save(fig, "convergence_map", dpi=70)

    fig, axes = plt.subplots(2, 2, figsize=(12, 8))
    for ax, tname in zip(axes.flat, names):
        for start, style in (("elastic", "-"), (ROLLING, ":")):
            for run, fl in zip(cases[(tname, start)].flow_runs, cases[(tname, start)].flights):
                t = np.cumsum(fl)
                for j in range(5):
                    ax.semilogx(t, run[:, j], lw=0.6, ls=style, color=plt.get_cmap("viridis")(j / 4))
        finals = [np.abs(run[-1]).max() for start in ("elastic", ROLLING) for run in cases[(tname, start)].flow_runs]
        top = 3 * max(finals + [0.05])
        ax.set_ylim(-top, top)
        ax.axhline(0, color="0.6", lw=0.5)
        ax.set(xlabel="time [s]", ylabel="running flow exponents [1/s]",
               title=f"{tname}, elastic: all 5, every orbit (dotted: rolling starts)")
    save(fig, "convergence_flow", dpi=70)

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for lname in laws:
        for tname, mk in zip(names, "o^sd"):
            c = cases[(tname, lname)]
            for i, ld in enumerate(c.flow_logdet):
                K = len(ld)
                ax.plot(np.abs(c.coords[1][1:K + 1, i]), ld + 2 * np.log(c.orbits.restitution[:K, i]), mk, ms=2,
                        color=colors[lname], alpha=0.4, label=f"{lname}" if (tname == "circle" and i == 0) else None)
    bb = np.linspace(0, np.pi / 2, 200)
    ax.plot(bb, 2 * np.log(plastic_coefficient(bb, params)), "k-", lw=1, label="2 ln e_p(beta), plastic formula")
    for e in (0.9, 0.5):
        ax.axhline(2 * np.log(e), color="k", ls=":", lw=0.8)
    ax.set(xlabel="|beta| at the impact [rad]", ylabel="ln |det| of the flow's tangent map per impact",
           title="volume change per impact (dotted: 2 ln 0.9, 2 ln 0.5)")
    ax.legend(fontsize=7)
    save(fig, "logdet")

    checkpoints = np.unique(np.logspace(0, np.log10(cfg["impacts"]), 20).astype(int))
    lags = np.arange(0, min(40, cfg["impacts"] // 2))
    fig, axes = plt.subplots(1, 3, figsize=(15, 4))
    erg_rows = []
    rolling_share = []
    for tname, col in zip(names, ("tab:blue", "tab:orange", "tab:green", "tab:red")):
        c = cases[(tname, "elastic")]
        tab = make_table(TABLES[tname])
        _, rs, rb, rp = bm.sample_invariant(20 * cfg["push"], tab, np.random.default_rng(11), params, rho)
        cov, iid = coverage_curve(c, cfg["bins"], checkpoints, (rs, rb, rp))
        rolling_share.append(float(np.mean(np.abs(np.sin(rp)) <= ROLLING_SPIN)))
        axes[0].semilogx(checkpoints, cov, color=col, label=tname)
        axes[0].semilogx(checkpoints, iid, color=col, ls=":", lw=0.8)
        s, b, p, dn = c.coords
        cb = autocorrelation(np.cos(b), lags)
        cn = autocorrelation(np.abs(dn), lags)
        axes[1].semilogy(lags, np.maximum(np.abs(cb), 1e-4), color=col, label=tname)
        axes[2].semilogy(lags, np.maximum(np.abs(cn), 1e-4), color=col, label=tname)
        erg_rows.append([tname, fmt(cov[-1], 3), fmt(iid[-1], 3), checkpoints[-1], fmt(cb[min(10, len(lags) - 1)], 2),
                         fmt(cn[min(10, len(lags) - 1)], 2)])
    axes[0].set(xlabel="impacts n", ylabel="fraction of accessible cells visited (median orbit)",
                title="coverage (dotted: n independent draws from the invariant measure)")
    axes[1].set(xlabel="lag [impacts]", ylabel="|C(lag)|", title="correlation of cos(beta), elastic")
    axes[2].set(xlabel="lag [impacts]", ylabel="|C(lag)|", title="correlation of |v_n| / rho, elastic")
    for ax in axes:
        ax.legend(fontsize=8)
    save(fig, "ergodicity")

    fig, axes = plt.subplots(1, 4, figsize=(16, 4), sharey=True)
    for ax, tname in zip(axes, names):
        for lname in laws:
            t, sp, lin, _ = fig5[(tname, lname)]
            ax.semilogy(t[1:], np.maximum(sp[1:], 1e-12), color=colors[lname], label=lname)
            ax.semilogy(t[1:], lin[1:], color=colors[lname], ls="--", lw=0.8)
        ax.set(xlabel="time [s]", title=f"{tname} (dashed: linear prediction)")
        ax.legend(fontsize=7)
    axes[0].set_ylabel("spread of the contact points [m]")
    save(fig, "figure5")

    # -- report ---------------------------------------------------------------------------------------
    summary, answer_lines = summary_rows(cases, erg_rows, fmt)
    cons = conserved_rows(cases, params, fmt)
    vol = volume_rows(cases, params, fmt)
    spec, flow_spec = spectra_rows(cases, two_traj, fmt)
    orbit_rows = []
    for (tname, lname), c in cases.items():
        a = c.orbits.alive
        orbit_rows.append([tname, lname, a.shape[1], a.shape[0] - 1, int(np.median(a.sum(0) - 1)), int((~a[-1]).sum()),
                           fmt(c.seconds, 2)])
    push_rows = [[t, fmt(v[0], 3), fmt(v[1], 3), fmt(v[2], 3)] for t, v in push.items()]
    same = [law for law in laws if np.array_equal(fig5[("stadium", law)][1], fig5[("rounded rectangle", law)][1])]
    notes = [f"For {', '.join(same)}, the stadium's and the rounded rectangle's rows are identical: those copies stay "
             "between the flat sides y = +-0.1 m that both tables share, so they meet the same walls."] if same else []
    cover = np.array([[float(r[1]), float(r[2])] for r in erg_rows])
    if np.all(cover[:, 0] < 0.5 * cover[:, 1]):
        notes.append(f"On every table the median orbit covers less than half of what independent draws would after "
                     f"{checkpoints[-1]} impacts: transport through the shell is slow at this time scale (most of the "
                     "invariant measure is on spin-dominated, creeping orbits), so these indicators neither show "
                     "ergodicity nor rule it out.")
    fig5_rows = []
    for t in names:
        for law in laws:
            times, sp, lin, growth = fig5[(t, law)]
            at = [np.searchsorted(times, x) for x in (cfg["fig5_t"] / 4, cfg["fig5_t"] / 2, cfg["fig5_t"])]
            valid = np.isfinite(growth)
            last = int(np.flatnonzero(valid)[-1])
            fig5_rows.append([t, law, *(f"{fmt(sp[k], 2)} ({fmt(lin[k], 2)})" for k in at),
                              fmt(growth[last] / times[last], 3) if last else "-", fmt(times[last], 3)])
    return _write(rep, out, argv, args, cfg, params, rho, compute_s, pngs, orbit_rows, cons, vol, spec, flow_spec, push_rows,
                  erg_rows, fig5_rows, summary, notes, rolling_share, table, fmt, header, answer_lines)


def _write(rep, out, argv, args, cfg, params, rho, compute_s, pngs, orbit_rows, cons, vol, spec, flow_spec, push_rows,
           erg_rows, fig5_rows, summary, notes, rolling_share, table, fmt, header, answer_lines):
    lines = header("The penny as a nonholonomic billiard", "studies.billiards", argv)
    lines += [
        f"Compute time {compute_s:.0f} s ({'--quick' if args.quick else 'full'} run; the machine may have been shared). "
        f"Penny: the paper's (R = {params.R} m, I = m R^2 / 2, J = m R^2 / 4), no torques. Tables: "
        + "; ".join(f"{k} `{v}`" for k, v in TABLES.items()) + ". Laws: elastic, restitution e = 0.9 and 0.5, and the "
        "paper's plastic law. Every orbit starts at the paper's energy (metric speed rho = "
        f"{rho:.4g}, that of theta_dot = 10, phi_dot = 0.2 rad/s) on the wall, drawn from the invariant measure of the elastic "
        "map (below), the same starts for every law on a table. Code: `penny_env/analysis/boundary_map.py` (the map, its "
        "exact tangent maps) and `studies/billiards.py` (this report).", "",
        "## The answer to question 2", "",
        "Written by `python -m studies.billiards_answer` ([billiards_answer.md](billiards_answer.md): 20,000 "
        "impacts per orbit, periodic orbits, slices, the dissipative fate, the cross-check with a published exponent); "
        "this report's finite-time exponents cover 1200 impacts and are indicators, not the answer.", "",
        *_answer_block(out), "",
        "## Coordinates", "",
        "In the scaled speeds (u, w) = (sqrt(I + m R^2) theta_dot, sqrt(J) phi_dot) the kinetic energy is rho^2 / 2 and "
        "between impacts the speeds are constant, so scaling both only rescales time. The boundary map takes one "
        "post-impact state to the next; at an impact the end sigma (+1 front, -1 back) is on the wall at p, and its "
        "coordinates are", "",
        "* s: arc length of p from the positive x axis, counter-clockwise, over the perimeter;",
        "* beta in [-pi/2, pi/2]: angle from the outward normal at p to sigma (cos phi, sin phi), the direction from the "
        "contact point to the end on the wall (the incidence angle);",
        "* psi = atan2(w, sigma u): the spin ratio, an angle on the energy circle.", "",
        "All three are unchanged by relabelling the ends (phi -> phi + pi, theta_dot -> -theta_dot, sigma -> -sigma). "
        "The end's outward normal speed is v_n = R rho nu(beta, psi), nu = cos psi cos beta / sqrt(I + m R^2) - sin psi "
        "sin beta / sqrt(J); after an impact nu < 0. The accessible region of the map is {nu < 0} (both ends inside). "
        "Dissipative orbits are rescaled to the start's speed after every impact (the same orbit in (s, beta, psi), "
        "exact); elastic orbits are not rescaled, so their energy is the simulator's.", "",
        "## Summary (elastic walls)", "",
        f"An orbit counts as chaotic-looking where its largest return-map exponent after {cfg['impacts']} impacts exceeds "
        f"{CHAOS_FACTOR:g} times the largest one on the circle from the same kind of starts (column 'circle's "
        "largest'), whose map is integrable (section 1): the circle's finite-time exponents are the null level at "
        "this number of impacts. The orbits start from independent draws of the invariant measure (all of it, or "
        "its rolling-dominated part, where the penny rolls along table-sized arcs like the paper's penny), so the "
        "share of such orbits estimates the measure of the chaotic-looking part (95 % Clopper-Pearson interval, "
        "honest at 0 and at all). The rolling-dominated part carries only "
        f"{100 * min(rolling_share):.1f} to {100 * max(rolling_share):.1f} % of the invariant measure (fraction of the "
        "reference samples of section 4): most of it sits on spin-dominated states, where the penny pivots near the "
        "wall in small circles and its impacts creep along the wall. Coverage and correlations: section 4.", "",
        *table(["table", "starts", "circle's largest", "lambda1 median [1/impact]", "lambda1 range",
                "chaotic-looking orbits", "95 % interval", "coverage at n", "independent draws at n",
                "C_cos(beta)(10)"], summary), "", *answer_lines, "",
        ]
    lines += [*table(["table", "law", "orbits", "impacts asked", "median impacts followed", "orbits stopped early",
                      "compute [s]"], orbit_rows), "",
              "An orbit stops early where it no longer reaches the wall within 1000 s (it circles clear of the wall) or "
              "at a grazing impact (normal speed below 1e-6 of the end's speed: no derivative there). Restitution and "
              "plastic orbits are driven towards grazing: the normal speed shrinks at every impact while the tangential "
              "part is kept (see the portraits), so their exponents are finite-time ones over the impacts before that.", "",
              "## 1. Boundary maps", "",
              f"![portraits (s, beta)]({pngs['portrait_beta']})", "",
              f"![portraits (s, psi)]({pngs['portrait_psi']})", "",
              "Every impact of every orbit; colour: the other angle (psi on the first figure, beta on the second).", "",
              "### What is conserved", "",
              "* Energy, for elastic walls (the law is a reflection in the kinetic metric, and the free flow keeps the "
              "speeds): column 'energy drift' (the simulator's, along unrescaled orbits).",
              "* On the circle, |beta| for every law, and for elastic walls also |nu| (equivalently the tangential part "
              "of the scaled speed): the reduced map (rotations quotiented out) is an involution, psi and beta repeat "
              "every second impact. Proof: between impacts the contact point runs on a circle about a centre C (radius "
              "R theta_dot / phi_dot) with the heading tangent to it, so both ends run on one circle G about C (radius "
              "sqrt(that^2 + R^2)). G meets the wall in two points X1, X2, mirror images across the line OC (O the "
              "table's centre; for phi_dot = 0, a straight flight, the perpendicular bisector of the chord). Every "
              "impact is at X1 or X2: after an impact at X1 both ends lie on the arc of G inside the table, and the "
              "leading end reaches X2 first. So the penny just before impact B is the mirror image across OC of the "
              "penny just after impact A, with its velocities reversed (the mirror reverses the orientation of the "
              "motion along G, which the motion keeps). In the wall's frame, state before B = K(state after A), K: beta "
              "-> -beta, psi -> pi - psi (theta_dot -> -theta_dot, phi_dot kept; the other end hits, which the "
              "coordinates absorb), hence nu -> -nu. K is an isometry of the kinetic metric that takes the normal-speed "
              "form at beta to minus the one at -beta, so each law here (v+ = v - k grad n with a coefficient even in "
              "beta) commutes with K, and the reduced map is F = Delta o K. Delta keeps beta, so |beta| is conserved "
              "by every law; for elastic walls Delta is an involution, so F o F = Delta o Delta = identity and "
              "nu after B = nu after A. Checked in the table (spread of |beta| and of |nu| along orbits, psi against "
              "psi two impacts earlier) and by tests/analysis/test_billiards.py. On the circle the boundary map is therefore "
              "integrable: (beta, psi) alternate between two values and s advances by a fixed step every two impacts, "
              "as in the specular circle billiard (where the angle is conserved).", "",
              *table(["table", "law", "energy drift max |E/E0 - 1|", "spread of |beta| [rad] (max over orbits)",
                      "relative spread of |nu|", "max |psi_{k+2} - psi_k| [rad]"], cons), "",
              f"![conserved quantities]({pngs['conserved']})", "",
              "## 2. Lyapunov spectra", "",
              "Exact tangent maps per impact (`boundary_map.tangent_maps`): the flight's flow Jacobian "
              "(physics/sensitivity.flow_jacobian), the impact's saltation matrix or, for the return map, the "
              "law's Jacobian after the projection that moves the impact time (physics/sensitivity.impact_linearisation), "
              "reduced to (x, y, phi, theta_dot, phi_dot) (theta is cyclic: one more exponent 0, left out). QR after "
              "every impact. The return map is taken on the 3-D energy shell of the section, in the chart (s, phi, "
              "psi) (speeds rescaled to rho: the energy direction is neutral, one more exponent 0, left out). "
              "The flow (elastic only: for dissipative laws the speed, and with it any exponent per second, decays) "
              "uses all 5 directions, per second of flight at speed rho; exponents scale with the speed.", "",
              "Return map (per impact; medians over the orbits). Known answer: K times the sum of the exponents equals "
              "the sum of ln|det| of the 3-D map in the chart (s [m], phi, psi) along the same K impacts plus the "
              "chart's volume factor at the two ends (ln sqrt(det T^T T), T the chart's 5 x 3 tangent vectors), so the "
              "sum tends to the mean log-determinant; 'max identity residual' is the largest violation of that "
              "identity over the orbits (round-off; larger for the dissipative laws, whose orbits end near grazing, where "
              "the tangent maps are ill-conditioned):", "",
              *table(["table", "law", "orbits", "impacts (median)", "lambda1", "lambda2", "lambda3", "lambda1 range",
                      "sum", "mean log det", "max identity residual"], spec), "",
              "Expected for elastic walls: the return map preserves a smooth measure (section 3), so its exponents sum "
              "to 0, and it is reversible (reverse the speeds, then apply the law), so its spectrum is symmetric: "
              "(lambda, 0, -lambda). The flow adds two zeros, along the flow and along the energy (theta, left out, is "
              "a third): (l, 0, 0, 0, -l) with l = lambda / (mean flight time) (Abramov). For dissipative laws nothing "
              "forces a zero.", "",
              "Flow, elastic walls (per second, medians over the orbits). "
              "Cross-checks: lambda1 of the return map over the mean flight time (Abramov's "
              "formula) and the two-trajectory estimate of `penny_env.analysis.dynamics.lyapunov_exponents` (started "
              f"from the same states, {cfg['two_traj_t']:g} s, fitted while the separation is < 1e-4):", "",
              *table(["table", "starts", "orbits", "l1", "l2", "l3", "l4", "l5", "sum", "l1 map / mean flight",
                      "l1 / (l1 map / mean flight), per orbit", "two-trajectory", "median flight [s]"], flow_spec), "",
              "Where the per-orbit ratio is far from 1 the flow's exponents have not converged (their running values "
              "in the figure still fall): a flight's tangent map grows linearly in time (shear along the flow and the "
              "energy), and near-grazing impacts, frequent on the creeping spin-dominated orbits, amplify it for a "
              "while. The two-trajectory estimate fits one perturbation's growth over a fixed window while it is below "
              "1e-4: a finite-time, single-direction estimate, expected to fall below l1 where the orbits are mixed.", "",
              f"![convergence of the return map's largest exponent]({pngs['convergence_map']})", "",
              f"![convergence of the flow's spectrum]({pngs['convergence_flow']})", "",
              "Limits: finite-time exponents from a few orbits; on the circle they fall like log(n)/n (integrable), so a "
              "small positive value there is a finite-time effect, not chaos. The spread across initial states "
              "(column 'lambda1 range', and the convergence plots) is the honest error bar; no orbit was discarded "
              "except as stated above.", "",
              "## 3. Volume", "",
              "Per impact, in the stated coordinates:", "",
              "* the flow's tangent map over one flight and impact (5-D, (x, y, phi, theta_dot, phi_dot), fixed times: "
              "free flow is divergence-free and the saltation matrix has det = det(D Delta) v_n+ / v_n-) has det = "
              "e_eff^2, e_eff = -v_n+ / v_n- the law's effective coefficient: 1 elastic, e restitution, e_p(beta) "
              "plastic (thin penny: (cos^2 beta / 3 + 3 sin^2 beta) / (1 + 4 sin^2 beta); the column 'max |e_eff - "
              "formula|' checks it against the simulator);",
              "* the return map on the 3-D energy shell in (s, phi, psi) satisfies, pointwise, ln|det| + ln|nu(after)| - "
              "ln|nu(before)| = 2 ln e_eff - 3 ln k, k the speed ratio of the impact (flux through the section; "
              "column 'max residual'). For elastic walls (e_eff = k = 1): the map preserves the measure |nu(beta, psi)| "
              "ds dbeta dpsi (ds dphi = ds dbeta): the analogue of Birkhoff's cos(theta) ds dtheta, the flux of the "
              "Liouville measure of the flow through the section. It is not Lebesgue: the plain log-determinant of a "
              "single step is not 0, only its average along an orbit tends to 0.", "",
              *table(["table", "law", "impacts", "mean ln|det| flow", "mean 2 ln e(formula)", "max |ln det - 2 ln e_eff|",
                      "max |e_eff - formula|", "mean ln|det| 3-D map", "mean (2 ln e_eff - 3 ln k)", "max residual"], vol), "",
              f"![log-determinant per impact]({pngs['logdet']})", "",
              f"A second check, one map step of a sample: {cfg['push']} states drawn from |nu| ds dbeta dpsi, pushed one "
              "elastic impact on, against a fresh sample, as total-variation distance on a grid of (s, beta, psi) "
              "boxes (8 per axis in the full run), next to the sampling noise (two fresh samples) and, for the check's "
              "resolution, the distance of the pushed sample from a sample uniform in (s, beta, psi) on the accessible "
              "region:", "",
              *table(["table", "TV(pushed, fresh)", "TV(fresh, fresh): noise", "TV(pushed, uniform)"],
                     push_rows), "",
              "## 4. Ergodicity indicators (elastic walls)", "",
              "Coverage: the fraction of the accessible cells of a grid of "
              f"{cfg['bins']}^3 boxes in (s, beta, psi) (the boxes that a large sample of the invariant measure visits) "
              "visited by one orbit's first n impacts (median over orbits), against n independent draws from the "
              "invariant measure (dotted). Correlations: normalised autocorrelation of cos(beta) and of |nu| along "
              "orbits (pooled).", "",
              *table(["table", "coverage at n", "independent draws at n", "n", "C_cos(beta)(10)", "C_|nu|(10)"], erg_rows),
              "", *[n for n in notes if n.startswith("On every")], "",
              f"![ergodicity indicators]({pngs['ergodicity']})", "",
              "Specular billiards on the same tables, for comparison (known results, not computed here): the circle "
              "and the ellipse are integrable (the angle, resp. Joachimsthal's integral, is conserved); Bunimovich's "
              "stadium is ergodic, mixing and Bernoulli; the rounded rectangle (flat sides joined by quarter circles) "
              "is of Bunimovich's type (focusing arcs and flat sides), and we have not checked the conditions of his "
              "theorems for it. Here: the circle keeps its integrability (proof above); whether the nonholonomic "
              "ellipse, stadium and rounded rectangle are ergodic is not settled by indicators: coverage close to "
              "that of independent draws and fast-decaying correlations are consistent with ergodicity and mixing, "
              "and a coverage well below it points to invariant sets (islands); neither is a proof.", "",
              "## 5. The paper's Figure 5, extended", "",
              f"{cfg['fig5_n']} copies of the paper's state (x = y = theta = 0, phi = pi/2, theta_dot = 10, phi_dot = 0.2) "
              "with theta_dot and phi_dot perturbed by less than 0.005 (uniform), simulated together "
              "(penny_env.batch.simulate, no rescaling); spread: the largest distance of the copies' contact points from "
              "their mean. In brackets and dashed: the spread that the exact Jacobian of the unperturbed penny predicts "
              "for the same perturbations (`simulate(..., sensitivities=True)`, linear in the perturbation): where the "
              "two agree, the linearisation, and with it the finite-time Lyapunov exponent along the paper's own orbit "
              "(last columns: ln of the largest singular value of the reduced Jacobian, positions over the table's size "
              "and speeds over the paper's speed as in `dynamics.state_distance`, over the time, at the last time "
              "with a derivative: a grazing impact or a Zeno rest ends it), predicts the spread; where the copies "
              "spread less than predicted, the spread has saturated (nonlinear) or the copies' impacts differ "
              "(a perturbation this size changes which impacts happen near grazing). The exponents of sections 2 "
              "are averages over the invariant measure, not this one orbit's.", "",
              *table(["table", "law", f"spread (linear) at {cfg['fig5_t'] / 4:g} s [m]", f"at {cfg['fig5_t'] / 2:g} s [m]",
                      f"at {cfg['fig5_t']:g} s [m]", "finite-time exponent [1/s]", "up to [s]"], fig5_rows), "",
              *[n for n in notes if n.startswith("For ")], "",
              f"![Figure 5 extended]({pngs['figure5']})", ""]
    return rep.write(lines, echo=True)


if __name__ == "__main__":
    main()
