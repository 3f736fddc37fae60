"""Does the optimal penny need impacts? Trajectory optimisation with exact derivatives through impacts.

    python -m studies.optimal_control [--quick] [--pairs 50] [--single-input-pairs 10] [--cross-check-pairs 10]
                                       [--workers 16] [--out docs/optimal_control_central.md] [--runs runs/optimal_control]
                                       [--report-only | --cross-check-only]

The central study (docs/optimal_control_central.md): slow starts and central targets, where impacts gave
no gain; studies/impact_oc.py (docs/optimal_control.md) reuses these problems and solvers on pairs where
impacts can pay. For start/target pairs drawn as the environments draw them (penny_env/presets: the paper's ellipse and
the stadium, reach and park tasks), each problem is solved twice:

* **impacts allowed**: the real table; the final state and its derivatives come from
  ``penny_env.simulate(..., sensitivities=True)`` (saltation matrices through every impact);
* **impacts forbidden**: both ends kept at least ``margin`` off the wall at every sample time (row ends
  and ``studies.shooting.SUBSAMPLES`` points inside each control row; the flow and its derivatives are
  exact, physics/sensitivity.flow_jacobians), checked afterwards by simulating the solution on the table
  (no impact, and at least half the margin at 40 samples per row).

Method: shooting over the K control rows (held for the scene's control_dt, as the environments act),
scaled torques v = u / torque_limit in [-1, 1], SLSQP (scipy.optimize) with the exact gradients. The
study uses single shooting (``Problem.segment_rows`` None); multiple shooting (segments of
``SEGMENT_ROWS`` rows with node states and continuity constraints, studies/shooting.py) solves the
minimum-effort problems of the first ``--cross-check-pairs`` pairs again as a cross-check: at these
horizons (at most ``MAX_ROWS`` rows) it finds the same optima and costs several times more.
The terminal set is the task's: contact point within ``tolerance`` of the target (reach), and rolling
speed |R theta_dot| below ``speed_tolerance`` too (park).

* **minimum effort**: minimise mean(v^2) over a fixed horizon (``EFFORT_ROWS`` rows);
* **minimum time**: the fewest rows K <= ``MAX_ROWS`` for which the terminal set is reachable (a downward
  scan over K, assuming that reachability at K rows implies it at more rows; each K is a feasibility solve).

SLSQP is a local solver. The impacts-forbidden problem is solved first from zero torques; its optimum
never touches the wall, so it is feasible with impacts allowed and seeds that solve, together with zero
torques and ``random_starts`` seeded random sequences: the impacts-allowed value is the best of these
(never worse than the forbidden one when that converged). A gap therefore shows an optimum that uses
impacts and is better; no gap does not prove that no better one with impacts exists.

Every solve is verified by simulating its controls again on the table; a solve that fails to converge
or whose verification fails is reported as such ("failed"), never dropped.

The solved pairs are saved to RUNS/rows.pkl; ``--report-only`` rewrites the report from them.
"""
from __future__ import annotations

import math
import pickle
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from penny_env.step.tasks.park import rest_speed

import penny_env as pe
from studies.shooting import SEGMENT_ROWS, MultipleShooting, segment_bounds, wall_values

EFFORT_ROWS = 30      # minimum effort: horizon in control rows (1.5 s at 0.05 s)
MAX_ROWS = 40         # minimum time: the longest horizon tried
DEFAULT_MARGIN = 0.005
SCENES = ("ellipse", "stadium")
TASKS = ("reach", "park")
OBJECTIVES = ("effort", "time")
ACTUATIONS = ("both", "steer", "drive")


