"""Work-precision report: error against the 50-digit reference vs run time, for several methods.

    python -m studies.work_precision [--quick] [--out docs/work_precision.md]

Scenes: the paper's four, the stadium scene and the controlled scene (extra_scenes.json); with
--all-scenes also the restitution scene. Per scene, each method computes the reference's impacts
(25 for the paper's scenes) and the state at the reference's fixed time; measured: max impact-time
error over matched impacts, missed / spurious impacts, max abs error of the state at the fixed time,
and the wall time (best of repeats for fast runs).

Methods: penny_env.simulate (default settings, and a sweep of SolverSettings.contact_tol); the
environment's step path (penny_env.physics.advance_pennies over control intervals of 0.05 s, batch of one);
scipy solve_ivp RK45 and DOP853 with rtol 1e-4 ... 1e-12 (atol = 1e-3 rtol (L, L, 1, 1, 1, 1));
fixed-step RK4 with a linear event locator at several step sizes. The diagram (log-log, error vs
run time, one line per method, one panel per scene) goes next to the Markdown file as
work_precision.png (impact times) and work_precision_state.png (state at the fixed time).
"""
from __future__ import annotations

import time

import numpy as np

from lab import common
from studies.integrators import rk4_hybrid, run_simulate, run_step_path, solve_ivp_hybrid
from studies.matching import match_impacts, state_error, unresolvable_mask
from studies.reference import extra_scenes, paper_scenes
from penny_env.physics import SolverSettings

DEFAULT_SCENES = ("circle_elastic", "circle_plastic", "ellipse_elastic", "ellipse_plastic", "stadium_elastic",
                  "ellipse_elastic_controlled")


def methods(quick: bool):
    """(method label, setting label, runner, extra kwargs)."""
    rtols = [1e-4, 1e-8, 1e-12] if quick else [1e-4, 1e-6, 1e-8, 1e-10, 1e-12]
    dts = [1e-2, 1e-3] if quick else [1e-2, 3e-3, 1e-3, 3e-4, 1e-4]
    tols = [1e-12, 1e-9] if quick else [1e-13, 1e-11, 1e-9, 1e-7]
    out = [("penny_env simulate", "default", run_simulate, {})]
    for ct in tols:
        out.append(("penny_env contact_tol sweep", f"contact_tol={ct:g}", run_simulate,
                    {"settings": SolverSettings(contact_tol=ct)}))
    out.append(("env step path (advance, 0.05 s)", "default", run_step_path, {"env_dt": 0.05}))
    try:
        from penny_env.physics import scalar  # noqa: F401
        out.append(("env step path (scalar advance_interval, 0.05 s)", "default", run_step_path,
                    {"env_dt": 0.05, "scalar": True}))
    except ImportError:  # pragma: no cover - older physics without the plain-float path
        pass
    for m in ("RK45", "DOP853"):
        for r in rtols:
            out.append((f"solve_ivp {m}", f"rtol={r:g}", solve_ivp_hybrid, {"method": m, "rtol": r}))
    for dt in dts:
        out.append(("RK4 + linear locator", f"dt={dt:g}", rk4_hybrid, {"dt": dt}))
    return out


def scenes(all_scenes: bool = False):
    sc = paper_scenes() + extra_scenes()
    return sc if all_scenes else [s for s in sc if s.name in DEFAULT_SCENES]


def run_one(sc, runner, kw, budget: float, min_time: float, unres=None):
    n = sc.n_impacts
    if sc.controls is not None:
        t_stop = sc.controls.shape[0] * sc.control_dt
        n_imp = None
    else:
        t_stop = 1.5 * float(sc.impact_times[-1]) + 1.0
        n_imp = n
    args = dict(params=sc.params, table=sc.table, law=sc.law, n_impacts=n_imp, t_stop=max(t_stop, sc.t_final),
                t_sample=sc.t_final, controls=sc.controls, control_dt=sc.control_dt, wall_budget=budget)
    try:
        wall, res = common.best_time(lambda: runner(sc.initial_state, **args, **kw), repeats=1,
                                     min_total=min_time, warmup=False)
    except Exception as exc:  # reported, not hidden
        return dict(time=float("nan"), err=float("nan"), serr=float("nan"), match=None, status=f"error: {exc!r}")
    m = match_impacts(sc.impact_times, sc.impact_ends, res.impact_times, res.impact_ends, t_end=res.final_time,
                      unresolvable=unres)
    return dict(time=wall, err=m.max_abs_err, serr=state_error(res.state_at_sample, sc.state_at_t_final), match=m,
                status=res.status, n_steps=res.n_steps, n_impacts=res.n_impacts)


