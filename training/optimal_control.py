"""Does the optimal penny need impacts? Trajectory optimisation with exact derivatives through impacts.

    python -m training.optimal_control [--quick] [--pairs 50] [--workers 16] [--out docs/optimal_control.md]

For start/target pairs drawn as the environments draw them (penny_env/presets: the paper's ellipse and
the stadium, reach and park tasks), each problem is solved twice:

* **impacts allowed**: the real table; the final state and its derivatives come from
  ``penny_env.simulate(..., sensitivities=True)`` (saltation matrices through every impact);
* **impacts forbidden**: both ends kept at least ``margin`` off the wall at every sample time
  (row ends and ``SUBSAMPLES`` points inside each control row; the flow and its derivatives are exact,
  physics/sensitivity.flow_jacobians), checked afterwards by simulating the solution on the table (no
  impact, and at least half the margin at 40 samples per row).

Method: single shooting over the K control rows (held for the scene's control_dt, as the environments
act), scaled torques v = u / torque_limit in [-1, 1], SLSQP (scipy.optimize) with the exact gradients.
The terminal set is the task's: contact point within ``tolerance`` of the target (reach), and rolling
speed |R theta_dot| below ``speed_tolerance`` too (park).

* **minimum effort**: minimise mean(v^2) over a fixed horizon (``EFFORT_ROWS`` rows);
* **minimum time**: the fewest rows K <= ``MAX_ROWS`` for which the terminal set is reachable (bisection
  on K, assuming that reachability at K rows implies it at more rows; each K is a feasibility solve).

SLSQP is a local solver. The impacts-forbidden problem is solved first from zero torques; its optimum
never touches the wall, so it is feasible with impacts allowed and seeds that solve, together with zero
torques and ``random_starts`` seeded random sequences: the impacts-allowed value is the best of these
(never worse than the forbidden one when that converged). A gap therefore shows an optimum that uses
impacts and is better; no gap does not prove that no better one with impacts exists.

Every solve is verified by simulating its controls again on the table; a solve that fails to converge
or whose verification fails is reported as such ("failed"), never dropped.
"""
from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

import penny_env as pe
from penny_env.physics.kernels import end_point, SCALAR
from penny_env.physics.scalar import flow1
from penny_env.physics.sensitivity import flow_jacobians

EFFORT_ROWS = 30      # minimum effort: horizon in control rows (1.5 s at 0.05 s)
MAX_ROWS = 40         # minimum time: the longest horizon tried
SUBSAMPLES = 4        # impacts forbidden: wall-distance samples inside each row (plus its end)
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
    table: object = field(init=False, repr=False)

    def __post_init__(self):
        from penny_env.envs.scene import resolve

        if self.scene not in SCENES:
            raise ValueError(f"scene must be one of {SCENES}, got {self.scene!r}")
        if self.task not in TASKS:
            raise ValueError(f"task must be one of {TASKS}, got {self.task!r}")
        if self.actuation not in ACTUATIONS:
            raise ValueError(f"actuation must be one of {ACTUATIONS}, got {self.actuation!r}")
        sc, tk = resolve(self.scene, self.task)
        self.table, self.law, self.params = sc.make_table(), sc.make_law(), sc.make_params()
        self.dt = float(sc.control_dt)
        self.limits = np.array([sc.torque_limits["u1"], sc.torque_limits["u2"]], dtype=float)
        if self.actuation == "steer":
            self.limits[1] = 0.0
        elif self.actuation == "drive":
            self.limits[0] = 0.0
        self.tolerance, self.speed_tolerance = float(tk.tolerance), float(tk.speed_tolerance)
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


def wall_values(prob, s):
    """h(end) for the front and back end of state s."""
    R = prob.params.R
    out = []
    for sigma in (1.0, -1.0):
        px, py, _, _ = end_point(s[0], s[1], s[3], s[4], s[5], sigma, R, SCALAR)
        out.append(float(prob.table.h(px, py)))
    return out