@dataclass
class Problem:
    """One optimal-control problem: a scene (table, law, params, limits), a start, a target."""

    scene: str
    task: str
    start: np.ndarray
    target: np.ndarray
    impacts: bool
    margin: float = DEFAULT_MARGIN
    actuation: str = "both"
    segment_rows: int | None = None   # the method: None single shooting, L multiple shooting (L rows a segment)
    table: object = field(init=False, repr=False)

    def __post_init__(self):
        from penny_env.envs.scene import resolve

        if self.scene not in SCENES:
            raise ValueError(f"scene must be one of {SCENES}, got {self.scene!r}")
        if self.task not in TASKS:
            raise ValueError(f"task must be one of {TASKS}, got {self.task!r}")
        if self.actuation not in ACTUATIONS:
            raise ValueError(f"actuation must be one of {ACTUATIONS}, got {self.actuation!r}")
        if self.segment_rows is not None:
            segment_bounds(1, self.segment_rows)  # a TypeError / ValueError naming segment_rows
        sc, tk = resolve(self.scene, self.task)
        self.table, self.law, self.params = sc.make_table(), sc.make_law(), sc.make_params()
        self.dt = float(sc.control_dt)
        self.limits = np.array([sc.torque_limits["u1"], sc.torque_limits["u2"]], dtype=float)
        if self.actuation == "steer":
            self.limits[1] = 0.0
        elif self.actuation == "drive":
            self.limits[0] = 0.0
        self.tolerance, self.speed_tolerance = float(tk.tolerance), rest_speed(tk)
        self.start = np.array(self.start, dtype=float)
        if self.start.shape != (6,) or not np.all(np.isfinite(self.start)):
            raise ValueError(f"start must be 6 finite numbers, got {self.start!r}")
        self.target = np.array(self.target, dtype=float)
        if self.target.shape != (2,) or not np.all(np.isfinite(self.target)):
            raise ValueError(f"target must be 2 finite numbers (x, y), got {self.target!r}")
        R = self.params.R
        # the contact point can be anywhere the penny fits: at least R (the ends) inside the wall
        if not float(self.table.h(*self.target)) < -R:
            raise ValueError(f"target {tuple(self.target)} is outside the table (the penny cannot reach it)")
        if isinstance(self.margin, bool) or not isinstance(self.margin, (int, float)) or not math.isfinite(self.margin):
            raise TypeError(f"margin must be a real number, got {self.margin!r}")
        if not 0.0 <= self.margin < self.table.inradius - R:
            raise ValueError(f"margin must be in [0, inradius - R) = [0, {self.table.inradius - R:.4g}) m, got "
                             f"{self.margin!r}: no penny fits that far off the wall")
        if not self.impacts:
            if max(wall_values(self, self.start)) > -self.margin:
                raise ValueError("start: an end is closer than margin to the wall, so impacts cannot be forbidden")
            if float(self.table.h(*self.target)) > -self.margin - R:
                raise ValueError("target: closer than margin + R to the wall, so impacts cannot be forbidden")


def scene_table(scene):
    from penny_env.envs.scene import resolve

    return resolve(scene, "reach")[0].make_table()


@dataclass
class Solution:
    status: str               # "optimal" | "failed: <why>"
    rows: int
    effort: float             # mean (u / limit)^2
    controls: np.ndarray
    impacts: int
    distance: float           # final distance to the target
    dt: float                 # control period [s]
    seconds: float
    traj: object = field(default=None, repr=False)

    @property
    def ok(self) -> bool:
        return self.status == "optimal"


