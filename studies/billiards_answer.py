"""The paper's second question, answered per law: "when and if nonholonomic billiards are chaotic / ergodic /
measure preserving" (Clark & Bloch, Section 6), with every claim labelled **theorem** (proved here or cited),
**computed** (measured by this command, with its error bars) or **open**.

    python -m studies.billiards_answer [--quick] [--out docs/billiards_answer.md]

Computed here (the uncontrolled paper's penny at the paper's energy; circle, the paper's ellipse, the stadium):

1. elastic walls: Lyapunov exponents of the boundary map from the exact tangent maps (boundary_map.tangent_maps,
   QR after every impact) over n_impacts (20,000 in the full run) impacts for many orbits drawn from the invariant
   measure and from its rolling-dominated part, with their running values (convergence) and the circle, integrable,
   as the null level; the ergodic check of Kac's lemma (each orbit's mean flight time against the invariant
   measure's mean);
2. the cross-check of the Lyapunov machinery on a billiard with a published exponent (penny_env.analysis.
   point_billiard: the Sinai billiard against Dahlqvist's small-scatterer formula);
3. periodic orbits of the elastic map (Newton from many seeds, penny_env.analysis.periodic_orbits) with their
   eigenvalues, and whether orbits started next to an elliptic one stay next to it (an island);
4. 2-D slices of the map (psi fixed): the finite-time exponent of every point of a grid, against the circle's;
5. dissipative walls (e = 0.9, 0.5, plastic): the fate of orbits from the invariant measure (impacts until grazing,
   the energy kept), and their finite-time exponents.

--quick runs a few short orbits (for the tests) into a temporary folder and never writes docs/ or the README. The
full run writes docs/billiards_answer.md (+ PNGs and billiards_answer.json) and the answer blocks of README.md and
docs/billiards.md (between the question2-answer markers).
"""
from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from penny_env.physics import PennyParams, make_table
from penny_env.analysis import boundary_map as bm
from penny_env.analysis import periodic_orbits as po
from studies import point_billiard as pb

ROOT = Path(__file__).resolve().parents[1]
TABLES = {"circle": {"kind": "circle", "radius": 0.2}, "ellipse": {"kind": "ellipse", "a": 0.15, "b": 0.2},
          "stadium": {"kind": "stadium", "radius": 0.1, "length": 0.15}}
DISSIPATIVE = {"e = 0.9": 0.9, "e = 0.5": 0.5, "plastic": "plastic"}
ROLLING_SPIN = 0.04   # rolling-dominated starts: |sin psi| <= this (billiards.py's)
WEDGE = 10           # this many impacts in a row at zero flight time: wedged (both ends on the wall)
ISLAND = 0.05        # orbits started 1e-3 from an elliptic periodic orbit that stay this close (in z): an island
CHAOS_FACTOR = 10.0   # chaotic-looking: lambda1 above this many times the circle's largest at the same length
CONVERGED = 0.10      # an exponent is called converged to 10 %: 2 batch-means SE and the n/2 -> n change both below
ISLAND_TURNS = 3      # island checks run at least this many turns of the linearised rotation (capped below)
ISLAND_CAP = 20000    # ... but at most this many impacts
PAPER_STATE = np.array([0.0, 0.0, 0.0, np.pi / 2, 10.0, 0.2])
CONFIGS = {
    "quick": dict(orbits=2, impacts=300, checkpoints=(75, 150, 300), sinai_rho=(0.03,), sinai_orbits=2,
                  sinai_impacts=1000, seeds=6, periods=(2,), island_steps=50, slice_grid=(12, 6), slice_impacts=20,
                  slices=(2.74,), fate_orbits=16, fate_impacts=400, fate_tangent=2, kac_sample=400),
    "full": dict(orbits=12, impacts=20000, checkpoints=(1250, 2500, 5000, 10000, 20000),
                 sinai_rho=(0.1, 0.03, 0.01, 0.003), sinai_orbits=16, sinai_impacts=20000, seeds=400,
                 periods=(1, 2, 3, 4), island_steps=2000, slice_grid=(100, 50), slice_impacts=300,
                 slices=(3.1, 2.74, 1.9), fate_orbits=2000, fate_impacts=3000, fate_tangent=8, kac_sample=20000),
}
README_BEGIN = "<!-- question2-answer: written by python -m studies.billiards_answer -->"
README_END = "<!-- /question2-answer -->"


# -- 1. Lyapunov exponents, elastic ------------------------------------------------------------------------
def lyapunov(tname, cfg, params, rho, seed):
    """Elastic orbits of one table from the invariant measure and its rolling part: per orbit the running largest
    exponent at the checkpoints, the final spectrum, a log-spaced running curve, the mean flight time."""
    tab = make_table(TABLES[tname])
    chart = bm.WallChart(tab)
    rng = np.random.default_rng(seed)
    out = []
    for kind, spin in (("invariant", None), ("rolling", ROLLING_SPIN)):
        S, _, _, _ = bm.sample_invariant(cfg["orbits"], tab, rng, params, rho, chart, max_spin=spin)
        orb = bm.iterate(S, np.ones(len(S)), cfg["impacts"], table=tab, law="elastic", params=params, rescale=True)
        for i in range(len(S)):
            tm = bm.tangent_maps(orb, i)
            K = len(tm.section)
            if K < 2:
                continue
            T0 = bm.section_chart(orb.post[0, i], orb.ends[0, i], tab, params)
            run = bm.qr_exponents(tm.section, T0)
            lam1 = run.max(axis=1)
            grid = np.unique(np.geomspace(1, K, 200).astype(int)) - 1
            out.append({"kind": kind, "impacts": K, "final": sorted(run[-1].tolist(), reverse=True),
                        "lam_se": batch_se(increments(run[:, int(np.argmax(run[-1]))])),
                        "at": {int(n): float(lam1[n - 1]) for n in cfg["checkpoints"] if n <= K},
                        "curve_n": (grid + 1).tolist(), "curve": lam1[grid].tolist(),
                        "mean_flight": float(np.mean(orb.flight[:K, i])), "flight_se": batch_se(orb.flight[:K, i])})
    return out


def increments(running):
    """The per-impact terms whose running mean is `running` (the log-stretch of each impact in QR)."""
    r = np.asarray(running, float)
    n = np.arange(1, len(r) + 1)
    return np.diff(np.concatenate([[0.0], n * r]))


def batch_se(x, batches=20):
    """Standard error of the mean of a correlated series by batch means (successive flights are correlated)."""
    x = np.asarray(x, float)
    m = len(x) // batches
    if m < 2:
        return float(np.std(x) / math.sqrt(max(len(x), 1)))
    means = x[:m * batches].reshape(batches, m).mean(axis=1)
    return float(np.std(means, ddof=1) / math.sqrt(batches))


