"""The study's report from the jobs' result files: per (cell, agent) statistics with 95 %
intervals, learning curves with bands (PNG), and the proven facts kept apart from the observations.
The answer to "which actuations and walls make the penny controllable" is not computed here: it is
the verdict table of studies/witness_study.py (theorems and certified witnesses, docs/witnesses.md);
the RL rates of this report appear beside it as learnability.

Interval method (success rates): clustered by seed, :func:`seed_clustered_ci` (a t interval over the
seed means, widened to the pooled exact Clopper-Pearson interval so that it is honest at 0 and at 1).
Learning-curve bands: percentile bootstrap over seeds.
"""
from __future__ import annotations

import csv
import json
import os
from collections import defaultdict
from pathlib import Path

import numpy as np

from studies.stats import seed_clustered_ci

B = 2000
PROBES = {"Steer": "steer only, park", "Drive": "drive only, reach off the heading line", "Both": "both controls, park"}
ROW_FIELDS = ["probe", "table", "cell", "agent", "seeds", "episodes", "success", "ci_low", "ci_high",
              "mean_time_s", "impact_share", "impacts_per_success", "curve_last_change", "curve_last"]


def job_dir(runs, job) -> Path:
    """RUNS/<cell>/<agent>/seed<k>: a job's folder."""
    return Path(runs) / job["cell"] / job["agent"] / f"seed{job['seed']}"


def split_cell(cell: str) -> tuple[str, str]:
    """('Steer', 'Ellipse-Plastic') from 'PennyProbeSteer-Ellipse-Plastic-v0' (other ids: ('-', id))."""
    if cell.startswith("PennyProbe") and cell.endswith("-v0"):
        probe, table = cell[len("PennyProbe"):-3].split("-", 1)
        return probe, table
    return "-", cell


def load_results(jobs, runs) -> dict:
    groups = defaultdict(list)
    for job in jobs:
        path = job_dir(runs, job) / "result.json"
        if not path.is_file():
            raise ValueError(f"missing job result {path} (rerun the study to finish it)")
        groups[(job["cell"], job["agent"])].append(json.loads(path.read_text()))
    return groups


def last_quarter_change(curve) -> float:
    """The rise of a learning curve [[timesteps, success], ...] over the last quarter of training: its
    last point minus the curve (linearly interpolated) at 3/4 of the last point's timesteps."""
    t, y = np.asarray(curve, float).T
    return float(y[-1] - np.interp(0.75 * t[-1], t, y))


def cell_rows(groups) -> list[dict]:
    rows = []
    for (cell, agent), results in groups.items():
        results = sorted(results, key=lambda r: r["job"]["seed"])
        succ = np.array([r["episodes"]["success"] for r in results], float)
        time_ = np.array([r["episodes"]["time"] for r in results], float)
        imp = np.array([r["episodes"]["impacts"] for r in results], float)
        ok = succ > 0
        lo, hi = seed_clustered_ci(succ)
        probe, table = split_cell(cell)
        change = last = ""
        curves = [r["curve"] for r in results if r["curve"]]
        if curves and all(len(c) >= 2 for c in curves):
            change = float(np.mean([last_quarter_change(c) for c in curves]))
            last = float(np.mean([c[-1][1] for c in curves]))
        rows.append({
            "probe": probe, "table": table, "cell": cell, "agent": agent, "seeds": len(results),
            "episodes": int(succ.size), "success": float(succ.mean()), "ci_low": lo, "ci_high": hi,
            "mean_time_s": float(time_[ok].mean()) if ok.any() else "",
            "impact_share": float((imp[ok] > 0).mean()) if ok.any() else "",
            "impacts_per_success": float(imp[ok].mean()) if ok.any() else "",
            "curve_last_change": change, "curve_last": last})
    rows.sort(key=lambda r: (r["probe"], r["table"] != "Plane", r["table"], r["agent"]))
    return rows