def solve_rows(prob, K, x0=None, maxiter=200, max_rows=MAX_ROWS):
    """Minimum effort over K rows into the terminal set, SLSQP with exact gradients: single shooting
    (prob.segment_rows None) or multiple shooting with segments of prob.segment_rows rows
    (studies/shooting.py); verified by simulating the torques again from the start, in one piece.
    max_rows: the longest horizon accepted (studies/impact_oc.py solves longer single-input ones)."""
    from scipy.optimize import minimize

    if isinstance(K, bool) or not isinstance(K, (int, np.integer)):
        raise TypeError(f"rows must be an int, got {type(K).__name__}")
    if not 1 <= K <= max_rows:
        raise ValueError(f"rows (the control count) must be in [1, {max_rows}], got {K}")
    t0 = time.perf_counter()
    R = prob.params.R
    active = prob.limits > 0
    ms = MultipleShooting(prob, K, prob.segment_rows)
    nv = ms.nv
    bounds = [(-1.0, 1.0) if active[i % 2] else (0.0, 0.0) for i in range(nv)] + [(None, None)] * (ms.n - nv)

    def terminal(z):
        s = ms.evaluate(z)[0]
        d = s[:2] - prob.target
        out = [1.0 - (d @ d) / prob.tolerance ** 2]
        if prob.task == "park":
            out.append(1.0 - (R * s[4] / prob.speed_tolerance) ** 2)
        return np.nan_to_num(np.array(out), nan=-1e6)

    def terminal_jac(z):
        s, D = ms.evaluate(z)[:2]
        d = s[:2] - prob.target
        rows = [-2.0 * (d @ D[:2]) / prob.tolerance ** 2]
        if prob.task == "park":
            rows.append(-2.0 * (R / prob.speed_tolerance) ** 2 * s[4] * D[4])
        return np.nan_to_num(np.array(rows))

    cons = [{"type": "ineq", "fun": terminal, "jac": terminal_jac}]
    if ms.S > 1:  # continuity of the segments
        cons.append({"type": "eq", "fun": lambda z: np.nan_to_num(ms.evaluate(z)[2], nan=1e6),
                     "jac": lambda z: np.nan_to_num(ms.evaluate(z)[3])})
    if not prob.impacts and prob.margin > 0:
        cons.append({"type": "ineq", "fun": lambda z: -(ms.evaluate(z)[4] + prob.margin) / prob.margin,
                     "jac": lambda z: -ms.evaluate(z)[5] / prob.margin})
    v0 = np.zeros((K, 2)) if x0 is None else np.asarray(x0, dtype=float).reshape(K, 2)
    res = minimize(lambda z: float(z[:nv] @ z[:nv]) / nv, ms.initial(v0),
                   jac=lambda z: np.concatenate([2.0 * z[:nv] / nv, np.zeros(ms.n - nv)]), method="SLSQP",
                   bounds=bounds, constraints=cons, options={"maxiter": maxiter, "ftol": 1e-10})
    v = np.clip(res.x[:nv], -1.0, 1.0)
    u = v.reshape(K, 2) * prob.limits[None, :]
    tr = pe.simulate(prob.start, params=prob.params, table=prob.table, law=prob.law, controls=u, control_dt=prob.dt)
    dist = float(np.hypot(*(tr.final_state[:2] - prob.target)))
    status = "optimal"
    valid, reason = ms.evaluate(res.x)[6:8]
    if not res.success:
        status = f"failed: {res.message}"
    elif not valid:
        status = f"failed: no derivative ({reason})"
    elif dist > prob.tolerance * (1 + 1e-6):
        status = f"failed: verification missed the target by {dist:.4g} m"
    elif prob.task == "park" and abs(R * tr.final_state[4]) > prob.speed_tolerance * (1 + 1e-6):
        status = "failed: verification not at rest"
    elif not prob.impacts and tr.n_impacts:
        status = f"failed: verification hit the wall {tr.n_impacts} times"
    elif not prob.impacts and prob.margin > 0 and dense_clearance(prob, tr) < 0.5 * prob.margin:
        status = f"failed: verification came within {dense_clearance(prob, tr):.3g} m of the wall between samples"
    return Solution(status, K, float(v @ v) / nv, u, tr.n_impacts, dist, prob.dt, time.perf_counter() - t0, tr)


def solve_best(prob, K, starts=(), random_starts=0, seed=0, maxiter=200):
    """The best verified solve over K rows from zero torques, the given starting controls (scaled, (K, 2)) and
    random_starts seeded random ones (local solvers find local optima: more starts, a better chance of the
    global one). The last failure when none succeeds."""
    rng = np.random.default_rng(seed)
    guesses = [None] + [np.asarray(g, dtype=float) for g in starts]
    guesses += [rng.uniform(-1.0, 1.0, (K, 2)) * (prob.limits > 0)[None, :] for _ in range(random_starts)]
    best = None
    for x0 in guesses:
        sol = solve_rows(prob, K, x0=x0, maxiter=maxiter)
        if best is None or (sol.ok and (not best.ok or sol.effort < best.effort)):
            best = sol
    return best


def dense_clearance(prob, traj, per_row=40):
    """min over both ends of -h(end) along traj, sampled per_row times per control row: the margin is
    enforced at shooting.SUBSAMPLES + 1 points per row and checked here between them (to half the margin)."""
    t = np.linspace(0.0, traj.final_time, max(2, int(round(traj.final_time / prob.dt)) * per_row + 1))
    return -max(max(wall_values(prob, st)) for st in traj.states_at(t))