def run(quick=False, all_scenes=False, budget=None):
    import scipy.integrate  # noqa: F401  (import outside the timings)
    budget = budget or (20.0 if quick else 60.0)
    min_time = 0.05 if quick else 0.3
    ms = methods(quick)
    scs = scenes(all_scenes)
    results = []
    jobs = [(sc, m) for sc in scs for m in ms]
    unres = {sc.name: unresolvable_mask(sc) for sc in scs}
    for sc, (label, setting, runner, kw) in common.progress(jobs, desc="work-precision runs"):
        r = run_one(sc, runner, kw, budget, min_time, unres[sc.name])
        r.update(scene=sc.name, method=label, setting=setting)
        results.append(r)
    return scs, results


def plot(scs, results, path_imp, path_state):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    labels = list(dict.fromkeys(r["method"] for r in results))
    colors = {lab: plt.cm.tab10(i % 10) for i, lab in enumerate(labels)}
    markers = dict(zip(labels, "os^vDP*Xh"))
    for path, key, ylab in ((path_imp, "err", "max impact-time error [s]"),
                            (path_state, "serr", "max state error at the fixed time [m, rad, rad/s]")):
        ncol = 3
        nrow = (len(scs) + ncol - 1) // ncol
        fig, axes = plt.subplots(nrow, ncol, figsize=(5.2 * ncol, 4.2 * nrow), squeeze=False)
        for ax, sc in zip(axes.flat, scs):
            for i, lab in enumerate(labels):
                z = 3 + len(labels) - i  # earlier methods on top: penny_env simulate is not hidden by its own sweep
                rs = [r for r in results if r["scene"] == sc.name and r["method"] == lab and np.isfinite(r["time"])]
                if not rs:
                    continue
                x = np.array([r["time"] for r in rs])
                y = np.array([r[key] for r in rs], dtype=float)
                bad = np.array([r["match"] is None or r["match"].missed_resolvable + r["match"].spurious > 0 for r in rs])
                y = np.where(np.isfinite(y), np.maximum(y, 1e-17), np.nan)
                good = np.flatnonzero(~bad)
                order = good[np.argsort(x[good])]  # lines join only the runs without missed/spurious impacts
                ax.plot(x[order], y[order], "-", color=colors[lab], alpha=0.7, zorder=z)
                ax.scatter(x[~bad], y[~bad], marker=markers[lab], color=colors[lab], s=30, zorder=z,
                           edgecolors="white", linewidths=0.4)
                ax.scatter(x[bad], y[bad], marker=markers[lab], facecolors="none", edgecolors=colors[lab], s=60, zorder=z)
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_title(sc.name)
            ax.set_xlabel("run time [s]")
            ax.set_ylabel(ylab)
            ax.grid(True, which="major", alpha=0.3)
        for ax in list(axes.flat)[len(scs):]:
            ax.axis("off")
        # one entry per method with its marker shape and colour (a line joins its settings where none missed)
        handles = [Line2D([], [], color=colors[lab], marker=markers[lab], markersize=7, label=lab) for lab in labels]
        handles.append(Line2D([], [], color="0.4", marker="o", markerfacecolor="none", ls="none", markersize=8,
                              label="hollow: missed or spurious impacts"))
        fig.legend(handles=handles, loc="lower center", ncol=4, fontsize=9)
        fig.suptitle(f"Work-precision: {ylab} vs run time (hollow, unjoined markers: runs with missed or spurious impacts)")
        fig.tight_layout(rect=(0, 0.09, 1, 0.96))
        fig.savefig(path, dpi=110)
        plt.close(fig)