def wall_gradient(prob, s, sigma):
    """(h(end), d h(end) / d state) for end sigma."""
    R = prob.params.R
    c, sn = math.cos(s[3]), math.sin(s[3])
    px, py = s[0] + sigma * R * c, s[1] + sigma * R * sn
    hx, hy = (float(v) for v in prob.table.grad(px, py))
    g = np.zeros(6)
    g[0], g[1], g[3] = hx, hy, sigma * R * (hy * c - hx * sn)
    return float(prob.table.h(px, py)), g


# -- the shooting functions: final state, path samples and their derivatives w.r.t. v = u / limits ----
def rollout(prob, v):
    """(final state, d final / d v (6 x 2K), path samples (h (n,), dh/dv (n, 2K)) or None, valid, reason)."""
    K = v.shape[0]
    u = v * prob.limits[None, :]
    scale = np.tile(prob.limits, K)  # du / dv
    if prob.impacts:
        tr = pe.simulate(prob.start, params=prob.params, table=prob.table, law=prob.law, controls=u,
                         control_dt=prob.dt, sensitivities=True)
        return tr.final_state, tr.control_jacobian * scale[None, :], None, tr.jacobian_valid, tr.jacobian_reason
    # impacts forbidden: the free flow, chained row by row, with wall samples inside each row
    R, J, Itot = prob.params.R, prob.params.J, prob.params.rolling_inertia
    s = tuple(prob.start)
    C = np.zeros((6, 2 * K))
    hs, dh = [], []
    taus = prob.dt * np.arange(1, SUBSAMPLES + 2) / (SUBSAMPLES + 1)
    dacc = np.array([1.0 / J, 1.0 / Itot])
    for k in range(K):
        a1, a2 = u[k, 0] / J, u[k, 1] / Itot
        Phi, B = flow_jacobians(np.array(s), a1, a2, taus, R)
        Cs = Phi @ C  # (n, 6, 2K)
        Cs[:, :, 2 * k:2 * k + 2] += B * dacc[None, None, :]
        G = np.empty((len(taus), 2, 6))
        for j, tau in enumerate(taus):
            st = flow1(s, a1, a2, tau, R)
            for e, sigma in enumerate((1.0, -1.0)):
                h, G[j, e] = wall_gradient(prob, st, sigma)
                hs.append(h)
        dh.append(np.einsum("jei,jik->jek", G, Cs).reshape(-1, 2 * K))
        s, C = st, Cs[-1]
    samples = (np.array(hs), np.concatenate(dh) * scale[None, :])
    return np.array(s), C * scale[None, :], samples, True, ""


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