def minimum_effort(prob, rows=EFFORT_ROWS, maxiter=200, hint=None, random_starts=0):
    """Minimum effort over a fixed horizon; hint: a solution whose controls start one more solve."""
    starts = [] if hint is None or not hint.ok or hint.rows != rows else [hint.controls / _safe(prob.limits)]
    return solve_best(prob, rows, starts, random_starts, maxiter=maxiter)


def _safe(limits):
    return np.where(limits > 0, limits, 1.0)[None, :]


def minimum_time(prob, max_rows=MAX_ROWS, maxiter=200, hint=None, random_starts=0):
    """The fewest rows that reach the terminal set; status failed if none up to max_rows.

    A downward scan: from a feasible horizon (hint's rows, e.g. the impacts-forbidden optimum, which is
    feasible with impacts allowed; else max_rows, from zero torques and random_starts random ones), try one
    row fewer, warm-started from the last solution cut by its last row (then from zero torques), until a
    horizon fails. It assumes, as a bisection would, that what K rows reach, K + 1 rows reach too; unlike a
    bisection it meets exactly one infeasible horizon, and infeasible solves are the costly ones (SLSQP
    runs to its iteration limit there)."""
    t0 = time.perf_counter()
    best = None
    if hint is not None and hint.ok and hint.rows <= max_rows:
        best = solve_best(prob, hint.rows, [hint.controls / _safe(prob.limits)], 0, maxiter=maxiter)
    if best is None or not best.ok:
        best = solve_best(prob, max_rows, (), random_starts, maxiter=maxiter)
    if not best.ok:
        best.status = f"failed: not reached within {max_rows} rows ({best.status})"
        best.seconds = time.perf_counter() - t0
        return best
    while best.rows > 1:
        K = best.rows - 1
        sol = solve_rows(prob, K, x0=best.controls[:K] / _safe(prob.limits), maxiter=maxiter)
        if not sol.ok:
            sol = solve_rows(prob, K, x0=None, maxiter=maxiter)
        if not sol.ok:
            break
        best = sol
    best.seconds = time.perf_counter() - t0
    return best


# -- the study -----------------------------------------------------------------------------------------
def draw_pairs(scene, task, n, seed, margin=DEFAULT_MARGIN):
    """n (start, target) pairs drawn as the environments draw them, kept where impacts can be forbidden
    (start ends and target at least margin off the wall), so both variants solve the same pairs."""
    from penny_env.envs.scene import resolve

    sc, tk = resolve(scene, task)
    table, params = sc.make_table(), sc.make_params()
    ax, ay = sc.spawn_axes()
    f_target = tk.target_fraction * (1.0 - params.R / table.inradius)
    init = sc.init
    rng = np.random.default_rng(seed)
    pairs = []
    while len(pairs) < n:
        r, a = sc.init["spawn_fraction"] * math.sqrt(rng.random()), rng.uniform(-math.pi, math.pi)
        s = np.array([r * ax * math.cos(a), r * ay * math.sin(a)] +
                     [rng.uniform(*init[k]) for k in ("theta", "phi", "theta_dot", "phi_dot")])
        r, a = f_target * math.sqrt(rng.random()), rng.uniform(-math.pi, math.pi)
        target = np.array([r * ax * math.cos(a), r * ay * math.sin(a)])
        try:
            Problem(scene, task, s, target, impacts=False, margin=margin)
        except ValueError:
            continue
        pairs.append((s, target))
    return pairs


def solve_pair(job):
    """One pair of one problem, solved with impacts forbidden and allowed: the study's unit of work."""
    sc, tk, ob, i, s, target, actuation, horizon, maxiter, random_starts, segment_rows = job
    # impacts forbidden first: its optimum is feasible with impacts allowed (it never touches the wall),
    # so it seeds the allowed solve, which then can only do as well or better
    solve = minimum_effort if ob == "effort" else minimum_time
    kw = dict(actuation=actuation, segment_rows=segment_rows)
    without = solve(Problem(sc, tk, s, target, impacts=False, **kw), horizon, maxiter)
    with_ = solve(Problem(sc, tk, s, target, impacts=True, **kw), horizon, maxiter,
                  hint=without, random_starts=random_starts)
    return {"scene": sc, "task": tk, "objective": ob, "pair": i, "actuation": actuation,
            "method": "single" if segment_rows is None else f"multiple ({segment_rows} rows a segment)",
            "start": np.asarray(s, dtype=float), "target": np.asarray(target, dtype=float),
            "with": with_, "without": without}