def report(scs, results, argv, png_names) -> list[str]:
    L = common.header("Work-precision of penny_env and baseline integrators", "studies.work_precision", argv)
    L += ["Errors are against the 50-digit mpmath reference (studies/reference_data). "
          "Impact-time error: max |t - t_ref| "
          "over the impacts matched by time and end (order-preserving alignment, studies.matching); "
          "missed / spurious impacts are counted separately (a method that misses a grazing impact and loses the "
          "trajectory shows a small error on the few impacts it still matches but many missed ones). "
          "State error: max abs difference of (x, y, theta, phi, theta_dot, phi_dot) at the scene's fixed time "
          "(5 s for the paper's scenes, 3 s stadium, 2 s controlled). Wall time: one run, or the best of several "
          "when a run is short. All other integrators apply penny_env's impact law at their events. Missed impacts in "
          "brackets are below float64 resolution (the end would pass the wall by less than contact_tol x table size "
          "without the impact; see bench_solvers.md); hollow markers in the plots: missed resolvable or spurious "
          "impacts. Note that after a missed impact a method follows a different trajectory, so its error on the "
          "impacts it still matches is not comparable with that of a method that found them all.", "",
          f"![work-precision, impact times]({png_names[0]})", "",
          f"![work-precision, state at the fixed time]({png_names[1]})", ""]
    # summary: per method/setting, worst over scenes
    L += ["## Summary over the scenes", "",
          "Worst error over the scenes, total time, and total missed / spurious impacts.", ""]
    keys = list(dict.fromkeys((r["method"], r["setting"]) for r in results))
    rows = []
    for k in keys:
        rs = [r for r in results if (r["method"], r["setting"]) == k]
        tot = sum(r["time"] for r in rs)
        err = np.nanmax([r["err"] for r in rs]) if any(np.isfinite(r["err"]) for r in rs) else float("nan")
        serr = np.nanmax([r["serr"] for r in rs]) if any(np.isfinite(r["serr"]) for r in rs) else float("nan")
        missed = sum(r["match"].missed for r in rs if r["match"])
        unr = sum(r["match"].missed_unresolvable for r in rs if r["match"])
        spur = sum(r["match"].spurious for r in rs if r["match"])
        nref = sum(r["match"].n_ref for r in rs if r["match"])
        st = sorted({r["status"] for r in rs if r["status"] != "ok"})
        rows.append([k[0], k[1], common.fmt(tot, 3), common.fmt(err), common.fmt(serr),
                     f"{missed}/{nref}" + (f" ({unr})" if unr else ""), spur,
                     ", ".join(st) or "ok"])
    L += common.table(["method", "setting", "total time [s]", "worst impact-time err [s]", "worst state err",
                       "missed / reference impacts", "spurious", "status"], rows)
    for sc in scs:
        L += ["", f"## {sc.name}", "",
              f"{sc.n_impacts} reference impacts, table {sc.table!r}, law {sc.law}, "
              f"state compared at t = {sc.t_final:g} s" + (", piecewise-constant controls" if sc.controls is not None else "")
              + ".", ""]
        rows = []
        for r in results:
            if r["scene"] != sc.name:
                continue
            m = r["match"]
            rows.append([r["method"], r["setting"], common.fmt(1e3 * r["time"], 3), common.fmt(r["err"]),
                         (f"{m.matched}/{m.missed}" + (f" ({m.missed_unresolvable})" if m.missed_unresolvable else "")
                          + f"/{m.spurious}") if m else "-", common.fmt(r["serr"]), r["status"]])
        L += common.table(["method", "setting", "time [ms]", "impact-time err [s]", "found/missed/spurious",
                           "state err", "status"], rows)
    return L


def main(argv=None):
    rep = common.report_command("studies.work_precision", "work_precision.md", "work-precision report of penny_env "
                                "and other integrators", argv, quick="fewer settings, shorter budgets",
                                options=lambda ap: ap.add_argument("--all-scenes", action="store_true",
                                                                   help="also the restitution scene"))
    args = rep.args
    t0 = time.perf_counter()
    scs, results = run(quick=args.quick, all_scenes=args.all_scenes)
    for r in results:
        m = r["match"]
        print(f"{r['scene']:27s} {r['method']:32s} {r['setting']:18s} {1e3 * r['time']:10.2f} ms  "
              f"err {r['err']:.2e}  {m.summary() if m else '-'}  state err {r['serr']:.2e}  {r['status']}")
    pngs = (rep.beside(".png"), rep.beside("_state.png"))  # (written first: the report names them)
    plot(scs, results, *(str(p) for p in pngs))
    rep.write(report(scs, results, rep.argv, [p.name for p in pngs]))
    print(f"total {time.perf_counter() - t0:.1f} s")
    return scs, results


if __name__ == "__main__":
    main()