def solve_rows(prob, K, x0=None, maxiter=200):
    """Minimum effort over K rows into the terminal set (SLSQP, exact gradients); verified by simulation."""
    from scipy.optimize import minimize

    if isinstance(K, bool) or not isinstance(K, (int, np.integer)):
        raise TypeError(f"rows must be an int, got {type(K).__name__}")
    if not 1 <= K <= MAX_ROWS:
        raise ValueError(f"rows (the control count) must be in [1, {MAX_ROWS}], got {K}")
    t0 = time.perf_counter()
    R = prob.params.R
    active = prob.limits > 0
    n = 2 * K
    bounds = [(-1.0, 1.0) if active[i % 2] else (0.0, 0.0) for i in range(n)]
    cache = {}

    def run(x):
        key = x.tobytes()
        if key not in cache:
            cache.clear()
            cache[key] = rollout(prob, x.reshape(K, 2))
        return cache[key]

    def terminal(x):
        s, D, _, _, _ = run(x)
        d = s[:2] - prob.target
        out = [1.0 - (d @ d) / prob.tolerance ** 2]
        if prob.task == "park":
            out.append(1.0 - (R * s[4] / prob.speed_tolerance) ** 2)
        return np.nan_to_num(np.array(out), nan=-1e6)

    def terminal_jac(x):
        s, D, _, _, _ = run(x)
        d = s[:2] - prob.target
        rows = [-2.0 * (d @ D[:2]) / prob.tolerance ** 2]
        if prob.task == "park":
            rows.append(-2.0 * (R / prob.speed_tolerance) ** 2 * s[4] * D[4])
        return np.nan_to_num(np.array(rows))

    def path(x):
        return -(run(x)[2][0] + prob.margin) / prob.margin

    def path_jac(x):
        return -run(x)[2][1] / prob.margin

    cons = [{"type": "ineq", "fun": terminal, "jac": terminal_jac}]
    if not prob.impacts and prob.margin > 0:
        cons.append({"type": "ineq", "fun": path, "jac": path_jac})
    x = np.zeros(n) if x0 is None else np.asarray(x0, dtype=float).ravel().copy()
    res = minimize(lambda z: float(z @ z) / n, x, jac=lambda z: 2.0 * z / n, method="SLSQP", bounds=bounds,
                   constraints=cons, options={"maxiter": maxiter, "ftol": 1e-10})
    u = res.x.reshape(K, 2) * prob.limits[None, :]
    tr = pe.simulate(prob.start, params=prob.params, table=prob.table, law=prob.law, controls=u, control_dt=prob.dt)
    dist = float(np.hypot(*(tr.final_state[:2] - prob.target)))
    status = "optimal"
    valid = run(res.x)[3]
    if not res.success:
        status = f"failed: {res.message}"
    elif not valid:
        status = f"failed: no derivative ({run(res.x)[4]})"
    elif dist > prob.tolerance * (1 + 1e-6):
        status = f"failed: verification missed the target by {dist:.4g} m"
    elif prob.task == "park" and abs(R * tr.final_state[4]) > prob.speed_tolerance * (1 + 1e-6):
        status = "failed: verification not at rest"
    elif not prob.impacts and tr.n_impacts:
        status = f"failed: verification hit the wall {tr.n_impacts} times"
    elif not prob.impacts and prob.margin > 0 and dense_clearance(prob, tr) < 0.5 * prob.margin:
        status = f"failed: verification came within {dense_clearance(prob, tr):.3g} m of the wall between samples"
    return Solution(status, K, float(res.x @ res.x) / n, u, tr.n_impacts, dist, prob.dt, time.perf_counter() - t0, tr)


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
    enforced at SUBSAMPLES + 1 points per row and checked here between them (to half the margin)."""
    t = np.linspace(0.0, traj.final_time, max(2, int(round(traj.final_time / prob.dt)) * per_row + 1))
    return -max(max(wall_values(prob, st)) for st in traj.states_at(t))


def minimum_effort(prob, rows=EFFORT_ROWS, maxiter=200, hint=None, random_starts=0):
    """Minimum effort over a fixed horizon; hint: a solution whose controls start one more solve."""
    starts = [] if hint is None or not hint.ok or hint.rows != rows else [hint.controls / _safe(prob.limits)]
    return solve_best(prob, rows, starts, random_starts, maxiter=maxiter)


def _safe(limits):
    return np.where(limits > 0, limits, 1.0)[None, :]


def minimum_time(prob, max_rows=MAX_ROWS, maxiter=200, hint=None, random_starts=0):
    """The fewest rows that reach the terminal set (bisection on K, assuming that what K rows reach, more
    rows reach too); status failed if none up to max_rows. hint: a solution (e.g. the impacts-forbidden
    optimum) whose row count is tried first as the upper end."""
    t0 = time.perf_counter()
    hi = None
    if hint is not None and hint.ok and hint.rows <= max_rows:
        hi = solve_best(prob, hint.rows, [hint.controls / _safe(prob.limits)], 0, maxiter=maxiter)
    if hi is None or not hi.ok:
        hi = solve_best(prob, max_rows, (), random_starts, maxiter=maxiter)
    if not hi.ok:
        hi.status = f"failed: not reached within {max_rows} rows ({hi.status})"
        hi.seconds = time.perf_counter() - t0
        return hi
    lo_rows, best = 0, hi
    while best.rows - lo_rows > 1:
        mid = (lo_rows + best.rows) // 2
        # warm start: the shorter horizon begins as the best solution does
        sol = solve_best(prob, mid, [best.controls[:mid] / _safe(prob.limits)], 0, maxiter=maxiter)
        if sol.ok:
            best = sol
        else:
            lo_rows = mid
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
    sc, tk, ob, i, s, target, actuation, horizon, maxiter, random_starts = job
    # impacts forbidden first: its optimum is feasible with impacts allowed (it never touches the wall),
    # so it seeds the allowed solve, which then can only do as well or better
    solve = minimum_effort if ob == "effort" else minimum_time
    without = solve(Problem(sc, tk, s, target, impacts=False, actuation=actuation), horizon, maxiter)
    with_ = solve(Problem(sc, tk, s, target, impacts=True, actuation=actuation), horizon, maxiter,
                  hint=without, random_starts=random_starts)
    return {"scene": sc, "task": tk, "objective": ob, "pair": i, "actuation": actuation,
            "with": with_, "without": without}


def study(n_pairs, seed=0, scenes=SCENES, tasks=TASKS, objectives=OBJECTIVES, actuation="both", progress=True,
          effort_rows=EFFORT_ROWS, max_rows=MAX_ROWS, maxiter=200, random_starts=2, workers=1):
    """Every (scene, task, objective) on n_pairs pairs; workers > 1 solves pairs in that many processes."""
    jobs = [(sc, tk, ob, i, s, target, actuation, effort_rows if ob == "effort" else max_rows, maxiter,
             random_starts)
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
    """Per (scene, task, objective): pairs, converged counts, share where the optimum with impacts is strictly
    better (by more than rel_gap relative, both converged), and the mean gap there."""
    out = []
    keys = sorted({(r["scene"], r["task"], r["objective"], r.get("actuation", "both")) for r in rows})
    for key in keys:
        sel = [r for r in rows if (r["scene"], r["task"], r["objective"], r.get("actuation", "both")) == key]
        both = [r for r in sel if r["with"].ok and r["without"].ok]
        better, gaps = 0, []
        for r in both:
            a, b = value(r["with"], key[2]), value(r["without"], key[2])
            if a < b * (1 - rel_gap) - 1e-15:
                better += 1
                gaps.append((b - a) / b if b > 0 else math.inf)
        out.append({"scene": key[0], "task": key[1], "objective": key[2], "actuation": key[3], "pairs": len(sel),
                    "ok_with": sum(r["with"].ok for r in sel), "ok_without": sum(r["without"].ok for r in sel),
                    "both": len(both), "better": better, "mean_gap": float(np.mean(gaps)) if gaps else math.nan,
                    "only_with": sum(r["with"].ok and not r["without"].ok for r in sel),
                    "impacts_used": sum(r["with"].ok and r["with"].impacts > 0 for r in sel)})
    return out


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
        wall = scene_table(r["scene"]).boundary(256)
        ax.plot(wall[:, 0], wall[:, 1], "k-", lw=1)
        for key, style in (("with", "C0-"), ("without", "C1--")):
            sol = r[key]
            if sol.traj is None:
                continue
            t = np.linspace(0.0, sol.traj.final_time, 400)
            p = sol.traj.states_at(t)
            ax.plot(p[:, 0], p[:, 1], style, lw=1.2, label=f"impacts {'allowed' if key == 'with' else 'forbidden'}"
                    f" ({sol.status.split(':')[0]})")
            if sol.traj.n_impacts:
                q = sol.traj.impact_states
                ax.plot(q[:, 0], q[:, 1], "rx", ms=7)
        ax.set_aspect("equal")
        ax.set_title(f"{r['scene']} {r['task']} min {r['objective']} #{r['pair']}", fontsize=9)
        ax.legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


def write_report(rows, out_path: Path, command: str, seconds: float):
    summary = summarise(rows)
    png = out_path.with_name("optimal_control.png")
    has_png = plot_examples(rows, png)
    lines = ["# Does the optimal penny need impacts?", "",
             f"Generated by `{command}` ({time.strftime('%Y-%m-%d')}, {seconds:.0f} s). "
             "Method: see the docstring of `training/optimal_control.py` (single shooting over the control rows, "
             "SLSQP, exact derivatives through impacts from `simulate(..., sensitivities=True)`).", "",
             "| scene | task | objective | actuation | pairs | converged with / without impacts | both | "
             "with impacts strictly better | mean gap | solved only with impacts | optimum uses impacts |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for s in summary:
        share = f"{s['better']}/{s['both']}" + (f" ({100 * s['better'] / s['both']:.0f}%)" if s["both"] else "")
        gap = "-" if math.isnan(s["mean_gap"]) else f"{100 * s['mean_gap']:.1f}%"
        lines.append(f"| {s['scene']} | {s['task']} | {s['objective']} | {s['actuation']} | {s['pairs']} "
                     f"| {s['ok_with']} / {s['ok_without']} "
                     f"| {s['both']} | {share} | {gap} | {s['only_with']} | {s['impacts_used']} |")
    lines += ["", "Not done here: the comparison with the RL agents of the study (issue 11) on the same pairs.",
              "", "Effort: mean of (u / torque limit)^2 over the rows; time: rows x control_dt. Failed solves:", ""]
    failed = [(r, k) for r in rows for k in ("with", "without") if not r[k].ok]
    lines += [f"* {r['scene']} {r['task']} {r['objective']} ({r.get('actuation', 'both')}) pair {r['pair']}, impacts "
              f"{'allowed' if k == 'with' else 'forbidden'}: {r[k].status}" for r, k in failed] or ["* none"]
    if has_png:
        lines += ["", f"![optimal trajectories]({png.name})", "",
                  "Optimal trajectories (impacts marked x): impacts allowed (solid), forbidden (dashed)."]
    out_path.write_text("\n".join(lines) + "\n")
    return summary


def main(argv=None):
    ap = argparse.ArgumentParser(description="Optimal control with and without impacts (docs/optimal_control.md)")
    ap.add_argument("--quick", action="store_true", help="2 pairs of one scene/task, to a temporary folder (never docs/)")
    ap.add_argument("--pairs", type=int, default=50)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=1, help="processes solving pairs in parallel")
    ap.add_argument("--single-input-pairs", type=int, default=None,
                    help="pairs for the steer-only and drive-only minimum-time problems (default: --pairs)")
    ap.add_argument("--out", type=Path, default=None, help="report path (default docs/optimal_control.md; "
                                                              "--quick: a temporary folder)")
    args = ap.parse_args(argv)
    if args.pairs < 1:
        raise SystemExit("--pairs must be >= 1")
    if args.workers < 1:
        raise SystemExit("--workers must be >= 1")
    t0 = time.perf_counter()
    if args.quick:
        out = args.out or Path(tempfile.mkdtemp(prefix="optimal_control_")) / "optimal_control.md"
        if out.resolve().parent == (Path(__file__).resolve().parents[1] / "docs"):
            raise SystemExit("--quick never writes into docs/")
        rows = study(2, args.seed, scenes=("ellipse",), tasks=("reach",), objectives=("effort",), effort_rows=EFFORT_ROWS, maxiter=100,
                     random_starts=1, workers=args.workers)
    else:
        out = args.out or Path(__file__).resolve().parents[1] / "docs" / "optimal_control.md"
        rows = study(args.pairs, args.seed, workers=args.workers)
        single = args.pairs if args.single_input_pairs is None else args.single_input_pairs
        for act in ("steer", "drive"):  # which single-input problems have solutions only with impacts?
            rows += study(single, args.seed, tasks=("reach",), objectives=("time",), actuation=act,
                          workers=args.workers)
    out.parent.mkdir(parents=True, exist_ok=True)
    cmd = "python -m training.optimal_control" + (" --quick" if args.quick else f" --pairs {args.pairs}")
    write_report(rows, out, cmd, time.perf_counter() - t0)
    print(f"wrote {out}")
    return out


if __name__ == "__main__":
    main()