def study(n_pairs, seed=0, scenes=SCENES, tasks=TASKS, objectives=OBJECTIVES, actuation="both", progress=True,
          effort_rows=EFFORT_ROWS, max_rows=MAX_ROWS, maxiter=200, random_starts=2, workers=1, segment_rows=None):
    """Every (scene, task, objective) on n_pairs pairs; workers > 1 solves pairs in that many processes;
    segment_rows: None single shooting, L multiple shooting with L rows a segment."""
    jobs = [(sc, tk, ob, i, s, target, actuation, effort_rows if ob == "effort" else max_rows, maxiter,
             random_starts, segment_rows)
            for sc in scenes for tk in tasks for ob in objectives
            for i, (s, target) in enumerate(draw_pairs(sc, tk, n_pairs, seed))]
    if workers > 1:
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(workers) as pool:
            results = pool.map(solve_pair, jobs)
            rows = [_report_progress(r, progress) for r in results]
    else:
        rows = [_report_progress(solve_pair(job), progress) for job in jobs]
    return rows


def _report_progress(row, progress):
    if progress:
        w, wo, ob = row["with"], row["without"], row["objective"]
        print(f"{row['scene']} {row['task']} {ob} ({row['actuation']}) #{row['pair']}: with impacts {w.status} "
              f"({value(w, ob):.4g}), without {wo.status} ({value(wo, ob):.4g})", file=sys.stderr, flush=True)
    return row


def value(sol, objective):
    """The objective's value: mean squared scaled torque (effort) or seconds (time); nan if failed."""
    if not sol.ok:
        return math.nan
    return sol.effort if objective == "effort" else sol.rows * sol.dt


def summarise(rows, rel_gap=1e-3):
    """Per (scene, task, objective, actuation): pairs, converged counts, pairs where the impacts-allowed optimum is
    strictly better (by more than rel_gap relative, both converged) with the mean gap there, and how many of those
    hit the wall. An allowed optimum can be better without an impact (it may come closer to the wall than the
    forbidden problem's margin), so the pairs where impacts pay are the better ones that hit the wall."""
    out = []
    keys = sorted({(r["scene"], r["task"], r["objective"], r.get("actuation", "both")) for r in rows})
    for key in keys:
        sel = [r for r in rows if (r["scene"], r["task"], r["objective"], r.get("actuation", "both")) == key]
        both = [r for r in sel if r["with"].ok and r["without"].ok]
        better, gaps = [], []
        for r in both:
            a, b = value(r["with"], key[2]), value(r["without"], key[2])
            if a < b * (1 - rel_gap) - 1e-15:
                better.append(r)
                gaps.append((b - a) / b if b > 0 else math.inf)
        only = [r for r in sel if r["with"].ok and not r["without"].ok]
        out.append({"scene": key[0], "task": key[1], "objective": key[2], "actuation": key[3], "pairs": len(sel),
                    "ok_with": sum(r["with"].ok for r in sel), "ok_without": sum(r["without"].ok for r in sel),
                    "both": len(both), "better": len(better), "mean_gap": float(np.mean(gaps)) if gaps else math.nan,
                    "better_impacts": sum(r["with"].impacts > 0 for r in better),
                    "only_with": len(only), "only_with_impacts": sum(r["with"].impacts > 0 for r in only),
                    "impacts_used": sum(r["with"].ok and r["with"].impacts > 0 for r in sel)})
    return out