def pooled_batch_means(runs, batches=10):
    """Batch means of the per-collision terms of every orbit (batches per orbit), pooled: the heavy-tailed flights of
    small scatterers make single orbits' spreads unreliable, so the error bar uses every batch of every orbit."""
    out = []
    for run in np.atleast_2d(runs):
        x = increments(run)
        m = len(x) // batches
        if m >= 1:
            out += x[:m * batches].reshape(batches, m).mean(axis=1).tolist()
    return out


def kac_mean_flight(tname, n, params, rho, seed):
    """The invariant measure's mean flight time (one impact from n independent draws of it) and its standard error."""
    tab = make_table(TABLES[tname])
    rng = np.random.default_rng(seed)
    S, _, _, _ = bm.sample_invariant(n, tab, rng, params, rho)
    orb = bm.iterate(S, np.ones(n), 1, table=tab, law="elastic", params=params, rescale=True)
    f = orb.flight[0][np.isfinite(orb.flight[0])]
    return float(f.mean()), float(f.std() / math.sqrt(f.size))


# -- 3. periodic orbits ----------------------------------------------------------------------------------------
def periodic(tname, cfg, params, rho, seed):
    smap = po.SectionMap(TABLES[tname], params, rho)
    rng = np.random.default_rng(seed)
    rows = []
    for p in cfg["periods"]:
        _, s, b, q = bm.sample_invariant(cfg["seeds"], smap.table, rng, params, rho, smap.chart)
        seeds = np.stack([s, b, q], 1)
        if tname != "circle" and p == 2:  # the double normals' head-on bounces (T3.4), as seeds too
            seeds = np.vstack([seeds, [[0.0, 0.0, np.pi], [0.25, 0.0, np.pi]]])
        found = po.distinct(po.find_periodic(smap, p, seeds), p, smap)
        for z, J, res, low in found:
            kind, ev = po.classify(J)
            row = {"period": p, "z": z.tolist(), "type": kind, "eigenvalues": [[float(e.real), float(e.imag)] for e in ev],
                   "residual": res, "island": None}
            if kind == "elliptic":
                a = rotation_per_period(ev)
                steps = cfg["island_steps"]
                if a > 0:  # at least ISLAND_TURNS turns of the linearised rotation, within the cap
                    steps = int(min(max(steps, math.ceil(ISLAND_TURNS * 2 * math.pi / a) * p), ISLAND_CAP))
                row["rotation"], row["island_steps"] = a, steps
                row["turns"] = steps / p * a / (2 * math.pi)
                row["island"] = island(smap, z, p, steps, rng)
            if kind == "parabolic" and tname == "stadium":
                row["pieces"] = wall_pieces(smap, z, p)
            rows.append(row)
    return rows


def rotation_per_period(ev) -> float:
    """The rotation angle a (rad per period) of an elliptic orbit: the argument of its complex eigenvalue pair."""
    return float(max(abs(math.atan2(e.imag, e.real)) for e in ev))


def wall_pieces(smap, z, p) -> str:
    """Where the impacts of the stadium's period-p orbit through z lie: "flat" (every one on the flat sides: the orbit
    translated along a side is again periodic, a neutral family like the specular stadium's bouncing-ball orbits),
    "cap" (every one on one cap, a circle arc: the orbit rotated about the cap's centre is again periodic, a neutral
    family as on the circle, whose orbits are all neutral), or "mixed"."""
    pts, cur = [z], np.asarray(z, float)[None, :]
    for _ in range(p - 1):
        cur = smap.step(cur, 1)[0]
        pts.append(cur[0])
    tab = smap.table
    where = set()
    for q in pts:
        px, py = smap.chart.point(np.array([q[0]]))
        x, y = float(np.ravel(px)[0]), float(np.ravel(py)[0])
        where.add("flat" if abs(x) <= tab.length / 2 and abs(abs(y) - tab.radius) < 1e-9 else
                  ("cap+" if x > 0 else "cap-"))
    if where == {"flat"}:
        return "flat"
    return "cap" if len(where) == 1 else "mixed"


def island(smap, z, p, steps, rng, n=6, start=1e-3):
    """Largest distance from the periodic orbit (its p points) over `steps` impacts of n orbits started `start`
    away: small means the orbits stay in a neighbourhood (an island), of the order of the box means they left."""
    pts = [z]
    cur = z[None, :]
    for _ in range(p - 1):
        cur = smap.step(cur, 1)[0]
        pts.append(cur[0])
    zs = z + start * rng.normal(size=(n, 3))
    zs = zs[smap.valid(zs)]
    worst = 0.0
    for _ in range(steps):
        zs, _, alive = smap.step(zs, 1)
        zs = zs[alive]
        if not len(zs):
            return float("nan")
        d = np.min([np.abs(po.difference(zs, q)).max(axis=1) for q in pts], axis=0)
        worst = max(worst, float(d.max()))
    return worst


# -- 5. dissipative walls --------------------------------------------------------------------------------------
def fate(tname, law, cfg, params, rho, seed):
    """Orbits from the invariant measure under a dissipative law, followed (speeds rescaled) until they stop:
    per orbit the impacts followed, how it stopped, the energy kept, the start's normal share q0 (the part of the
    speed along the impact normal) and the shortest flight."""
    tab = make_table(TABLES[tname])
    rng = np.random.default_rng(seed)
    S, _, beta, psi = bm.sample_invariant(cfg["fate_orbits"], tab, rng, params, rho)
    orb = bm.iterate(S, np.ones(len(S)), cfg["fate_impacts"], table=tab, law=law, params=params, rescale=True)
    dens = bm.normal_speed_density(beta, psi, params)
    norm = np.sqrt(np.cos(beta) ** 2 / params.rolling_inertia + np.sin(beta) ** 2 / params.J)
    q0 = np.abs(dens) / norm
    K = orb.flight.shape[0]
    rows = []
    for i in range(len(S)):
        dead = np.flatnonzero(~orb.alive[:, i])
        k_end = int(dead[0]) - 1 if dead.size else K
        ratio = orb.speed_ratio[:k_end, i]
        kept = float(np.prod(ratio[np.isfinite(ratio)] ** 2))
        flights = orb.flight[:k_end, i]
        if k_end >= WEDGE and np.all(flights[-WEDGE:] <= 1e-12):
            stop = "wedged"  # impacts at zero flight time: both ends on the wall, alternately
        elif not dead.size:
            stop = "running"
        else:
            stop = "grazing" if np.isfinite(orb.flight[min(k_end, K - 1), i]) else "clear"
        loss = (float(np.median(1.0 - ratio[-WEDGE:] ** 2)) if stop == "wedged" and k_end >= WEDGE else float("nan"))
        rows.append({"impacts": k_end, "stop": stop, "kept": kept, "q0": float(q0[i]), "wedged_loss": loss,
                     "min_flight": float(np.nanmin(flights[-20:])) if k_end else float("nan")})
    lam = []
    for i in range(min(cfg["fate_tangent"], len(S))):
        tm = bm.tangent_maps(orb, i)
        if len(tm.section) >= 3:
            T0 = bm.section_chart(orb.post[0, i], orb.ends[0, i], tab, params)
            lam.append(float(bm.qr_exponents(tm.section, T0)[-1].max()))
    return rows, lam