def paired_times(groups, probe: str = "Both") -> list[dict]:
    """Table vs plane on the same start/target pairs: a seed draws the same uniforms in every cell
    (docs/study_probes.md), so evaluation episode j of job seed k is the same pair, scaled to each
    table, in every cell of a probe. Per (table, agent): the pairs that both the table cell and the
    plane cell solved, the mean time difference table - plane with its 95 % percentile bootstrap
    interval over those pairs, and the share of them where the table was faster."""
    plane = {a: {r["job"]["seed"]: r["episodes"] for r in res}
             for (c, a), res in groups.items() if split_cell(c) == (probe, "Plane")}
    out = []
    for (cell, agent), results in sorted(groups.items()):
        pr, table = split_cell(cell)
        if pr != probe or table == "Plane" or agent not in plane:
            continue
        diffs = []
        for r in results:
            ref = plane[agent].get(r["job"]["seed"])
            if ref is None:
                continue
            ep = r["episodes"]
            for j in range(min(len(ep["success"]), len(ref["success"]))):
                if ep["success"][j] and ref["success"][j]:
                    diffs.append(ep["time"][j] - ref["time"][j])
        d = np.array(diffs, float)
        row = {"table": table, "agent": agent, "pairs": int(d.size), "mean_diff_s": float("nan"),
               "ci_low": float("nan"), "ci_high": float("nan"), "table_faster": float("nan")}
        if d.size:
            rng = np.random.default_rng(0)
            means = d[rng.integers(0, d.size, (B, d.size))].mean(axis=1)
            lo, hi = np.percentile(means, [2.5, 97.5])
            row.update(mean_diff_s=float(d.mean()), ci_low=float(lo), ci_high=float(hi),
                       table_faster=float((d < 0).mean()))
        out.append(row)
    return out


FLAT = 0.05  # a learning curve has flattened when its success rate rose by less than this over the last quarter,
# or when it ends within FLAT of success 1 (no room left to rise)


def flattening(rows: list[dict]) -> tuple[list[str], list[dict]]:
    """(solved cells, their PPO/SAC rows whose curve has not flattened). A cell is solved when its best
    trained agent's 95 % interval lies above 0; a curve has flattened when its "last change" (the mean
    over seeds of the success rate's rise over the last quarter of training) is below FLAT, or when its
    last point (mean over seeds) is above 1 - FLAT."""
    rl = [r for r in rows if r["agent"] in ("ppo", "sac") and r["curve_last_change"] != ""]
    solved = sorted({r["cell"] for r in rl if r["ci_low"] > 0})
    rising = [r for r in rl if r["cell"] in solved and r["curve_last_change"] >= FLAT and r["curve_last"] <= 1 - FLAT]
    return solved, rising


def _num(v):
    """A CSV cell as a float where it is one (the rows read back from study.csv are strings)."""
    if isinstance(v, str):
        try:
            return float(v)
        except ValueError:
            return v
    return v