def answer(summary) -> list[str]:
    """The report's reading, computed from the summary: where an optimum that hits the wall beats every optimum
    found without impacts, per objective for both controls, and for the single-input problems."""
    lines = []
    for ob in OBJECTIVES:
        sel = [s for s in summary if s["objective"] == ob and s["actuation"] == "both"]
        if sel:
            n_both, n_imp = sum(s["both"] for s in sel), sum(s["better_impacts"] for s in sel)
            n_only = sum(s["only_with_impacts"] for s in sel)
            lines.append(f"- Both controls, minimum {ob}: the optimum with impacts allowed hits the wall and is strictly "
                         f"better in {n_imp} of {n_both} pairs solved both ways ({100 * n_imp / max(n_both, 1):.0f}%), "
                         f"and {n_only} pair(s) were solved only with impacts allowed and with an impact.")
    for act in ("steer", "drive"):
        sel = [s for s in summary if s["actuation"] == act]
        if sel:
            n = sum(s["pairs"] for s in sel)
            lines.append(f"- {act.capitalize()} only, minimum time to reach: solved in {sum(s['ok_with'] for s in sel)} "
                         f"of {n} pairs with impacts allowed and {sum(s['ok_without'] for s in sel)} with impacts "
                         f"forbidden; {sum(s['only_with_impacts'] for s in sel)} solved only with an impact, and "
                         f"{sum(s['better_impacts'] for s in sel)} faster with one.")
    return lines


def draw_plans(ax, r, points, label):
    """The table's wall and pair r's plans with and without impacts (impacts marked x); label(key, sol) names each."""
    wall = scene_table(r["scene"]).boundary(256)
    ax.plot(wall[:, 0], wall[:, 1], "k-", lw=1)
    for key, style in (("with", "C0-"), ("without", "C1--")):
        sol = r[key]
        if sol.traj is None:
            continue
        p = sol.traj.states_at(np.linspace(0.0, sol.traj.final_time, points))
        ax.plot(p[:, 0], p[:, 1], style, lw=1.2, label=label(key, sol))
        if sol.traj.n_impacts:
            q = sol.traj.impact_states
            ax.plot(q[:, 0], q[:, 1], "rx", ms=7)


def plot_examples(rows, path, n=4):
    """A PNG of up to n optimal trajectories (those using impacts first); False without matplotlib."""
    try:
        import matplotlib
    except ImportError:  # an optional extra: the report is written without the picture
        return False

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    picks = [r for r in rows if r["with"].ok and r["with"].impacts > 0][:n] or [r for r in rows if r["with"].ok][:n]
    if not picks:
        return False
    fig, axes = plt.subplots(1, len(picks), figsize=(4 * len(picks), 4), squeeze=False)
    for ax, r in zip(axes[0], picks):
        draw_plans(ax, r, 400, lambda key, sol: f"impacts {'allowed' if key == 'with' else 'forbidden'}"
                                                f" ({sol.status.split(':')[0]})")
        if "target" in r:
            ax.plot(*r["target"], "o", mfc="none", mec="k", ms=8, label="target")
        ax.set_aspect("equal")
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.set_title(f"{r['scene']} {r['task']} min {r['objective']} ({r.get('actuation', 'both')}) #{r['pair']}",
                     fontsize=9)
        ax.legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


def is_single(row) -> bool:
    return row.get("method", "single") == "single"


def cross_check(rows, rel=1e-6):
    """Multiple against single shooting on the same (scene, task, objective, actuation, pair, impacts): pairs
    compared, both converged, agreeing values (within rel), and the largest relative difference."""
    single = {(r["scene"], r["task"], r["objective"], r.get("actuation", "both"), r["pair"]): r
              for r in rows if is_single(r)}
    out = {"compared": 0, "both": 0, "agree": 0, "max_rel": 0.0, "multiple_better": 0, "single_better": 0,
           "seconds_single": 0.0, "seconds_multiple": 0.0}
    for r in rows:
        if is_single(r):
            continue
        twin = single.get((r["scene"], r["task"], r["objective"], r.get("actuation", "both"), r["pair"]))
        if twin is None:
            continue
        for k in ("with", "without"):
            out["compared"] += 1
            out["seconds_single"] += twin[k].seconds
            out["seconds_multiple"] += r[k].seconds
            if r[k].ok and twin[k].ok:
                a, b = value(r[k], r["objective"]), value(twin[k], r["objective"])
                d = abs(a - b) / max(abs(b), 1e-300)
                out["both"] += 1
                out["agree"] += d <= rel
                out["max_rel"] = max(out["max_rel"], d)
                out["multiple_better"] += a < b and d > rel
                out["single_better"] += b < a and d > rel
    return out