# -- the answer ------------------------------------------------------------------------------------------------
def summarise(res, cfg) -> dict:
    """The numbers the answer quotes, from the raw results."""
    from lab.stats import clopper_pearson

    s = {"impacts": cfg["impacts"], "tables": {}}
    n_max = max(n for n in cfg["checkpoints"] if n <= cfg["impacts"])
    null = max(o["at"].get(n_max, np.nan) for o in res["lyapunov"]["circle"])
    s["null"] = null
    for t, orbits in res["lyapunov"].items():
        lam = np.array([o["at"].get(n_max, np.nan) for o in orbits])
        half = np.array([o["at"].get(n_max // 2, np.nan) for o in orbits])
        chaotic = lam > CHAOS_FACTOR * null
        k, n = int(chaotic.sum()), int(len(lam))
        drift = np.abs(lam - half)[chaotic] / lam[chaotic] if k else np.array([])
        rel_se = np.array([o["lam_se"] for o in orbits])[chaotic] / lam[chaotic] if k else np.array([])
        conv = (2 * rel_se <= CONVERGED) & (drift <= CONVERGED)
        flights = np.array([o["mean_flight"] for o in orbits])
        ses = np.array([o["flight_se"] for o in orbits])
        kac, kac_se = res["kac"][t]
        z = (flights - kac) / np.sqrt(ses ** 2 + kac_se ** 2)
        s["tables"][t] = {"orbits": n, "chaotic": k, "ci": clopper_pearson(k, n),
                          "stopped": int(sum(o["impacts"] < cfg["impacts"] for o in orbits)),
                          "chaotic_inv": int(sum(c for c, o in zip(chaotic, orbits) if o["kind"] == "invariant")),
                          "n_inv": sum(o["kind"] == "invariant" for o in orbits),
                          "lam_median": float(np.median(lam[chaotic])) if k else float("nan"),
                          "lam_range": [float(lam[chaotic].min()), float(lam[chaotic].max())] if k else [],
                          "regular_max": float(lam[~chaotic].max()) if (~chaotic).any() else float("nan"),
                          "drift_max": float(drift.max()) if k else float("nan"),
                          "drift_median": float(np.median(drift)) if k else float("nan"),
                          "rel_se_median": float(np.median(rel_se)) if k else float("nan"),
                          "rel_se_max": float(rel_se.max()) if k else float("nan"),
                          "converged": int(conv.sum()),
                          "kac": kac, "kac_z_max": float(np.max(np.abs(z))),
                          "kac_off": int(np.sum(np.abs(z) > 4))}
    s["sinai"] = []
    for r, v in res["sinai"].items():
        f, b = np.array(v["finals"]), np.array(v["batch_means"])
        between = float(np.std(f, ddof=1) / math.sqrt(len(f))) if len(f) > 1 else float("nan")
        pooled = float(np.std(b, ddof=1) / math.sqrt(len(b))) if len(b) > 1 else float("nan")
        s["sinai"].append({"rho": r, "lam": float(np.mean(f)), "se_between": between, "se_batches": pooled,
                           "se": float(np.nanmax([between, pooled])), "orbits": len(f), "batches": len(b),
                           "dahlqvist": float(pb.dahlqvist(r))})
    s["periodic"] = {t: {"found": len(rows), "types": {k: sum(r["type"] == k for r in rows)
                                                       for k in ("hyperbolic", "elliptic", "parabolic")},
                         "islands": [r["island"] for r in rows if r["type"] == "elliptic"],
                         "with_island": sum(r["type"] == "elliptic" and r["island"] is not None
                                            and r["island"] < ISLAND for r in rows),
                         "island_turns": [r["turns"] for r in rows if r["type"] == "elliptic" and r["island"] is not None
                                          and r["island"] < ISLAND],
                         "rotations": [r["rotation"] for r in rows if r["type"] == "elliptic"],
                         "parabolic_pieces": {k: sum(r.get("pieces") == k for r in rows if r["type"] == "parabolic")
                                              for k in ("cap", "flat", "mixed")}}
                     for t, rows in res["periodic"].items()}
    s["slices"] = res["slice_summary"]
    s["fate"] = {}
    for (t, law), (rows, lam) in res["fate"].items():
        k = np.array([r["impacts"] for r in rows])
        kept = np.array([r["kept"] for r in rows])
        pred = np.array([1 - r["q0"] ** 2 for r in rows])
        stops = {x: sum(r["stop"] == x for r in rows) for x in ("grazing", "clear", "wedged", "running")}
        s["fate"][f"{t}|{law}"] = {"orbits": len(rows), "stops": stops,
                                   "impacts_q": [float(np.percentile(k, q)) for q in (5, 50, 95)],
                                   "kept_q": [float(np.percentile(kept, q)) for q in (5, 50, 95)],
                                   "kept_vs_tangential": float(np.max(np.abs(kept - pred))),
                                   "kept_vs_tangential_median": float(np.median(np.abs(kept - pred)[
                                       np.array([r["stop"] == "grazing" for r in rows])])),
                                   "min_flight": float(np.nanmin([r["min_flight"] for r in rows])),
                                   "wedged_loss": [r["wedged_loss"] for r in rows if r["stop"] == "wedged"],
                                   "lam": [float(np.min(lam)), float(np.max(lam))] if lam else []}
    return s


def answer_block(s, base="docs/") -> str:
    """The short answer per law (README with base "docs/", docs/billiards.md with base ""): computed from the summary,
    never typed."""
    t = s["tables"]
    ell, sta = t["ellipse"], t["stadium"]
    pe, ps = s["periodic"]["ellipse"], s["periodic"]["stadium"]
    fates = s["fate"]
    graze = sum(f["stops"]["grazing"] + f["stops"]["clear"] for f in fates.values())
    wedged = sum(f["stops"]["wedged"] for f in fates.values())
    total = sum(f["orbits"] for f in fates.values())
    kept = [f["kept_q"] for f in fates.values()]
    sinai = s["sinai"][-1]

    def isl(p):
        good = [x for x in p["islands"] if x is not None and np.isfinite(x) and x < ISLAND]
        n = p['types']['elliptic']
        found = f"{n} elliptic periodic orbit{'' if n == 1 else 's'} found"
        if not good:
            return f"{found}, none with an island"
        rot, turns = p.get("rotations") or [0.0], p.get("island_turns") or [0.0]
        return (f"{found}, {p['with_island']} with an island as far as checked (orbits started 1e-3 away stay within "
                f"{max(good):.2g} over {min(turns):.1f} to {max(turns):.1f} turns of the linearised rotation, which "
                f"turns {min(rot):.3f} to {max(rot):.3f} rad per period: stability over those turns, not a KAM proof)")

    def wedge():
        loss = [x for f in fates.values() for x in f.get("wedged_loss", []) if np.isfinite(x)]
        span = f", losing {min(loss):.1e} to {max(loss):.1e} of its energy per impact over its last {WEDGE}" if loss else ""
        return (f"{wedged} end wedged as a chord of the wall: a Zeno accumulation of the sequential single-impact model "
                f"(both ends alternately, flights below 1e-12 s{span}), so whether such a penny comes to rest is not "
                "decided by the impacts followed, and a configuration with both ends on the wall is outside the "
                "paper's single-impact theory")

    def pieces(p):
        c = p.get("parabolic_pieces", {})
        return (f"{c.get('cap', 0)} with every impact on one cap, a family by rotation about its centre as on the "
                f"circle; {c.get('flat', 0)} on the flat sides, a family by translation along them like the "
                f"bouncing-ball orbits; {c.get('mixed', 0)} on both")

    def conv(v):
        return (f"{v['converged']}/{v['chaotic']} within {100 * CONVERGED:.0f} % (2 batch-means SE and the change "
                f"n/2 -> n, median {100 * v['drift_median']:.0f} %)")
    lines = [
        "Answer to the paper's second question (chaotic? ergodic? measure preserving?) per law, each claim labelled; "
        f"details, proofs and error bars: [{base}billiards_answer.md]({base}billiards_answer.md).", "",
        "| law | measure | chaos | ergodicity |", "| --- | --- | --- | --- |",
        "| elastic | **theorem**: the boundary map preserves \\|nu\\| ds dbeta dpsi (the flux of the flow's Liouville "
        "measure; proof written out) | **computed**: positive exponents on part of the ellipse and the stadium: "
        f"{ell['chaotic']}/{ell['orbits']} and {sta['chaotic']}/{sta['orbits']} orbits over {s['impacts']} impacts "
        f"({ell['chaotic_inv']}/{ell['n_inv']} and {sta['chaotic_inv']}/{sta['n_inv']} of those drawn from the whole "
        f"invariant measure), lambda1 {_span(ell['lam_range'])} and {_span(sta['lam_range'])} per impact, finite-time "
        f"values not converged ({conv(ell)}; {conv(sta)}): the classification is robust, the values are not; the circle "
        "has none (**theorem**: integrable) | circle: **not ergodic (theorem**: \\|beta\\| is an invariant function "
        f"that is not constant). Ellipse: **computed** evidence against: {isl(pe)}; regular-looking orbits hold most of "
        f"the measure. Stadium: **computed**: {isl(ps)}, {ps['types']['parabolic']} parabolic (all eigenvalues 1: "
        f"neutral families, not islands: {pieces(ps)}); Kac's check "
        f"(each orbit's mean flight against the invariant mean) fails for {ell['kac_off']}/{ell['orbits']} ellipse and "
        f"{sta['kac_off']}/{sta['orbits']} stadium orbits (more than 4 standard errors off): not ergodic, or mixing "
        "slower than these runs. A proof either way is **open** |",
        "| e < 1, plastic | **theorem**: volume contracts by e_eff^2 per impact (no invariant measure with a density) | "
        f"**computed**: no chaotic attractor; {graze}/{total} orbits from the invariant measure reach grazing (or stop "
        f"hitting the wall) within {max(f['impacts_q'][2] for f in fates.values()):.0f} impacts (95th percentiles), "
        f"keeping {min(k[1] for k in kept):.2f} to {max(k[1] for k in kept):.2f} of the energy (medians), and "
        f"{wedge()}; on the circle **theorem**: the "
        "normal part shrinks by e each impact and the tangential part is kept, so every orbit tends to grazing with the "
        "energy share 1 - q0^2 | not applicable (dissipative) |", "",
        f"Cross-check of the exponents' code: the Sinai billiard's published exponent (Dahlqvist 1997) is reproduced "
        f"to {abs(sinai['lam'] - sinai['dahlqvist']):.3f} per collision at rho = {sinai['rho']:g} (standard error "
        f"{sinai['se']:.3f} from {sinai.get('batches', 0)} pooled batch means of {sinai.get('orbits', 0)} orbits; the "
        "flights are heavy-tailed at small rho, so the error bar is itself uncertain; the formula's error term is "
        "O(rho ln^2 rho))."]
    return "\n".join(lines)


def _loss_span(losses):
    x = [v for v in losses if np.isfinite(v)]
    return f"{min(x):.1e} to {max(x):.1e}" if x else "-"


def _span(r):
    return f"{r[0]:.2f} to {r[1]:.2f}" if r else "-"


# -- the report ------------------------------------------------------------------------------------------------
def run(cfg, params, rho):
    res = {"lyapunov": {}, "kac": {}, "sinai": {}, "periodic": {}, "slices": {}, "slice_summary": {}, "fate": {}}
    for ti, t in enumerate(TABLES):
        t0 = time.perf_counter()
        res["lyapunov"][t] = lyapunov(t, cfg, params, rho, seed=ti)
        res["kac"][t] = kac_mean_flight(t, cfg["kac_sample"], params, rho, seed=100 + ti)
        print(f"lyapunov {t}: {time.perf_counter() - t0:.0f} s", flush=True)
    for r in cfg["sinai_rho"]:
        finals, runs, _ = pb.sinai_lyapunov(r, cfg["sinai_orbits"], cfg["sinai_impacts"], seed=7)
        res["sinai"][r] = {"finals": finals.tolist(), "batch_means": pooled_batch_means(runs)}
    for ti, t in enumerate(TABLES):
        if t == "circle":
            continue
        t0 = time.perf_counter()
        res["periodic"][t] = periodic(t, cfg, params, rho, seed=200 + ti)
        print(f"periodic {t}: {time.perf_counter() - t0:.0f} s", flush=True)
    for t in TABLES:
        smap = po.SectionMap(TABLES[t], params, rho)
        for psi in cfg["slices"]:
            t0 = time.perf_counter()
            res["slices"][(t, psi)] = po.slice_ftle(smap, psi, *cfg["slice_grid"], cfg["slice_impacts"])
            print(f"slice {t} psi={psi}: {time.perf_counter() - t0:.0f} s", flush=True)
    for psi in cfg["slices"]:
        null = res["slices"][("circle", psi)][2]
        level = float(np.nanpercentile(null, 99)) if np.isfinite(null).any() else float("nan")
        for t in TABLES:
            F = res["slices"][(t, psi)][2]
            ok = np.isfinite(F)
            res["slice_summary"][f"{t}|{psi:g}"] = {"points": int(ok.sum()), "null_level": level,
                                                   "regular_share": float(np.mean(F[ok] <= level)) if ok.any() else float("nan"),
                                                   "median": float(np.nanmedian(F)) if ok.any() else float("nan")}
    for ti, t in enumerate(TABLES):
        for law, value in DISSIPATIVE.items():
            res["fate"][(t, law)] = fate(t, value, cfg, params, rho, seed=300 + ti)
    return res


def plots(res, s, out, cfg):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = {}

    def save(fig, key):
        fig.tight_layout()
        path = out.with_name(f"{out.stem}_{key}.png")
        fig.savefig(path, dpi=80)
        plt.close(fig)
        names[key] = path.name

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2), sharey=True)
    for ax, t in zip(axes, TABLES):
        for o in res["lyapunov"][t]:
            ax.loglog(o["curve_n"], np.maximum(o["curve"], 1e-6), color="tab:red" if o["kind"] == "rolling" else "tab:blue",
                      lw=0.7, alpha=0.8)
        ax.axhline(CHAOS_FACTOR * s["null"], color="k", ls=":", lw=0.8)
        ax.set(xlabel="impacts", title=f"{t}")
    axes[0].set_ylabel("largest exponent per impact")
    save(fig, "convergence")

    psis = cfg["slices"]
    fig, axes = plt.subplots(len(psis), 3, figsize=(15, 3.6 * len(psis)), squeeze=False)
    for r, psi in enumerate(psis):
        for c, t in enumerate(TABLES):
            sg, bg, F = res["slices"][(t, psi)]
            im = axes[r, c].pcolormesh(sg, bg, F, vmin=0, vmax=0.4, cmap="magma", shading="auto")
            axes[r, c].set(title=f"{t}, psi = {psi:g}", xlabel="s", ylabel="beta")
            fig.colorbar(im, ax=axes[r, c], label="FTLE per impact")
    save(fig, "slices")

    fig, axes = plt.subplots(1, 2, figsize=(12, 4))
    for (t, law), (rows, _) in res["fate"].items():
        k = np.sort([r["impacts"] for r in rows])
        axes[0].plot(k, np.linspace(0, 1, len(k)), label=f"{t}, {law}", lw=0.9)
        kept = np.sort([r["kept"] for r in rows])
        axes[1].plot(kept, np.linspace(0, 1, len(kept)), label=f"{t}, {law}", lw=0.9)
    axes[0].set(xscale="log", xlabel="impacts until grazing", ylabel="share of orbits", title="dissipative walls: fate")
    axes[1].set(xlabel="energy kept", ylabel="share of orbits", title="energy kept at the end")
    axes[0].legend(fontsize=6)
    save(fig, "fate")

    fig, ax = plt.subplots(figsize=(6, 4))
    rhos = np.array([x["rho"] for x in s["sinai"]])
    ax.errorbar(rhos, [x["lam"] + 2 * math.log(x["rho"]) for x in s["sinai"]], yerr=[2 * x["se"] for x in s["sinai"]],
                fmt="o-", label="computed: lambda + 2 ln rho")
    ax.axhline(pb.DAHLQVIST_C, color="k", ls="--", label="Dahlqvist's C")
    ax.set(xscale="log", xlabel="disk radius rho", ylabel="per collision", title="Sinai billiard: the known answer")
    ax.legend()
    save(fig, "sinai")
    return names


def write_report(rep, res, s, cfg, seconds):
    from lab.common import table

    names = plots(res, s, rep.out, cfg)
    lines = rep.header("The penny's billiard: the answer to question 2 per law")
    lines += [f"Compute time {seconds:.0f} s. Penny: the paper's, no torques, at the paper's energy; tables "
              + ", ".join(f"{t} `{v}`" for t, v in TABLES.items()) + ". Coordinates and the boundary map: "
              "[billiards.md](billiards.md) (s: arc length over the perimeter; beta: incidence; psi: spin ratio; "
              "nu(beta, psi): the end's normal speed per unit metric speed).", "",
              "## The answer", "", answer_block(s, base=""), ""]
    lines += ["## 1. Elastic walls: the invariant measure (theorem)", "", *MEASURE_PROOF, "",
              "## 2. The elastic circle is integrable, hence not ergodic (theorem)", "", *CIRCLE_PROOF, ""]
    t = s["tables"]
    rows = [[name, f"{v['orbits']} ({v['stopped']} stopped early)",
             f"{v['chaotic']} ({v['chaotic_inv']} of {v['n_inv']} from the whole measure)",
             f"{v['ci'][0]:.2f} .. {v['ci'][1]:.2f}", f"{v['lam_median']:.4g}" if v["chaotic"] else "-",
             _span(v["lam_range"]), f"{v['regular_max']:.2e}",
             f"{v['drift_median']:.2f} / {v['drift_max']:.2f}" if v["chaotic"] else "-",
             f"{v['rel_se_median']:.3f} / {v['rel_se_max']:.3f}" if v["chaotic"] else "-",
             f"{v['converged']}/{v['chaotic']}" if v["chaotic"] else "-",
             f"{v['kac']:.4g}", f"{v['kac_z_max']:.1f}", v["kac_off"]] for name, v in t.items()]
    lines += ["## 3. Elastic walls: Lyapunov exponents over many impacts (computed)", "",
              f"{cfg['orbits']} orbits from the invariant measure and {cfg['orbits']} from its rolling-dominated part "
              f"(|sin psi| <= {ROLLING_SPIN:g}) per table, {cfg['impacts']} impacts each, exact tangent maps, QR after "
              "every impact (billiards.md, section 2). An orbit counts as chaotic-looking when its largest exponent "
              f"exceeds {CHAOS_FACTOR:g} times the circle's largest at the same number of impacts "
              f"({s['null']:.2e}: the integrable null level, falling like ln(n)/n). Not converged: the relative change of "
              "a chaotic-looking orbit's exponent between half the impacts and all of them (median / largest), its "
              "relative standard error by batch means (20 batches of the per-impact log-stretch; median / largest), and "
              f"the orbits whose exponent is within {100 * CONVERGED:.0f} % by both (2 standard errors and the change): "
              "the values of lambda1 are finite-time estimates (orbits of a mixed phase space stick near islands for "
              "long stretches), and only the classification chaotic-looking / regular-looking is claimed. Kac: each orbit's "
              "mean flight time against the invariant measure's (a large independent sample); an ergodic map gives every "
              "typical orbit the same mean, so orbits more than 4 standard errors off belong to different invariant "
              "sets.", "",
              *table(["table", "orbits", "chaotic-looking", "95 % interval of the share", "lambda1 median", "lambda1 range",
                      "largest regular-looking lambda1", "relative change n/2 -> n (median / max)",
                      "relative batch-means SE (median / max)", f"within {100 * CONVERGED:.0f} %",
                      "invariant mean flight [s]",
                      "max |z| of the orbits' mean flights", "orbits > 4 SE off"], rows), "",
              f"![running exponents]({names['convergence']})", "",
              "Running largest exponent per impact of every orbit (blue: drawn from the invariant measure, red: from its "
              f"rolling-dominated part); dotted: {CHAOS_FACTOR:g} times the circle's largest.", "",
              "## 4. Cross-check on a billiard with a published answer (computed)", "",
              "The same QR routine (boundary_map.qr_exponents) on the Sinai billiard's disk-to-disk map with its exact "
              "Jacobian (studies/point_billiard.py; the Jacobian is also checked against finite differences "
              "in tests/studies/test_billiards_answer.py), against P. Dahlqvist, *The Lyapunov exponent in the Sinai billiard in "
              "the small scatterer limit*, Nonlinearity 10 (1997) 159 (arXiv:chao-dyn/9601007): lambda = -2 ln rho + C + "
              f"O(rho ln^2 rho), C = 1 - 4 ln 2 + 27 zeta(3) / (2 pi^2) = {pb.DAHLQVIST_C:.5f}. "
              f"{cfg['sinai_orbits']} orbits of {cfg['sinai_impacts']} collisions per radius. The standard error is the "
              "larger of two estimates: between the orbits' exponents, and from batch means of the per-collision "
              "log-stretch pooled over every orbit (10 batches per orbit). At small rho the free flights are "
              "heavy-tailed (the stretch of a collision grows with the flight before it), so both estimates converge "
              "slowly and the error bar is itself uncertain: an independent code "
              "differed from an earlier run of this one by about 3 of its (8-orbit) standard errors at rho = 0.03 "
              "and 0.003. The difference column is therefore not a test at "
              "the scale of the SE; what is checked is the agreement within the formula's "
              "error term O(rho ln^2 rho).", "",
              *table(["rho", "computed lambda (mean +- SE)", "SE between orbits / from pooled batches",
                      "Dahlqvist -2 ln rho + C", "difference", "difference / SE", "rho ln^2 rho"],
                     [[x["rho"], f"{x['lam']:.4f} +- {x['se']:.4f}",
                       f"{x.get('se_between', x['se']):.4f} / {x.get('se_batches', x['se']):.4f}", f"{x['dahlqvist']:.4f}",
                       f"{x['lam'] - x['dahlqvist']:.4f}", f"{(x['lam'] - x['dahlqvist']) / x['se']:.1f}",
                       f"{x['rho'] * math.log(x['rho']) ** 2:.3f}"] for x in s["sinai"]]),
              "", f"![Sinai check]({names['sinai']})", ""]
    prow = []
    for tname, rows_ in res["periodic"].items():
        for r in rows_:
            ev = ", ".join(f"{complex(*e):.4g}" for e in r["eigenvalues"])
            prow.append([tname, r["period"], ", ".join(f"{v:.4f}" for v in r["z"]), r["type"], ev,
                         "-" if r["island"] is None else f"{r['island']:.3g}",
                         f"{r['rotation']:.4f} / {r['island_steps']} / {r['turns']:.1f}" if "turns" in r else
                         r.get("pieces", "-")])
    lines += ["## 5. Periodic orbits and their stability (computed)", "",
              f"Newton's method on F^p(z) = z (periods {', '.join(map(str, cfg['periods']))}) from {cfg['seeds']} seeds "
              "drawn from the invariant measure (and the axes' head-on bounces), in z = (s, beta, psi), one row per "
              "distinct orbit found (penny_env/analysis/periodic_orbits.py). The map is reversible and preserves a "
              "smooth measure, so its periodic orbits come in one-parameter families with an eigenvalue 1: hyperbolic "
              "(lambda, 1, 1/lambda), elliptic (e^{+-i a}, 1: a candidate island), parabolic (all 1). Island: the "
              "largest distance (in z) from the orbit of 6 orbits started 1e-3 from an elliptic one, followed for at "
              f"least {cfg['island_steps']} impacts and at least {ISLAND_TURNS} turns of the linearised rotation (the "
              f"argument a of the eigenvalue pair per period; at most {ISLAND_CAP} impacts): an island where it stays "
              f"below {ISLAND:g}, over the turns the last column states (most rotate 0.006 to 0.03 rad per period, so "
              "2000 impacts would be about one turn; KAM-type stability is not proved here). Parabolic (every eigenvalue 1): "
              "neutral families, not islands; the last column says which wall pieces a stadium orbit hits: one cap "
              "(the orbit rotated about the cap's centre is again periodic, as every orbit of the circle), the flat "
              "sides (translated along them, like the specular stadium's bouncing-ball orbits), or both. A search from "
              "finitely many seeds finds some orbits, not all.", "",
              *table(["table", "period", "z = (s, beta, psi)", "type", "eigenvalues of DF^p", "island: max distance",
                      "rotation a [rad/period] / impacts followed / turns, or the wall pieces hit"],
                     prow or [["-", "-", "-", "none found", "-", "-", "-"]]), ""]
    srow = [[k.split("|")[0], k.split("|")[1], v["points"], f"{v['median']:.3f}", f"{v['null_level']:.3f}",
             f"{v['regular_share']:.2f}"] for k, v in s["slices"].items()]
    lines += ["## 6. 2-D slices: islands or their absence (computed)", "",
              f"A grid of {cfg['slice_grid'][0]} x {cfg['slice_grid'][1]} points (s, beta) at fixed psi, each followed "
              f"{cfg['slice_impacts']} impacts with a companion orbit 1e-7 away renormalised after every impact: its "
              "finite-time exponent per impact. Regular share: the points at or below the circle's 99th percentile "
              "on the same slice (the integrable level at this length).", "",
              *table(["table", "psi", "points", "median FTLE", "circle's 99th percentile", "regular share"], srow), "",
              f"![slices]({names['slices']})", ""]
    frow = []
    for key, f in s["fate"].items():
        tname, law = key.split("|")
        frow.append([tname, law, f["orbits"],
                     f"{f['stops']['grazing']} / {f['stops']['clear']} / {f['stops']['wedged']} / {f['stops']['running']}",
                     " / ".join(f"{x:.0f}" for x in f["impacts_q"]), " / ".join(f"{x:.3f}" for x in f["kept_q"]),
                     f"{f['kept_vs_tangential']:.2e} / {f['kept_vs_tangential_median']:.2e}", f"{f['min_flight']:.3g}",
                     _loss_span(f.get("wedged_loss", [])), _span(f["lam"])])
    lines += ["## 7. Dissipative walls: contraction and the fate of orbits", "", *DISSIPATIVE_TEXT, "",
              *table(["table", "law", "orbits", "grazing / clear / wedged / still bouncing", "impacts 5 / 50 / 95 %",
                      "energy kept 5 / 50 / 95 %", "|kept - (1 - q0^2)|: max / median of the grazing orbits",
                      "shortest flight [s]", "wedged: energy lost per impact",
                      "finite-time lambda1 range"], frow), "",
              f"![fate]({names['fate']})", "",
              "## 8. Related work", "", *RELATED, ""]
    rep.write(lines)
    return names


MEASURE_PROOF = [
    "**Theorem.** Under the elastic law the boundary map preserves the measure |nu(beta, psi)| ds dbeta dpsi on each "
    "energy shell (s: arc length, beta: incidence, psi: spin ratio, nu: the end's normal speed per unit metric speed).",
    "",
    "*Proof.* (1) The flow between impacts preserves the volume dx dy dphi du dw of (x, y, phi, u, w), (u, w) the "
    "scaled speeds: x' = R theta_dot cos phi and y' = R theta_dot sin phi do not depend on x, y; phi' = phi_dot does not "
    "depend on phi; the speeds are constant; so the vector field has zero divergence (theta, cyclic, is left out). "
    "(2) Parametrise the impact section by (s, phi, u, w): the end sigma is on the wall at p(s), so (x, y) = p(s) - "
    "sigma R e(phi). The flux of the volume through the section is i_X(vol) restricted to it; with X = (R theta_dot e, "
    "phi_dot, 0, 0) and the section's tangent vectors d/ds = (t(s), 0, 0, 0), d/dphi = (sigma R (sin phi, -cos phi), 1, "
    "0, 0), d/du, d/dw, the determinant is that of (X - phi_dot d/dphi, d/ds) in the plane, i.e. of (the end's velocity "
    "p', t): the flux measure is |v_n| ds dphi du dw, v_n the end's normal speed. (3) A volume-preserving flow carries "
    "the flux measure of the post-impact section to that of the pre-impact section (flux tubes). (4) The elastic law "
    "keeps s and phi, maps (u, w) by a reflection (|det| = 1) and v_n to -v_n: it preserves |v_n| ds dphi du dw. (5) So "
    "the return map preserves it. On the energy shell (u, w) = rho (cos psi', sin psi'), du dw = rho drho dpsi, v_n = R "
    "rho nu(beta, psi) and, at fixed s, dphi = dbeta: the measure is R rho^2 |nu| ds dbeta dpsi drho, and conditioned on "
    "rho it is |nu| ds dbeta dpsi. QED. It is the analogue of Birkhoff's cos(theta) ds dtheta; it is not Lebesgue.",
    "",
    "**Theorem (general: any invariant density of the constrained flow).** Let a nonholonomic system with an impact "
    "surface S = {h = 0} in its configuration space Q have a flow between impacts (on the constraint distribution, in "
    "velocity coordinates v in which the kinetic metric restricted to it is Euclidean) that preserves a measure "
    "N(q) dq dv with a smooth positive density N depending on the configuration only. Then the elastic boundary map "
    "preserves N(q) |v_n| dsigma dv on the impact section (dsigma the volume of S, v_n the normal speed of the "
    "impacting point), and a restitution e, or the plastic law with e_eff = e(beta), multiplies it by e_eff^2 per "
    "impact. *Proof.* Steps (1) to (5) above with the volume replaced by N vol: (1) is the hypothesis; (2) the flux "
    "of N vol through the section is N i_X vol restricted to it, = N |v_n| dsigma dv by the same determinant; (3) a "
    "flow preserving N vol carries the flux of the post-impact section to that of the pre-impact section; (4) an "
    "impact keeps q, hence N, and acts on v by a reflection (|det| = 1, v_n -> -v_n) or a restitution (|det| = e, "
    "v_n -> -e v_n). QED. The penny is the case N = 1: its flow has zero divergence, and it has no other smooth "
    "invariant density of this form (X . grad N = R theta_dot (cos phi N_x + sin phi N_y) + phi_dot N_phi = 0 for "
    "all speeds forces grad N = 0), so the general statement matters for other nonholonomic billiards (systems whose "
    "constrained flow preserves a non-uniform density, such as Chaplygin's sleigh-type examples), not for this one.",
    "",
    "Checked: pointwise along orbits (ln|det| of the 3-D map + ln|nu after| - ln|nu before| = 0 to round-off) and by one "
    "map step of a large sample ([billiards.md](billiards.md), section 3; tests/analysis/test_billiards.py). For a restitution e "
    "the law scales v_n by -e and keeps the tangential part, |det| = e in (u, w): the flux measure is multiplied by "
    "e^2 per impact (the plastic law: e(beta)^2), the flow's volume too (billiards.md, section 3: det = e_eff^2).",
]

CIRCLE_PROOF = [
    "**Theorem.** On the circle under the elastic law the boundary map is integrable: |beta| and |nu| are invariant, "
    "(beta, psi) alternate between two values and s advances by a fixed step every two impacts. Hence it is **not "
    "ergodic**: |beta| is an invariant function that is not constant almost everywhere for the invariant measure (the "
    "sets {|beta| < c} have measures strictly between 0 and the total for 0 < c < pi/2), and an ergodic map has only "
    "constant invariant functions.",
    "",
    "*Proof.* Between impacts the contact point runs on a circle about a centre C and both ends on one circle G about "
    "C; G meets the wall at two points, mirror images across the line OC (O the table's centre), and every impact is at "
    "one of them. The penny just before impact B is the mirror image of the penny just after impact A with its "
    "velocities reversed, so in the wall's frame the state before B is K(state after A) with K: beta -> -beta, psi -> "
    "pi - psi, an isometry of the kinetic metric that takes the normal form at beta to minus the one at -beta. Every law "
    "here commutes with K, so the reduced map is F = Delta o K; Delta keeps beta, so |beta| is conserved; for elastic "
    "walls Delta is an involution, F o F = identity, and nu after B = nu after A (the full proof: billiards.md, "
    "section 1). QED. Along the 20,000-impact orbits of section 3 the circle's exponents fall like ln(n)/n: the null "
    "level.",
]

DISSIPATIVE_TEXT = [
    "**Theorem (contraction).** A restitution e (plastic: e_eff = e(beta)) multiplies the flow's volume and the "
    "boundary map's flux measure by e_eff^2 at every impact (section 1): there is no invariant measure with a density, "
    "and the orbits are attracted to lower-dimensional sets.",
    "",
    "**Theorem (the circle's fate).** On the circle, under a restitution e < 1 or the plastic law, the part of the "
    "scaled velocity along the impact normal shrinks by e (plastic: e(beta), beta being conserved) at every impact "
    "and the tangential part is kept: after impact A the state before the next impact B is K(state after A) (section 2), "
    "K an isometry mapping the normal direction at beta to minus the one at -beta, so the normal and tangential parts "
    "pass from A to B unchanged, and the law scales the normal part by -e. So |v_n| = e^k |v_n(0)| after k impacts, "
    "every orbit tends to grazing (the ends' circle touching the wall), and the energy kept tends to the tangential "
    "share 1 - q0^2, q0 = |v . n| / |v| at the start. QED. The limit set is the grazing set: on it the penny circles, "
    "touching the wall without an impact (a periodic motion: exponent 0), so the attractor is not chaotic. The column "
    "'max |kept - (1 - q0^2)|' checks the energy law on the circle's orbits; on the ellipse and the stadium it "
    "measures how far their fate departs from the circle's.",
    "",
    "**Computed (the other tables).** Orbits from the invariant measure (speeds rescaled after each impact, an exact "
    "symmetry), followed until they stop: grazing (an impact whose normal speed is below 1e-6 of the end's speed: the "
    "map has no derivative there), clear (no impact within 1000 s: the ends' circle clear of the wall), or still "
    "bouncing at the last impact followed, or wedged: the penny lies as a chord of the wall with both ends on it, and "
    "its ends hit alternately with flights below 1e-12 s (at least 10 in a row at the end). This is a real Zeno "
    "accumulation of the **sequential single-impact model** (the paper's law applied to one end at a time), not an "
    "artefact: an independent replay reproduced such an orbit's impact sequence to 4 "
    "digits for 25 impacts, front and back alternating, the gaps shrinking by about e each time; here "
    "tests/studies/test_billiards_answer.py checks a wedged orbit's flights, both ends on the wall and its speed "
    "falling at every impact. But each impact removes only a small share of the "
    "energy (the column 'wedged: energy lost per impact' gives the median over each wedged orbit's last 10 impacts), "
    "so 'the penny comes to rest' would extrapolate over infinitely many impacts and is not claimed; its 'energy kept' "
    "is that after the impacts followed. A configuration with both ends on the wall is outside the paper's single-"
    "impact theory: a two-contact impact law would be needed to say what happens. No orbit is discarded. The shortest "
    "flight over the last 20 impacts of every orbit is in the table (0: wedged). The "
    "finite-time exponents over the impacts before grazing are transients: the map's derivative grows without bound "
    "near grazing (like 1/|v_n|), which is why the provably non-chaotic circle shows positive ones too.",
]

RELATED = [
    "* **Borisov, Kilin and Mamaev**, *On the model of non-holonomic billiard*, Regular and Chaotic Dynamics 16 (2011) "
    "653-662: a rolling (nonholonomic) ball bouncing inside a billiard, its intrinsic rotation kept; the billiard "
    "between parallel walls and in a circle are worked out (as the penny's circle here, integrable), and with a "
    "three-dimensional point map they show that the nonholonomic billiard in an ellipse is not integrable. The "
    "penny's boundary map is also a three-dimensional point map; its ellipse shows positive exponents on part of "
    "phase space and elliptic periodic orbits with islands: mixed, neither integrable nor (in evidence) ergodic.",
    "* **Broomhead and Gutkin**, *The dynamics of billiards with no-slip collisions*, Physica D 67 (1993) 188-197: a "
    "rough disk that exchanges linear and angular momentum at the wall with energy kept (the only conservative "
    "alternative to the specular law in two dimensions); bounded orbits in strips. **Cox and Feres**, *No-slip billiards "
    "in dimension two* (arXiv:1602.01490): periodicity and boundedness results suggesting that a class of no-slip "
    "billiards (polygons included) is not ergodic, phase portraits with non-ergodic features; **Cox, Feres and Zhang**, "
    "*Stability of periodic orbits in no-slip billiards*, Nonlinearity 31 (2018) (arXiv:1612.03355): elliptic period-2 "
    "orbits whenever a corner is below pi, polygonal no-slip billiards not ergodic, linearly stable period-2 orbits in "
    "the no-slip Sinai billiard. The penny's elastic law is of the same kind (energy kept, rolling and spin exchanged at "
    "the wall, a reversible map on a three-dimensional energy shell preserving a smooth measure), and shows the same "
    "picture: elliptic periodic orbits and islands next to chaotic orbits, rather than the specular billiards' "
    "ergodicity on the stadium. Wojtkowski (*The system of two spinning disks in the torus*, 1994) reduced no-slip disks "
    "to a three-dimensional measure-preserving reversible map with elliptic periodic orbits, the same structure.",
    "* Specular billiards on the same tables, for contrast: the circle and the ellipse are integrable; Bunimovich's "
    "stadium is ergodic, mixing and Bernoulli. The penny's circle stays integrable; its ellipse is not integrable "
    "(positive exponents); its stadium is not (in evidence) ergodic.",
]


def main(argv=None):
    from lab.common import report_command

    rep = report_command("studies.billiards_answer", "billiards_answer.md", __doc__, argv, docs_default=True,
                         quick="few short orbits (for the tests)")
    cfg = CONFIGS["quick" if rep.quick else "full"]
    out = rep.out
    params = PennyParams()
    rho = float(bm.metric_speed(PAPER_STATE, params))
    t0 = time.perf_counter()
    res = run(cfg, params, rho)
    s = summarise(res, cfg)
    seconds = time.perf_counter() - t0
    write_report(rep, res, s, cfg, seconds)
    rep.beside(".json").write_text(json.dumps(s, indent=1, default=float))
    if not rep.quick and out == (ROOT / "docs" / "billiards_answer.md").resolve():
        for path, base in ((ROOT / "README.md", "docs/"), (ROOT / "docs" / "billiards.md", "")):
            if rep.readme(path, README_BEGIN, README_END, answer_block(s, base)):
                print(f"{path.name}: the question-2 answer updated")
    return out, s


if __name__ == "__main__":
    main()