def plot_curves(groups, path: Path, probe: str) -> bool:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import EngFormatter, MaxNLocator
    cells = sorted({c for (c, a) in groups if split_cell(c)[0] == probe and a in ("ppo", "sac")},
                   key=lambda c: (split_cell(c)[1] != "Plane", c))
    if not cells:
        return False
    n = len(cells)
    cols = min(4, n)
    rows = (n + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 2.6 * rows), squeeze=False, sharey=True)
    rng = np.random.default_rng(0)
    for ax, cell in zip(axes.flat, cells):
        for agent, color in (("ppo", "C0"), ("sac", "C1")):
            res = groups.get((cell, agent))
            if not res:
                continue
            k = min(len(r["curve"]) for r in res)
            if k == 0:
                continue
            x = np.array([r["curve"][:k] for r in res])  # seeds x points x (t, success)
            t, y = x[0, :, 0], x[:, :, 1]
            boot = y[rng.integers(0, len(y), (B, len(y)))].mean(axis=1)
            lo, hi = np.percentile(boot, [2.5, 97.5], axis=0)
            ax.plot(t, y.mean(0), color=color, label=agent.upper())
            ax.fill_between(t, lo, hi, color=color, alpha=0.25)
        ax.set_title(split_cell(cell)[1], fontsize=9)
        ax.set_ylim(-0.02, 1.02)
        ax.set_xlabel("env steps", fontsize=8)
        ax.xaxis.set_major_locator(MaxNLocator(4))
        ax.xaxis.set_major_formatter(EngFormatter(sep=""))  # 400k, 1M: readable at this size
        ax.tick_params(labelsize=7)
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    axes[0, 0].set_ylabel("eval success rate")
    axes[0, 0].legend(fontsize=7)
    fig.suptitle(f"{probe}: {PROBES.get(probe, probe)} (mean over seeds, 95 % bootstrap band)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return True


def _fmt(v, spec=".2f"):
    return format(v, spec) if isinstance(v, float) else str(v)


def jobs_span(jobs, runs, groups):
    """(first start, last end, seconds) of the jobs, from their result.json's modification times
    minus their durations: the wall time of the study across invocations (a rerun skips finished jobs)."""
    import datetime as dt
    ends, starts = [], []
    by_key = {(r["job"]["cell"], r["job"]["agent"], r["job"]["seed"]): r for res in groups.values() for r in res}
    for job in jobs:
        end = (job_dir(runs, job) / "result.json").stat().st_mtime
        ends.append(end)
        starts.append(end - by_key[(job["cell"], job["agent"], job["seed"])]["seconds"])
    fmt = lambda t: dt.datetime.fromtimestamp(t, dt.timezone.utc).strftime("%Y-%m-%d %H:%M")  # noqa: E731
    return fmt(min(starts)), fmt(max(ends)), max(ends) - min(starts)


def write_report(cfg, jobs, runs, out, argv=(), seconds=0.0):
    from studies.common import header
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    groups = load_results(jobs, runs)
    rows = cell_rows(groups)
    with open(out.with_suffix(".csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=ROW_FIELDS)
        w.writeheader()
        w.writerows(rows)
    job_seconds = sum(r["seconds"] for res in groups.values() for r in res)
    cpu_seconds = sum(r.get("cpu_seconds", 0.0) for res in groups.values() for r in res)
    lines = header("Does controllability of the penny need impacts? (RL study)", "studies.study", list(argv))
    span = jobs_span(jobs, runs, groups)
    cores = os.cpu_count() or 1
    lines += [f"Jobs: {len(jobs)} ((cell, agent, seed)); job time {job_seconds:.0f} s in all ({cpu_seconds:.0f} s CPU, "
              f"{cpu_seconds / cores / 60:.0f} min on this machine's {cores} cores if nothing else runs); "
              f"the jobs ran from {span[0]} to {span[1]} UTC ({span[2] / 60:.0f} min, from their result files); wall "
              f"time of this invocation {seconds:.0f} s (finished jobs are not rerun). Seeds {cfg['seeds']}; "
              f"{cfg['eval_episodes']} evaluation episodes per job; "
              f"budgets {cfg['timesteps']} env steps"
              + (f", per probe {cfg['timesteps_per_probe']}" if cfg.get("timesteps_per_probe") else "")
              + ". Probe tasks: [study_probes.md](study_probes.md).", ""]
    lines += ["## Proven (not observed)", "",
              "- On the open plane with u2 = 0 (steer only), (I + m R^2) theta'' = 0: theta_dot is conserved, so the "
              "steer probe's start (|R theta_dot| >= 0.03 m/s > the 0.01 m/s speed tolerance) can never come to rest.",
              "- On the open plane with u1 = 0 (drive only), J phi'' = 0: from phi_dot = 0 the heading never turns and "
              "the contact point stays on its initial heading line; the drive probe's targets lie >= 3 cm off it "
              "(tolerance 1.5 cm), so they are unreachable.",
              "- Both hold between impacts on any table; only an impact can change theta_dot (steer) or phi_dot (drive).",
              "- With both controls the plane is controllable (the feedback controller below is one witness).", ""]
    lines += ["## Which actuations and walls make the penny controllable", "",
              "Not decided from these success rates: the verdict per (actuation, law, table) comes from the "
              "theorems ([controllability_theory.md](controllability_theory.md)) and certified witness episodes "
              "([witnesses.md](witnesses.md), `python -m studies.witness_study`), with the agents below reported "
              "beside it as learnability."]
    lines += ["", "Impacts in the successes of the trained agents (PPO, SAC) on tables, and time to success on "
              "the plane vs the tables (computed from the rows below):", ""]
    for probe in PROBES:
        rl = [r for r in rows if r["probe"] == probe and r["agent"] in ("ppo", "sac") and r["success"] > 0]
        wall = [r for r in rl if r["table"] != "Plane"]
        n_succ = sum(r["success"] * r["episodes"] for r in wall)
        n_imp = sum(r["success"] * r["episodes"] * r["impact_share"] for r in wall)
        plane_t = [r["mean_time_s"] for r in rl if r["table"] == "Plane"]
        wall_t = [r["mean_time_s"] for r in wall]
        if rl:
            lines.append(f"- {probe}: {n_imp:.0f} of {n_succ:.0f} successful table episodes used an impact; mean time to "
                         f"success {np.mean(plane_t):.2f} s on the plane" if plane_t else
                         f"- {probe}: {n_imp:.0f} of {n_succ:.0f} successful table episodes used an impact; no success "
                         f"on the plane")
            if wall_t:
                lines[-1] += f", {min(wall_t):.2f} to {max(wall_t):.2f} s on the tables (per cell and agent)"
    paired = paired_times(groups, "Both")
    if paired:
        lines += ["", "Both controls, table vs plane on the same start/target pairs (episode j of job seed k is the "
                  "same draw in every cell): pairs that both cells solved, mean time to success on the table minus "
                  "on the plane with its 95 % bootstrap interval (over pairs; negative: the table is faster), and the "
                  "share of those pairs where the table was faster.", "",
                  "| table | agent | pairs solved in both | time table - plane (s) [95 % CI] | table faster |",
                  "| --- | --- | ---: | --- | ---: |"]
        for r in paired:
            diff = (f"{r['mean_diff_s']:+.2f} [{r['ci_low']:+.2f}, {r['ci_high']:+.2f}]" if r["pairs"] else "-")
            share = f"{r['table_faster']:.2f}" if r["pairs"] else "-"
            lines.append(f"| {r['table']} | {r['agent']} | {r['pairs']} | {diff} | {share} |")
    solved, rising = flattening(rows)
    n_curves = sum(1 for r in rows if r["cell"] in solved and r["agent"] in ("ppo", "sac"))
    lines += ["", "## Have the learning curves flattened?", "",
              f"Rule: a cell is solved when its best trained agent's interval lies above 0; a curve has flattened "
              f"when its \"last change\" (below) is under {FLAT:+.2f} or its last point (mean over seeds) is above "
              f"{1 - FLAT:.2f}, where it has no room left to rise. Solved cells: {len(solved)}; "
              f"{n_curves - len(rising)} of their {n_curves} PPO/SAC curves have flattened"
              + (", all of them." if not rising else ". Still rising: " + "; ".join(
                  f"{r['probe']} {r['table']} {r['agent']} {r['curve_last_change']:+.2f}" for r in rising) + ".")]
    lines += ["", "## Observed, per cell", "",
              "success: evaluation success rate (deterministic policies for PPO/SAC) with its 95 % interval "
              "clustered by seed (t interval over the seed means, widened to the pooled exact Clopper-Pearson "
              "interval: honest at 0 and at 1). time: mean time to success [s]. impact "
              "share: share of successful episodes with at least one impact. impacts/success: mean impacts in a "
              "successful episode. last change: mean change of the eval success rate over the last quarter "
              "of the learning curve (last point minus the curve, linearly interpolated, at 3/4 of training; near 0: "
              "flattened).", "",
              "| probe | table | agent | success [95 % CI] | time [s] | impact share | impacts/success | last change |",
              "| --- | --- | --- | --- | ---: | ---: | ---: | ---: |"]
    for r in rows:
        lines.append(f"| {r['probe']} | {r['table']} | {r['agent']} | {r['success']:.2f} [{r['ci_low']:.2f}, "
                     f"{r['ci_high']:.2f}] | {_fmt(r['mean_time_s'])} | {_fmt(r['impact_share'])} | "
                     f"{_fmt(r['impacts_per_success'], '.1f')} | {_fmt(r['curve_last_change'], '+.2f')} |")
    lines += ["", "## Learning curves", ""]
    for probe in PROBES:
        png = out.with_name(f"{out.stem}_curves_{probe.lower()}.png")
        if plot_curves(groups, png, probe):
            lines.append(f"![{probe}]({png.name})")
    lines.append("")
    out.write_text("\n".join(lines))
    return rows