def write_report(rep, rows, commands, seconds: float):
    """The report (rep.out) from the solved rows (single shooting; multiple-shooting rows go to the cross-check);
    commands: the command lines of the runs that solved them."""
    checked = [r for r in rows if not is_single(r)]
    rows = [r for r in rows if is_single(r)]
    summary = summarise(rows)
    png = rep.out.with_name("optimal_control.png")
    has_png = plot_examples(rows, png)
    from lab.common import machine_lines

    lines = ["# Does the optimal penny need impacts? (the central study: slow starts, central targets)", "",
             *machine_lines(),
             "- commands: " + ", then ".join(f"`{c}`" for c in commands) +
             f" (from the repository root); the solves took {seconds:.0f} s in all", "",
             "Method: see the docstring of `studies/optimal_control.py` (single shooting over the control rows, "
             "SLSQP, exact derivatives through impacts from `simulate(..., sensitivities=True)`; multiple "
             "shooting, studies/shooting.py, as a cross-check below).", "",
             "## Answer (computed from the table below)", "", *answer(summary), "",
             "SLSQP is a local solver: \"strictly better\" shows an optimum with impacts that beats the best one "
             "found without; a pair with no gap does not prove that none exists.", "",
             "## Every problem", "",
             "Columns: pairs; solves that converged with impacts allowed / forbidden; pairs where both converged; of "
             "those, pairs where the allowed optimum is strictly better (by more than 0.1 %), with the mean gap, and "
             "how many of those hit the wall (an allowed optimum may also win by coming closer to the wall than the "
             "forbidden problem's 5 mm margin); pairs solved only with impacts allowed, and how many of those hit the "
             "wall; allowed optima that hit the wall.", "",
             "| scene | task | objective | actuation | pairs | converged allowed / forbidden | both | "
             "allowed strictly better | mean gap | better and hits the wall | solved only when allowed | "
             "of those, hits the wall | allowed optimum hits the wall |",
             "|---|---|---|---|---:|---|---:|---|---:|---:|---:|---:|---:|"]
    for s in summary:
        share = f"{s['better']}/{s['both']}" + (f" ({100 * s['better'] / s['both']:.0f}%)" if s["both"] else "")
        gap = "-" if math.isnan(s["mean_gap"]) else f"{100 * s['mean_gap']:.1f}%"
        lines.append(f"| {s['scene']} | {s['task']} | {s['objective']} | {s['actuation']} | {s['pairs']} "
                     f"| {s['ok_with']} / {s['ok_without']} | {s['both']} | {share} | {gap} | {s['better_impacts']} "
                     f"| {s['only_with']} | {s['only_with_impacts']} | {s['impacts_used']} |")
    lines += ["", "Effort: mean of (u / torque limit)^2 over the rows; time: rows x control_dt. Failed solves:", ""]
    failed = [(r, k) for r in rows for k in ("with", "without") if not r[k].ok]
    lines += [f"* {r['scene']} {r['task']} {r['objective']} ({r.get('actuation', 'both')}) pair {r['pair']}, impacts "
              f"{'allowed' if k == 'with' else 'forbidden'}: {r[k].status}" for r, k in failed] or ["* none"]
    if has_png:
        lines += ["", f"![optimal trajectories]({png.name})", "",
                  "Optimal trajectories of the contact point (impacts marked x, the target circled), those that hit "
                  "the wall first: impacts allowed (solid), forbidden (dashed; its status in the legend)."]
    if checked:
        c = cross_check(rows + checked)
        lines += ["", "## Multiple shooting against single shooting", "",
                  f"The minimum-effort problems of the first pairs, solved again by multiple shooting "
                  f"({checked[0]['method']}; node states and continuity defects, studies/shooting.py), from the "
                  f"same starting torques: {c['compared']} solves compared, {c['both']} converged with both "
                  f"methods, {c['agree']} of those with the same optimal effort to 1e-6 relative (largest relative "
                  f"difference {c['max_rel']:.1e}); multiple shooting lower in {c['multiple_better']}, single "
                  f"shooting lower in {c['single_better']}. Solver time: {c['seconds_single']:.0f} s single, "
                  f"{c['seconds_multiple']:.0f} s multiple, which is why the study above uses single shooting at "
                  f"these horizons (at most {MAX_ROWS} rows)."]
    rep.write(lines)
    return summary


def main(argv=None):
    from lab.common import report_command

    def options(ap):
        ap.add_argument("--pairs", type=int, default=50)
        ap.add_argument("--seed", type=int, default=0)
        ap.add_argument("--workers", type=int, default=1, help="processes solving pairs in parallel")
        ap.add_argument("--single-input-pairs", type=int, default=10,
                        help="pairs for the steer-only and drive-only minimum-time problems (default 10)")
        ap.add_argument("--cross-check-pairs", type=int, default=10,
                        help="pairs whose minimum-effort problems are solved again by multiple shooting (default 10)")
        ap.add_argument("--runs", type=Path, default=None,
                        help="where the solved pairs are saved (rows.pkl; default runs/optimal_control, --quick: beside "
                             "the report)")
        stage = ap.add_mutually_exclusive_group()
        stage.add_argument("--report-only", action="store_true", help="rewrite the report from the saved rows.pkl")
        stage.add_argument("--cross-check-only", action="store_true",
                           help="redo only the multiple-shooting cross-check on the saved rows.pkl, then the report")
    rep = report_command("studies.optimal_control", "optimal_control_central.md", "Optimal control with and without "
                         "impacts (docs/optimal_control_central.md)", argv, options=options, docs_default=True,
                         quick="2 pairs of one scene/task")
    args, out = rep.args, rep.out
    for name in ("pairs", "workers"):
        if getattr(args, name) < 1:
            raise SystemExit(f"--{name} must be >= 1, got {getattr(args, name)}")
    for name in ("single_input_pairs", "cross_check_pairs"):
        if getattr(args, name) < 0:
            raise SystemExit(f"--{name.replace('_', '-')} must be >= 0, got {getattr(args, name)}")
    if args.quick:
        scenes, tasks, objectives, n_pairs, checked = ("ellipse",), ("reach",), ("effort",), 2, 1
        cmd = "python -m studies.optimal_control --quick"
    else:
        scenes, tasks, objectives, n_pairs, checked = SCENES, TASKS, OBJECTIVES, args.pairs, args.cross_check_pairs
        cmd = (f"python -m studies.optimal_control --pairs {args.pairs} --single-input-pairs "
               f"{args.single_input_pairs} --cross-check-pairs {args.cross_check_pairs} --seed {args.seed}")
    runs = args.runs or (out.parent if args.quick else Path("runs/optimal_control"))
    saved = runs / "rows.pkl"
    quick = dict(maxiter=100, random_starts=1) if args.quick else {}
    t0 = time.perf_counter()
    if args.report_only or args.cross_check_only:
        if not saved.is_file():
            raise SystemExit(f"no saved solves at {saved} (run without --report-only / --cross-check-only first)")
        with open(saved, "rb") as f:
            rows, seconds, commands = pickle.load(f)
    else:
        rows = study(n_pairs, args.seed, scenes=scenes, tasks=tasks, objectives=objectives, workers=args.workers,
                     **quick)
        if not args.quick:
            for act in ("steer", "drive"):  # which single-input problems have solutions only with impacts?
                if args.single_input_pairs:
                    rows += study(args.single_input_pairs, args.seed, tasks=("reach",), objectives=("time",),
                                  actuation=act, workers=args.workers)
        commands, seconds = [cmd], 0.0
    if not args.report_only:
        if args.cross_check_only:
            rows = [r for r in rows if is_single(r)]
            commands = commands + [f"python -m studies.optimal_control --cross-check-only --cross-check-pairs "
                                   f"{args.cross_check_pairs}"]
        if checked:  # the same pairs (same seed), by multiple shooting
            rows += study(checked, args.seed, scenes=scenes, tasks=tasks, objectives=("effort",),
                          workers=args.workers, segment_rows=SEGMENT_ROWS, **quick)
        seconds += time.perf_counter() - t0
        runs.mkdir(parents=True, exist_ok=True)
        with open(saved, "wb") as f:
            pickle.dump((rows, seconds, commands), f)
    write_report(rep, rows, commands, seconds)
    return out


if __name__ == "__main__":
    # run the importable module's main, so that rows.pkl names its classes studies.optimal_control.Solution
    # (not __main__.Solution) and loads from any entry point
    from studies.optimal_control import main as module_main

    module_main()
