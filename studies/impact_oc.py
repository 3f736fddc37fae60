"""Optimal control where impacts can pay: fast starts near the wall, targets near the
wall, single-input problems over horizons long enough to be feasible, and a multi-start search over
impact sequences seeded from the certified witnesses.

    python -m studies.impact_oc [--quick] [--pairs 10] [--seed 0] [--workers 1] [--out docs/optimal_control.md]
                                 [--runs runs/impact_oc] [--report-only]
    python -m studies.impact_oc --recertify  # replay docs/optimal_control_certificates.json with the margin rule

The problems are those of studies/optimal_control.py (the same ``Problem``, shooting, SLSQP with exact
derivatives through impacts, and the same verification by simulating the torques again), on a new
distribution of start/target pairs (:func:`draw_pairs`, the same pairs for every actuation of a table):

* start: the contact point 2-5 cm inside the wall (along a ray from the centre), heading at the wall
  (within 45 degrees of the wall's outward normal there), rolling at 0.05-0.15 m/s (``SPEED``; the probes
  and the environments start at most 0.05 m/s); phi_dot as the scene draws it, in [-1, 1] rad/s;
* target: 1.7-3.5 cm inside the wall at a uniformly drawn ray (so it may lie behind the start).

Both ends start at least ``margin`` off the wall and the target at least margin + R, so the impacts-forbidden
problem is defined on every pair. Per actuation (the probes' tasks, docs/witnesses.md):

* both controls, park: minimum time (horizon ``HORIZON['both']`` rows) and minimum effort (``EFFORT_ROWS``);
* steer only, park: minimum time. Without impacts theta_dot is conserved (theorem T2 of
  docs/controllability_theory.md), so from a rolling start the task is infeasible without impacts: reported
  as "infeasible (T2)", not solved;
* drive only, reach: minimum time. Without impacts phi_dot is conserved (T3); with phi_dot != 0 the heading
  turns and the task can be feasible without impacts, so both variants are solved.

Feasibility first: the witness of studies/witness.py (the probe's controller family, searched on the
package's vector env from the pair's exact start) is run as an episode of the probe's environment
(``gymnasium.make(PennyProbe{Steer,Drive,Both}-<Table>-Elastic-v0)``, reset with the pair's state and
target): success certifies the pair feasible with impacts, its step count bounds the minimum time, and its
actions (the piecewise-constant torques) are replayed on the optimal-control problem (``replay``) and seed
the solver. The horizon of both variants is max(HORIZON[actuation], the witness's steps).

Each variant's best solution is a multi-start search:

* impacts forbidden: zero torques and ``random_starts`` random sequences at the horizon;
* impacts allowed: the witness's torques (its replay and an SLSQP solve from it), the impacts-forbidden
  optimum (feasible here too: it never touches the wall), zero torques and random sequences; every start
  lands on its own impact sequence, so the starts search over impact sequences.

Minimum time: every verified solution is cut at the first control row whose end is in the terminal set; the
best solution of each impact count is kept, and those of the ``SHORTEN_SEQUENCES`` best counts are shortened
(:func:`shorten`: one solve at K - step rows warm-started from the solution cut to K - step rows, step K // 4
halved after each failure, at most ``budget`` solves; a horizon fails when SLSQP does not converge into the
set), so that a plan with impacts that starts slower than the impact-free optimum still gets shortened.
Steer only, whose horizons reach hundreds of rows through many impacts, uses fewer and shorter solves
(``STEER_SOLVER``). Minimum effort: the best of the starts at EFFORT_ROWS rows.

Impacts pay on a pair when the best solution with impacts hits the wall and beats the best impact-free plan
found by more than ``MARGIN`` (relative), or when no impact-free plan exists by theorem (steer only: T2). A
solver failure of the impact-free search is not evidence: such pairs are counted in their own column ("impact-free
solve failed"), never as paying. Both are local searches: "beats" shows a better plan with impacts; no gap does
not prove that none exists, and a pair infeasible in both is reported as such ("neither"), never dropped.
Certified (minimum time): the plan with impacts reaches the set in fewer rows than the lower bound of
studies/oc_bounds.py allows every impact-free plan (drive only: the exact fewest rows of the open plane, a zonotope;
both controls: a validated directional bound), so it beats every impact-free plan, found or not; the certified plans
are replayed as episodes of the probe's environment (:func:`env_replay`). The open plane is not studied: it has no wall, so
no impact can happen there and both variants are the same problem.
"""
from __future__ import annotations

import math
import pickle
import sys
import time
from pathlib import Path

import numpy as np

import penny_env as pe
from studies.optimal_control import (EFFORT_ROWS, DEFAULT_MARGIN, Problem, Solution, dense_clearance, draw_plans,
                                      scene_table, solve_rows)

SCENES = ("ellipse", "stadium")
ACTUATIONS = ("both", "steer", "drive")
TASK = {"both": "park", "steer": "park", "drive": "reach"}
PROBE = {"both": "Both", "steer": "Steer", "drive": "Drive"}
TABLE_ID = {"ellipse": "Ellipse", "stadium": "Stadium"}
OBJECTIVES = {"both": ("time", "effort"), "steer": ("time",), "drive": ("time",)}
HORIZON = {"both": 40, "steer": 300, "drive": 120}   # rows (x 0.05 s): the default minimum-time horizons
SPEED = (0.05, 0.15)       # [m/s] initial rolling speed |R theta_dot|
START_GAP = (0.02, 0.05)   # [m] start contact point inside the wall, along the ray from the centre
TARGET_GAP = (0.017, 0.035)  # [m] target inside the wall, along the ray
HEADING_SPREAD = math.pi / 4  # start heading within this of the wall's outward normal
STEER_SOLVER = {"maxiter": 30, "random_starts": 1, "budget": 2}  # steer only: fewer, shorter solves
SHORTEN_SEQUENCES = 2     # minimum time: the best solutions of this many impact counts are shortened
MARGIN = 0.05              # relative: "with impacts beats without" when lower by more than this
ROOT = Path(__file__).resolve().parent.parent


def check_choice(name, value, allowed):
    if value not in allowed:
        raise ValueError(f"{name} must be one of {tuple(allowed)}, got {value!r}")


# -- the pairs ------------------------------------------------------------------------------------------
def draw_pairs(scene, n, seed, margin=DEFAULT_MARGIN):
    """n (start, target) pairs of the module docstring's distribution on a table, kept where impacts can
    be forbidden (both ends margin off the wall, target margin + R off it) for every actuation."""
    check_choice("scene", scene, SCENES)
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"pairs must be a positive integer, got {n!r}")
    table = scene_table(scene)
    R = Problem(scene, "park", np.zeros(6), np.zeros(2), impacts=True).params.R
    rng = np.random.default_rng(seed)
    pairs = []
    while len(pairs) < n:
        a = rng.uniform(-math.pi, math.pi)
        c, s = math.cos(a), math.sin(a)
        rho = float(table.wall_distance(c, s))
        g = np.asarray(table.grad(rho * c, rho * s), dtype=float)
        normal = math.atan2(g[1], g[0])
        d = rng.uniform(*START_GAP)
        phi = normal + rng.uniform(-HEADING_SPREAD, HEADING_SPREAD)
        speed = rng.uniform(*SPEED)
        start = np.array([(rho - d) * c, (rho - d) * s, rng.uniform(-math.pi, math.pi), phi, speed / R,
                          rng.uniform(-1.0, 1.0)])
        b = rng.uniform(-math.pi, math.pi)
        rb = float(table.wall_distance(math.cos(b), math.sin(b))) - rng.uniform(*TARGET_GAP)
        target = np.array([rb * math.cos(b), rb * math.sin(b)])
        try:
            for task in ("park", "reach"):
                Problem(scene, task, start, target, impacts=False, margin=margin)
        except ValueError:
            continue
        pairs.append((start, target))
    return pairs


# -- witnesses: feasibility certificates and seeds --------------------------------------------------------
_WITNESSES = {}


def probe_id(scene, actuation):
    return f"PennyProbe{PROBE[actuation]}-{TABLE_ID[scene]}-Elastic-v0"


def check_probe_matches(scene, actuation):
    """'' if the probe env poses the optimal-control problem (table, law, params, torque limits, control_dt,
    tolerances), else the first field that differs."""
    import dataclasses
    from penny_env.envs.scene import env_presets, resolve

    oc_sc, oc_tk = resolve(scene, TASK[actuation])
    sc, tk = resolve(**env_presets()[probe_id(scene, actuation)])
    for name in ("table", "law", "torque_limits", "control_dt", "params"):
        a, b = getattr(oc_sc, name, None), getattr(sc, name, None)
        if dataclasses.is_dataclass(a):
            a, b = dataclasses.asdict(a), dataclasses.asdict(b)
        if a != b:
            return f"scene field {name}: {a!r} here, {b!r} in the probe"
    for name in ("kind", "tolerance", "speed_tolerance"):
        if getattr(oc_tk, name, None) != getattr(tk, name, None):  # (speed_tolerance: a park task's field)
            return f"task field {name}: {getattr(oc_tk, name, None)!r} here, {getattr(tk, name, None)!r} in the probe"
    return ""


def witness(scene, actuation, start, target):
    """The witness of a pair: {"certified", "steps", "impacts", "v" (steps, 2) scaled torques or None,
    "reason"}: searched on the vector env, then run as one episode of the probe env from the pair."""
    from studies.witness import Witness, _act

    key = (scene, actuation)
    if key not in _WITNESSES:
        why = check_probe_matches(scene, actuation)
        if why:
            raise ValueError(f"{probe_id(scene, actuation)} is another problem: {why}")
        _WITNESSES[key] = Witness(probe_id(scene, actuation))
    w = _WITNESSES[key]
    idx, diag = w.search(np.asarray(start, float), np.asarray(target, float))
    if idx is None:
        return {"certified": False, "steps": 0, "impacts": 0, "v": None, "reason": w.why(diag)}
    ctrl = w.family(w.core, w.cands[idx:idx + 1])
    env = w.env
    obs, _ = env.reset(options={"state": np.asarray(start, float), "target": np.asarray(target, float)})
    u = env.unwrapped
    impacts, n_imp, actions = np.zeros(1, np.int64), 0, []
    while True:
        a = _act(ctrl, u.state[None, :], u.target[None, :], impacts, obs[None, :])[0]
        actions.append(np.asarray(a, float))
        obs, _, term, trunc, info = env.step(a)
        impacts = np.array([info["impacts"]], np.int64)
        n_imp += int(info["impacts"])
        if term or trunc:
            break
    ok = bool(info["is_success"])
    acts = np.array(actions)
    v = np.zeros((len(acts), 2))
    if actuation == "both":
        v[:] = acts
    else:
        v[:, 0 if actuation == "steer" else 1] = acts[:, 0]
    return {"certified": ok, "steps": len(acts), "impacts": n_imp, "v": v if ok else None,
            "reason": "" if ok else "the searched candidate failed in the real episode"}


# -- solving --------------------------------------------------------------------------------------------
def in_set(prob, states):
    """Boolean per state (rows of (n, 6)): in the terminal set of the problem."""
    states = np.atleast_2d(states)
    d = np.hypot(states[:, 0] - prob.target[0], states[:, 1] - prob.target[1])
    ok = d <= prob.tolerance * (1 + 1e-6)  # the same slack as solve_rows' verification (SLSQP ends on the edge)
    if prob.task == "park":
        ok &= np.abs(prob.params.R * states[:, 4]) <= prob.speed_tolerance * (1 + 1e-6)
    return ok


def replay(prob, v, first=True):
    """The solution given by scaled torques v (K, 2), verified by simulation like solve_rows' solves; first:
    cut at the first row whose end is in the terminal set (a minimum-time solution stops there)."""
    t0 = time.perf_counter()
    v = np.clip(np.asarray(v, float), -1.0, 1.0) * (prob.limits > 0)[None, :]

    def run(vv):
        u = vv * prob.limits[None, :]
        return u, pe.simulate(prob.start, params=prob.params, table=prob.table, law=prob.law, controls=u,
                              control_dt=prob.dt)
    u, tr = run(v)
    K = len(v)
    if first:
        ends = tr.states_at(prob.dt * np.arange(1, K + 1))
        hit = np.flatnonzero(in_set(prob, ends))
        if hit.size and hit[0] + 1 < K:
            u2, tr2 = run(v[:hit[0] + 1])
            if in_set(prob, tr2.final_state)[0]:
                v, u, tr, K = v[:hit[0] + 1], u2, tr2, hit[0] + 1
    dist = float(np.hypot(*(tr.final_state[:2] - prob.target)))
    status = "optimal"
    if not in_set(prob, tr.final_state)[0]:
        status = f"failed: replay ends {dist:.4g} m from the target" + (
            "" if prob.task == "reach" else f", rolling at {abs(prob.params.R * tr.final_state[4]):.3g} m/s")
    elif not prob.impacts and tr.n_impacts:
        status = f"failed: replay hits the wall {tr.n_impacts} times"
    elif not prob.impacts and prob.margin > 0 and dense_clearance(prob, tr) < 0.5 * prob.margin:
        status = "failed: replay comes closer than half the margin to the wall"
    nv = v.size
    return Solution(status, K, float((v * v).sum()) / nv, u, tr.n_impacts, dist, prob.dt, time.perf_counter() - t0, tr)


def _scaled(prob, sol):
    return sol.controls / np.where(prob.limits > 0, prob.limits, 1.0)[None, :]


def _better(a, b, objective):
    """a strictly better than b (None counts as worst)."""
    if a is None or not a.ok:
        return False
    if b is None or not b.ok:
        return True
    if objective == "time":
        return (a.rows, a.effort) < (b.rows, b.effort)
    return a.effort < b.effort


def shorten(prob, best, maxiter, budget, max_rows):
    """Fewer rows from a feasible minimum-time solution (module docstring): (best, solves)."""
    step, n = max(1, best.rows // 4), 0
    while step >= 1 and best.rows > 1 and n < budget:
        K = max(1, best.rows - step)
        sol = solve_rows(prob, K, x0=_scaled(prob, best)[:K], maxiter=maxiter, max_rows=max_rows)
        n += 1
        if sol.ok:
            cut = replay(prob, _scaled(prob, sol))
            best = cut if cut.ok and cut.rows <= sol.rows else sol
        else:
            step //= 2
    return best, n


def multistart(prob, objective, seeds, horizon, maxiter, random_starts, rng, budget):
    """The best verified solution over the seeds [(name, v (K, 2) or None for zeros at the horizon, replay
    it too?)] and random_starts random sequences; minimum time: then shortened. (best or the last failure,
    the name of the start it came from, solves)."""
    active = (prob.limits > 0)[None, :]
    starts = list(seeds) + [(f"random {i}", rng.uniform(-1.0, 1.0, (horizon, 2)) * active, False)
                            for i in range(random_starts)]
    found, last, solves = {}, None, 0  # impact count -> (best solution with that many impacts, its start)

    def keep(sol, name):
        if _better(sol, found.get(sol.impacts, (None,))[0], objective):
            found[sol.impacts] = (sol, name)
    for name, v, also_replay in starts:
        v = np.zeros((horizon, 2)) if v is None else np.asarray(v, float)
        if objective == "effort":
            v = np.vstack([v, np.zeros((max(0, horizon - len(v)), 2))])[:horizon]
        if also_replay:
            keep(replay(prob, v, first=objective == "time"), f"{name} (replayed)")
        sol = solve_rows(prob, len(v), x0=v, maxiter=maxiter, max_rows=max(horizon, len(v)))
        solves += 1
        last = sol
        if sol.ok and objective == "time":
            cut = replay(prob, _scaled(prob, sol))
            sol = cut if cut.ok and cut.rows <= sol.rows else sol
        keep(sol, name)
    if not found:
        return last, "", solves
    if objective == "time":  # shorten the best of each impact count (the SHORTEN_SEQUENCES best counts)
        ranked = sorted(found.values(), key=lambda p: (p[0].rows, p[0].effort))[:SHORTEN_SEQUENCES]
        found = {}
        for sol, name in ranked:
            short, n = shorten(prob, sol, maxiter, budget, max(horizon, sol.rows))
            solves += n
            if _better(short, found.get(0, (None,))[0], objective):
                found[0] = (short, name)
    best, source = min(found.values(), key=lambda p: (p[0].rows, p[0].effort) if objective == "time" else p[0].effort)
    return best, source, solves


def value(sol, objective):
    if sol is None or not sol.ok:
        return math.nan
    return sol.rows * sol.dt if objective == "time" else sol.effort


def solve_pair(job):
    """Every objective of one (scene, pair, actuation): the witness, then impacts forbidden, then allowed."""
    scene, i, start, target, actuation, cfg = job
    t0 = time.perf_counter()
    task = TASK[actuation]
    wit = witness(scene, actuation, start, target) if cfg["witness"] else {
        "certified": False, "steps": 0, "impacts": 0, "v": None, "reason": "witness not run"}
    rows = []
    for objective in OBJECTIVES[actuation]:
        if objective not in cfg["objectives"]:
            continue
        rng = np.random.default_rng([cfg["seed"], i, ACTUATIONS.index(actuation)])
        horizon = EFFORT_ROWS if objective == "effort" else max(cfg["horizon"][actuation], wit["steps"])
        kw = dict(maxiter=cfg["maxiter"], random_starts=cfg["random_starts"], rng=rng, budget=cfg["budget"])
        if actuation == "steer":  # long chaotic horizons: each solve costs seconds (module docstring)
            kw.update({k: min(v, kw[k]) for k, v in STEER_SOLVER.items()})
        without_p = Problem(scene, task, start, target, impacts=False, actuation=actuation)
        with_p = Problem(scene, task, start, target, impacts=True, actuation=actuation)
        R = with_p.params.R
        if actuation == "steer" and abs(R * start[4]) > with_p.speed_tolerance:
            without = Solution("infeasible (T2): without impacts |R theta_dot| stays "
                               f"{abs(R * start[4]):.3g} m/s > {with_p.speed_tolerance:g}", 0, math.nan,
                               np.zeros((0, 2)), 0, math.nan, with_p.dt, 0.0)
            wo_src, wo_solves = "theorem T2", 0
        else:
            without, wo_src, wo_solves = multistart(without_p, objective, [("zero", None, False)], horizon, **kw)
        seeds = []
        if wit["certified"]:
            seeds.append(("witness", wit["v"], True))
        if without.ok:
            seeds.append(("impact-free optimum", _scaled(without_p, without), True))
        if not (actuation == "steer" and wit["certified"]):
            seeds.append(("zero", None, False))
        with_, w_src, w_solves = multistart(with_p, objective, seeds, horizon, **kw)
        if not cfg["keep_traj"]:
            for s in (with_, without):
                s.traj = None if s is not None and not s.ok else s.traj
        rows.append({"scene": scene, "pair": i, "actuation": actuation, "task": task, "objective": objective,
                     "start": np.asarray(start, float), "target": np.asarray(target, float), "horizon": horizon,
                     "witness": {k: v for k, v in wit.items() if k != "v"}, "with": with_, "without": without,
                     "with_source": w_src, "without_source": wo_src, "solves": w_solves + wo_solves,
                     "seconds": time.perf_counter() - t0})
    return rows


def infeasible_by_theorem(sol) -> bool:
    """The impact-free variant has no plan at all by a theorem (steer only: T2), as opposed to a solver failure."""
    return sol.status.startswith("infeasible (T")


def solve_failed(sol) -> bool:
    return sol.status.startswith("failed")


def pays(row, margin=MARGIN):
    """Impacts pay on this row: the best with impacts hits the wall and beats the best impact-free plan found by more
    than margin (relative), or no impact-free plan exists by theorem. A failed impact-free solve never counts."""
    w, wo = row["with"], row["without"]
    if not w.ok or w.impacts == 0:
        return False
    if infeasible_by_theorem(wo):
        return True
    if not wo.ok:
        return False
    a, b = value(w, row["objective"]), value(wo, row["objective"])
    return a < (1.0 - margin) * b


_BOUNDS: dict = {}


def lower_bound(row):
    """(rows, reason) of studies/oc_bounds.rows_lower_bound for the row's impact-free problem (minimum time), computed
    once per problem (the both-controls bound runs a validated dynamic programme per row count)."""
    from studies.oc_bounds import rows_lower_bound

    key = (row["scene"], row["task"], row["actuation"], np.asarray(row["start"], float).tobytes(),
           np.asarray(row["target"], float).tobytes())
    if key not in _BOUNDS:
        prob = Problem(row["scene"], row["task"], row["start"], row["target"], impacts=True,
                       actuation=row["actuation"])
        _BOUNDS[key] = rows_lower_bound(prob, row["actuation"])
    return _BOUNDS[key]


REPLAY_MARGIN = 1e-9  # [m, m/s] a replay counts only if it ends this far inside the env's success set


def end_margin(env) -> float:
    """How far inside its task's success set an env's state is: tolerance - d, and for park also speed_tolerance -
    |R theta_dot| (the smaller). Computed in float64 from the state, whose rounding (about 1e-17 m) is far below
    REPLAY_MARGIN: a positive margin above it is a success that no rounding of the end can undo."""
    u = env.unwrapped
    s, task = u.state, u.task
    m = task.tolerance - math.hypot(s[0] - u.target[0], s[1] - u.target[1])
    if task.kind == "park":
        m = min(m, task.speed_tolerance - abs(u.scene.make_params().R * s[4]))
    return float(m)


def env_replay(row, v=None):
    """(is_success, steps, impacts, margin): the plan with impacts (scaled torques v, default the row's) replayed as an
    episode of the probe's environment reset with the pair's start and target, success as in the optimal-control
    problem (park: position and rolling speed; the probe's spin tolerance, which the problem does not pose, is switched
    off), and :func:`end_margin` at its last step. The env's success is strict (d < tolerance) where the problem allows
    1e-6 of slack, so an episode misses, or meets by a rounding, a minimum-time plan that ends on the edge of the set:
    :func:`env_certified_plan` moves it inside."""
    import gymnasium as gym

    kw = {"spin_tolerance": None} if TASK[row["actuation"]] == "park" else {}
    env = gym.make(probe_id(row["scene"], row["actuation"]), **kw)
    try:
        env.reset(options={"state": np.asarray(row["start"], float), "target": np.asarray(row["target"], float)})
        prob = Problem(row["scene"], row["task"], row["start"], row["target"], impacts=True, actuation=row["actuation"])
        v = _scaled(prob, row["with"]) if v is None else np.asarray(v, float)
        n_imp = 0
        for i, a in enumerate(v, 1):
            act = a if row["actuation"] == "both" else a[[0 if row["actuation"] == "steer" else 1]]
            _, _, term, trunc, info = env.step(np.asarray(act, np.float64))
            n_imp += int(info["impacts"])
            if term or trunc:
                return bool(info["is_success"]), i, n_imp, end_margin(env)
        return False, len(v), n_imp, end_margin(env)
    finally:
        env.close()


INSIDE = 1e-3  # the re-solve's margin inside the terminal set (relative), for the env's strict success test
_ENV_PLANS: dict = {}


def env_certified_plan(row):
    """(scaled torques, is_success, steps, impacts, how, margin): the certified row's plan with impacts as an episode of
    the probe's environment. Computed once per row by :func:`inside_plan`."""
    key = (row["scene"], row["actuation"], np.asarray(row["start"], float).tobytes(),
           np.asarray(row["target"], float).tobytes(), np.asarray(row["with"].controls, float).tobytes())
    if key not in _ENV_PLANS:
        prob = Problem(row["scene"], row["task"], row["start"], row["target"], impacts=True,
                       actuation=row["actuation"])
        _ENV_PLANS[key] = inside_plan(row, prob, _scaled(prob, row["with"]))
    return _ENV_PLANS[key]


def inside_plan(row, prob, v):
    """(scaled torques, is_success, steps, impacts, how, margin): the plan v replayed in the probe's environment; it
    counts (is_success True) only if the episode succeeds with its end at least REPLAY_MARGIN inside the success set.
    A minimum-time plan ends on the edge of the set, which the env's strict test can miss or meet by a rounding; then
    the package's optimizer (solve_rows, SLSQP) re-solves the same rows from it into the set shrunk by INSIDE, and that
    plan, verified again by simulation, hitting the wall, is replayed."""
    from studies.optimal_control import solve_rows

    ok, steps, n_imp, margin = env_replay(row, v)
    how = "the plan as found"
    if not (ok and margin >= REPLAY_MARGIN):
        prob.tolerance *= 1.0 - INSIDE
        prob.speed_tolerance *= 1.0 - INSIDE
        K = len(v)
        sol = solve_rows(prob, K, x0=v, maxiter=100, max_rows=max(K, 40))
        how = (f"re-solved {100 * INSIDE:g} % inside the set ({'no success' if not ok else f'ended {margin:.1e} inside'}"
               f" as found): {sol.status.split(':')[0]}")
        if sol.ok and sol.impacts > 0:
            v = _scaled(prob, sol)
            ok, steps, n_imp, margin = env_replay(row, v)
    return v, bool(ok and margin >= REPLAY_MARGIN), steps, n_imp, how, margin


def recertify(path):
    """Replay every plan of a certificates file (write_certificates) in the probe's environment with the margin rule of
    :func:`inside_plan`, re-solving inside the set the plans that end within REPLAY_MARGIN of its edge; rewrite the
    file with each replay's margin. The pairs, bounds and rows are kept (a re-solve keeps the rows)."""
    import json

    certs = json.loads(path.read_text())
    for c in certs:
        row = {k: c[k] for k in ("scene", "actuation", "task", "start", "target")}
        prob = Problem(c["scene"], c["task"], c["start"], c["target"], impacts=True, actuation=c["actuation"])
        v, ok, steps, n_imp, how, margin = inside_plan(row, prob, np.asarray(c["plan"], float))
        if how != "the plan as found":
            c["plan_from"] = how
        c.update({"plan": np.asarray(v).tolist(), "env_success": ok, "env_steps": int(steps),
                  "env_impacts": int(n_imp), "env_margin": float(margin)})
    path.write_text(json.dumps(certs, indent=1) + "\n")
    return certs


def recertify_report(report, certs) -> int:
    """Rewrite, in the report's list of certified pairs, how each re-solved plan was obtained (the line's
    "(the plan as found)" becomes the certificate's plan_from); the number of lines changed."""
    lines, changed = report.read_text().split("\n"), 0
    for c in certs:
        head = f"  - {c['scene']} pair {c['pair']}, {LABEL[c['actuation']]}:"
        for i, line in enumerate(lines):
            if line.startswith(head) and "(the plan as found)" in line and c["plan_from"] != "the plan as found":
                lines[i] = line.replace("(the plan as found)", f"({c['plan_from']})")
                changed += 1
    report.write_text("\n".join(lines))
    return changed


def certified(row) -> bool:
    """Minimum time: the plan with impacts hits the wall and needs fewer rows than every impact-free plan can
    (the certified lower bound; for steer only, no impact-free plan exists)."""
    w = row["with"]
    if row["objective"] != "time" or not w.ok or w.impacts == 0 or infeasible_by_theorem(row["without"]):
        return False  # (steer only: no impact-free plan exists at all; that is feasibility, reported as such)
    return w.rows < lower_bound(row)[0]


def impact_free_optimal(row) -> bool:
    """Minimum time: the best impact-free plan found needs exactly the lower bound's rows, so it is a minimum-time
    impact-free plan (certified optimal among impact-free plans)."""
    wo = row["without"]
    return (row["objective"] == "time" and row["actuation"] != "steer" and wo.ok
            and wo.rows == lower_bound(row)[0])


# -- the study ------------------------------------------------------------------------------------------
def study(n_pairs, seed=0, scenes=SCENES, actuations=ACTUATIONS, objectives=("time", "effort"), workers=1,
          horizon=None, maxiter=100, random_starts=2, budget=8, witness=True, progress=True, keep_traj=True):
    for sc in scenes:
        check_choice("scene", sc, SCENES)
    for act in actuations:
        check_choice("actuation", act, ACTUATIONS)
    for ob in objectives:
        check_choice("objective", ob, ("time", "effort"))
    if isinstance(n_pairs, bool) or not isinstance(n_pairs, (int, np.integer)) or n_pairs < 1:
        raise ValueError(f"pairs must be a positive integer, got {n_pairs!r}")
    cfg = {"seed": seed, "horizon": dict(HORIZON, **(horizon or {})), "maxiter": maxiter,
           "random_starts": random_starts, "budget": budget, "witness": witness, "objectives": objectives,
           "keep_traj": keep_traj}
    jobs = [(sc, i, s, t, act, cfg) for sc in scenes for i, (s, t) in enumerate(draw_pairs(sc, n_pairs, seed))
            for act in actuations]
    out = []
    if workers > 1:
        from concurrent.futures import ProcessPoolExecutor
        with ProcessPoolExecutor(workers) as pool:
            results = pool.map(_solve_or_record, jobs)
            for rows in results:
                out += _progress(rows, progress)
    else:
        for job in jobs:
            out += _progress(_solve_or_record(job), progress)
    return out


def _solve_or_record(job):
    """solve_pair, or (an unexpected error in a pair) rows whose solves are failed with the error: reported,
    never dropped, and the other pairs still run."""
    try:
        return solve_pair(job)
    except Exception as exc:  # noqa: BLE001 - recorded in the report's every-pair table
        scene, i, start, target, actuation, cfg = job
        bad = Solution(f"failed: error {type(exc).__name__}: {exc}", 0, math.nan, np.zeros((0, 2)), 0, math.nan, 0.05, 0.0)
        return [{"scene": scene, "pair": i, "actuation": actuation, "task": TASK[actuation], "objective": ob,
                 "start": np.asarray(start, float), "target": np.asarray(target, float), "horizon": 0,
                 "witness": {"certified": False, "steps": 0, "impacts": 0, "reason": "error"}, "with": bad,
                 "without": bad, "with_source": "", "without_source": "", "solves": 0, "seconds": 0.0}
                for ob in OBJECTIVES[actuation] if ob in cfg["objectives"]]


def _progress(rows, progress):
    if progress:
        for r in rows:
            ob = r["objective"]
            print(f"{r['scene']} #{r['pair']} {r['actuation']} min {ob}: witness "
                  f"{'%d steps' % r['witness']['steps'] if r['witness']['certified'] else 'none'}; with "
                  f"{r['with'].status.split(':')[0]} {value(r['with'], ob):.4g} ({r['with'].impacts} impacts, "
                  f"{r['with_source']}), without {r['without'].status.split(':')[0]} {value(r['without'], ob):.4g}"
                  f"; pays {pays(r)} [{r['seconds']:.0f} s]", file=sys.stderr, flush=True)
    return rows


def summarise(rows, margin=MARGIN):
    """Per (actuation, objective), pooled over the tables, and per table: the counts of the report."""
    from lab.stats import clopper_pearson

    out = []
    keys = []
    for r in rows:
        for sc in (r["scene"], "all"):
            k = (r["actuation"], r["objective"], sc)
            if k not in keys:
                keys.append(k)
    keys.sort(key=lambda k: (ACTUATIONS.index(k[0]), k[1] != "time", k[2] != "all", k[2]))
    for act, ob, sc in keys:
        sel = [r for r in rows if r["actuation"] == act and r["objective"] == ob and sc in ("all", r["scene"])]
        n = len(sel)
        k = sum(pays(r, margin) for r in sel)
        both = [r for r in sel if r["with"].ok and r["without"].ok]
        gaps = [(value(r["without"], ob) - value(r["with"], ob)) / value(r["without"], ob) for r in both
                if pays(r, margin)]
        lo, hi = clopper_pearson(k, n)
        out.append({"actuation": act, "objective": ob, "scene": sc, "pairs": n,
                    "witnessed": sum(r["witness"]["certified"] for r in sel),
                    "without_failed": sum(solve_failed(r["without"]) for r in sel),
                    "only_with_failed": sum(r["with"].ok and r["with"].impacts > 0 and solve_failed(r["without"])
                                            for r in sel),
                    "certified": sum(certified(r) for r in sel),
                    "certified_env": sum(certified(r) and env_certified_plan(r)[1] for r in sel),
                    "feasible_without": sum(r["without"].ok for r in sel),
                    "feasible_with": sum(r["with"].ok for r in sel),
                    "neither": sum(not r["with"].ok and not r["without"].ok for r in sel),
                    "with_hits_wall": sum(r["with"].ok and r["with"].impacts > 0 for r in sel),
                    "pays": k, "ci": (lo, hi),
                    "pays_both_feasible": sum(pays(r, margin) for r in both), "both_feasible": len(both),
                    "pays_only_with": sum(pays(r, margin) for r in sel if infeasible_by_theorem(r["without"])),
                    "mean_gap": float(np.mean(gaps)) if gaps else math.nan,
                    "without_better": sum(value(r["without"], ob) < (1 - margin) * value(r["with"], ob) for r in both),
                    "from_witness": sum(r["with"].ok and r["with_source"].startswith("witness") for r in sel)})
    return out


def notes(rows) -> list[str]:
    """Where no plan was found: the starting rolling speeds of those pairs against all pairs' (computed)."""
    out = []
    for act in ACTUATIONS:
        sel = [r for r in rows if r["actuation"] == act and r["objective"] == "time"]
        bad = [r for r in sel if not r["with"].ok and not r["without"].ok]
        if sel and bad:
            v = [0.01 * abs(r["start"][4]) for r in bad]  # R = 0.01 m
            allv = [0.01 * abs(r["start"][4]) for r in sel]
            out.append(f"{LABEL[act].capitalize()}, minimum time: no plan found in {len(bad)} of {len(sel)} pairs, "
                       f"starting at {min(v):.3f}-{max(v):.3f} m/s (all pairs: {min(allv):.3f}-{max(allv):.3f} m/s); "
                       "the witness family found no impact sequence that left the penny slow at the target (the every-pair "
                       "table's witness column says which success condition its episodes never met), and the solver's "
                       "zero and random starts found nothing either (not a proof of infeasibility)." if act == "steer" else "")
    return [x for x in out if x]


LABEL = {"both": "both controls, park", "steer": "steer only, park", "drive": "drive only, reach"}


README_BEGIN = "<!-- oc-answer: written by python -m studies.impact_oc -->"
README_END = "<!-- /oc-answer -->"


def overall(summary) -> list:
    """(row, interval's low, high) of the summary's rows over all tables."""
    return [(s, *s["ci"]) for s in summary if s["scene"] == "all"]


def readme_block(summary, margin=MARGIN) -> str:
    """The README's answer: per actuation and objective the paying, failed and certified counts (from the summary)."""
    bits = []
    for s, lo, hi in overall(summary):
        if s["actuation"] == "steer":
            bits.append(f"steer-only park: no impact-free plan exists (theorem T2), a plan with impacts was found in "
                        f"{s['feasible_with']}/{s['pairs']} pairs (feasibility, not optimality)")
            continue
        cert = (f", certified in {s['certified']} ({s.get('certified_env', 0)} replayed as successful env episodes)"
                if s["objective"] == "time" else "")
        bits.append(f"{LABEL[s['actuation']]}, minimum {s['objective']}: impacts pay in {s['pays']}/{s['pairs']} "
                    f"(exact 95 % interval {lo:.2f} to {hi:.2f}){cert}, the impact-free solve failed in "
                    f"{s['without_failed']}")
    n = summary[0]["pairs"] if summary else 0
    return (f"On the elastic ellipse and stadium ({n} pairs per actuation and objective), the best plan with impacts "
            f"hits the wall and beats the best impact-free plan found by more than {100 * margin:.0f} %: "
            + "; ".join(bits) + ". Failed impact-free solves are a column of their own, never counted as paying. "
            "Certified: the plan with impacts reaches the target in fewer control steps than a validated lower bound "
            "(studies/oc_bounds.py: the exact fewest drive-only steps without impacts, a directional bound with both "
            "controls) allows any impact-free plan. The searches are local: a paying pair shows that a better plan "
            "with impacts exists, not that none without does, and no plan with impacts is shown optimal.")


def answer(summary, margin=MARGIN) -> list[str]:
    lines = []
    for s, lo, hi in overall(summary):
        if s["actuation"] == "steer":
            lines.append(
                f"- {LABEL[s['actuation']].capitalize()}, minimum {s['objective']}: feasibility, not optimality. No "
                f"impact-free plan exists (theorem T2: theta_dot is conserved without impacts), so every feasible plan "
                f"uses impacts: a plan with impacts was found in {s['feasible_with']} of {s['pairs']} pairs (witness "
                f"episodes in {s['witnessed']}), none in {s['neither']}; the plans found are not shown optimal.")
            continue
        cert = (f"; **certified** in {s['certified']} of {s['pairs']} (the plan with impacts needs fewer rows than the "
                f"lower bound of every impact-free plan; {s.get('certified_env', 0)} of them replayed as successful "
                "episodes of the probe's environment)" if s["objective"] == "time" else
                "; no certificate (no lower bound on the effort of impact-free plans is computed)")
        lines.append(
            f"- {LABEL[s['actuation']].capitalize()}, minimum {s['objective']}: impacts pay in {s['pays']} of "
            f"{s['pairs']} pairs ({100 * s['pays'] / s['pairs']:.0f} %, 95 % exact interval "
            f"[{100 * lo:.0f} %, {100 * hi:.0f} %]): the best plan found with impacts hits the wall and is more than "
            f"{100 * margin:.0f} % better than the best impact-free plan found, among the {s['both_feasible']} pairs "
            f"with both found{cert}. The impact-free solve failed in {s['without_failed']} pairs (its own column, "
            f"never counted as paying; in {s['only_with_failed']} of them a plan with impacts was found); feasible "
            f"without impacts {s['feasible_without']}, with impacts {s['feasible_with']} (witness episodes "
            f"{s['witnessed']}), neither {s['neither']}.")
    return lines


def certificates(rows) -> list[str]:
    """Lines: the minimum-time pairs whose plan with impacts beats the certified lower bound of every impact-free plan
    (both controls, drive only), each replayed as an episode of the probe's environment; then the pairs whose best
    impact-free plan attains the bound (certified optimal among impact-free plans)."""
    found, optimal = [], []
    for r in rows:
        if r["actuation"] == "steer" or r["objective"] != "time":
            continue
        k, why = lower_bound(r)
        if impact_free_optimal(r):
            optimal.append(f"{r['scene']} pair {r['pair']} ({LABEL[r['actuation']]}, {k * r['without'].dt:.3g} s)")
        if not certified(r):
            continue
        _, ok, steps, n_imp, how, _ = env_certified_plan(r)
        env = (f"replayed in {probe_id(r['scene'], r['actuation'])} ({how}): success at step {steps}, {n_imp} impacts"
               if ok else f"replayed in {probe_id(r['scene'], r['actuation'])} ({how}): no success (ended at step "
               f"{steps})")
        found.append(f"  - {r['scene']} pair {r['pair']}, {LABEL[r['actuation']]}: with impacts "
                     f"{r['with'].rows * r['with'].dt:.3g} s ({r['with'].rows} rows, {r['with'].impacts} impacts; "
                     f"{env}); every impact-free plan needs at least {k * r['with'].dt:.3g} s ({k} rows: {why})")
    out = (["Pairs where the plan with impacts is certified better than every impact-free plan (minimum time):", *found]
           if found else ["No pair where the plan with impacts beats the certified lower bound of every impact-free "
                          "plan."])
    if optimal:
        out += ["", "Impact-free plans found that attain the lower bound, hence minimum-time among impact-free plans "
                f"(certified): {'; '.join(optimal)}."]
    return out


def plot_examples(rows, path, n=4):
    """PNG of up to n pairs where impacts pay (one per actuation first); False without matplotlib."""
    try:
        import matplotlib
    except ImportError:  # optional extra: the report is written without the picture
        return False
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    picks, seen = [], set()
    paying = [r for r in rows if pays(r) and r["with"].traj is not None]
    for r in paying:
        if r["actuation"] not in seen:
            picks.append(r)
            seen.add(r["actuation"])
    picks += [r for r in paying if r not in picks][:max(0, n - len(picks))]
    picks = picks[:n]
    if not picks:
        return False
    fig, axes = plt.subplots(1, len(picks), figsize=(4 * len(picks), 4.4), squeeze=False)
    for ax, r in zip(axes[0], picks):
        ob = r["objective"]
        draw_plans(ax, r, 600, lambda key, sol: f"impacts {'allowed' if key == 'with' else 'forbidden'}: "
                                                f"{value(sol, ob):.3g}{' s' if ob == 'time' else ''}")
        s = r["start"]
        ax.annotate("", xy=(s[0] + 0.01 * math.cos(s[3]), s[1] + 0.01 * math.sin(s[3])), xytext=(s[0], s[1]),
                    arrowprops=dict(arrowstyle="->", color="g"))
        tol = Problem(r["scene"], r["task"], r["start"], r["target"], impacts=True).tolerance
        ax.plot(*r["target"], "k+", ms=6, label="target (tolerance circle)")
        ax.add_patch(plt.Circle(tuple(r["target"]), tol, fill=False, ec="k", lw=0.8))
        pts = np.vstack([np.vstack([ln.get_xydata() for ln in ax.lines[1:]]), [r["target"]]])
        c, half = (pts.max(0) + pts.min(0)) / 2, (pts.max(0) - pts.min(0)).max() / 2 + 0.02  # zoom on the plans
        ax.set_xlim(c[0] - half, c[0] + half)
        ax.set_ylim(c[1] - half, c[1] + half)
        ax.set_aspect("equal")
        ax.set_title(f"{r['scene']} #{r['pair']}: {LABEL[r['actuation']]}, min {ob}", fontsize=9)
        ax.legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


def write_report(rep, rows, argv, seconds, meta):
    """The report (rep.out; its figure and certificates beside it) from the solved rows; argv: the command line of
    the run that solved them (a --report-only rewrite keeps it)."""
    from lab.common import header

    out = rep.out
    summary = summarise(rows)
    png = rep.beside("_impacts.png")
    has_png = plot_examples(rows, png)
    n_pairs = meta["pairs"]
    lines = header("Optimal control where impacts can pay", "studies.impact_oc", argv)
    lines.insert(next(i for i, x in enumerate(lines) if x.startswith("- command:")) + 1,
                 f"- run: {seconds:.0f} s wall on {meta['workers']} worker process(es); {n_pairs} pairs per table "
                 f"({', '.join(meta['scenes'])}), the same pairs for every actuation; seed {meta['seed']}"
                 + (f"; this report rewritten on {meta['rewritten']} from the run's stored solves (--report-only)"
                    if meta.get("rewritten") else ""))
    lines += [
        "Issue 20, item 5. The earlier study ([optimal_control_central.md](optimal_control_central.md): slow "
        "starts, central targets, 2 s horizons) found that impacts never help; its pairs gave impacts no "
        "chance. Here the pairs are drawn where they can pay: fast starts near the wall heading at it, targets "
        "near the wall, single-input problems over horizons a certified witness shows feasible, and a multi-start "
        "search over impact sequences. Method and distribution: the docstring of `studies/impact_oc.py` "
        "(problems, shooting and verification of `studies/optimal_control.py`).", "",
        f"- start: contact point {100 * START_GAP[0]:.0f}-{100 * START_GAP[1]:.0f} cm inside the wall, heading "
        f"within 45 degrees of the wall's outward normal, rolling at {SPEED[0]:g}-{SPEED[1]:g} m/s, "
        "phi_dot in [-1, 1] rad/s; target 1.7-3.5 cm inside the wall at a uniform ray (it may lie behind the start);",
        f"- horizons (rows of 0.05 s): minimum time {HORIZON['both']} (both), {HORIZON['drive']} (drive only), "
        f"{HORIZON['steer']} (steer only), or the witness's episode length if longer; minimum effort "
        f"{EFFORT_ROWS} rows;",
        f"- starts: witness torques (replayed, and solved from), the impact-free optimum, zero torques and "
        f"{meta['random_starts']} random sequences; SLSQP at most {meta['maxiter']} iterations a solve, minimum time "
        f"shortened with at most {meta['budget']} further solves;",
        f"- impacts pay on a pair: the best plan with impacts hits the wall and is more than {100 * MARGIN:.0f} % "
        "lower (time or effort) than the best without, or it is the only feasible plan found;",
        "- the open plane: no wall, so no impact can happen; both variants are the same problem and impacts "
        "cannot pay there (not run).", "",
        "## Answer (computed from the table below)", "", *answer(summary), "",
        "Both searches are local (multi-start SLSQP): a pair where impacts pay shows a plan with impacts that beats "
        "every plan found without; the shares are lower bounds of the shares in the problem distribution only in "
        "so far as the impact-free searches found the impact-free optima. Certified pairs do not depend on that: "
        "their plan with impacts reaches the set in fewer rows than any impact-free plan can (studies/oc_bounds.py; "
        "an impact-free plan moves as on the open plane, so a bound for the plane holds on the table. Drive only: "
        "the heading turns at its constant rate, so the end point is affine in the torques and the K-row end "
        "points form a zonotope; the bound is the **exact** fewest rows of the plane, every smaller K certified "
        "unreachable in interval arithmetic (studies/drive_zonotope.py). Both controls: the heading lies in its "
        "reachable tube and the rolling speed obeys the torque limit; a dynamic programme over the rolling speed, "
        "rounded outward with the cosines in interval arithmetic, bounds the displacement along a direction, and "
        "a row count is excluded when some direction's bound falls short of the target (studies/both_bound.py). "
        "Both bounds ignore the wall, so they are lower bounds on the table.) Where the best impact-free plan found "
        "needs exactly the bound's rows it is a minimum-time impact-free plan. No plan with impacts is certified "
        "optimal: they are local optima, and no lower bound on plans with impacts is computed. Steer only: without "
        "impacts the task is infeasible by theorem T2 (theta_dot is conserved), so every feasible plan there uses "
        "impacts (feasibility, not optimality).", "",
        *certificates(rows), "",
        *notes(rows), "",
        "## Per actuation and table", "",
        "Pairs; feasible without / with impacts (a verified plan found); with impacts certified by the witness's "
        "episode; neither; best plan with impacts that hits the wall; impacts pay (share, 95 % exact "
        "Clopper-Pearson interval); of those, pairs feasible both ways and pairs feasible only with impacts; mean "
        "relative gain where both were feasible and impacts pay; pairs where the plan without impacts is the "
        "better by the margin; best plan with impacts that came from the witness's start. For minimum effort the "
        "witness certifies the task within its own episode, which is often longer than the effort horizon, not "
        "within that horizon.", "",
        "| actuation | objective | table | pairs | feasible without | impact-free solve failed | feasible with | "
        "witnessed | neither | with hits the wall | impacts pay [95 % CI] | pay, both feasible | pay, no impact-free "
        "plan (theorem) | certified (time) | mean gain | without better | best from witness |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|"]
    for s in summary:
        lo, hi = s["ci"]
        gap = "-" if math.isnan(s["mean_gap"]) else f"{100 * s['mean_gap']:.0f} %"
        lines.append(f"| {LABEL[s['actuation']]} | {s['objective']} | {s['scene']} | {s['pairs']} | "
                     f"{s['feasible_without']} | {s['without_failed']} | {s['feasible_with']} | {s['witnessed']} | "
                     f"{s['neither']} | {s['with_hits_wall']} | {s['pays']}/{s['pairs']} = {s['pays'] / s['pairs']:.2f} "
                     f"[{lo:.2f}, {hi:.2f}]{' (feasibility: T2)' if s['actuation'] == 'steer' else ''} | "
                     f"{s['pays_both_feasible']}/{s['both_feasible']} | "
                     f"{s['pays_only_with']} | "
                     f"{s['certified'] if s['objective'] == 'time' and s['actuation'] != 'steer' else '-'} | {gap} | "
                     f"{s['without_better']} | {s['from_witness']} |")
    if has_png:
        lines += ["", f"![where impacts pay]({png.name})", "",
                  "Pairs where impacts pay (the first of each actuation): the contact point's path of the best plan "
                  "found with impacts (solid; x: the contact point at each impact, the penny's edge touching the "
                  "wall 1 cm beyond) and without (dashed, where one was found); the start's heading arrow green, "
                  "the target's tolerance circle black."]
    lines += ["", "## Every pair", "",
              "Times in s, effort as mean (u / limit)^2; the start the best plan with impacts came from; failures "
              "with their reasons.", "",
              "| table | pair | actuation | objective | horizon | witness | without impacts | impact-free lower bound "
              "[s] | with impacts | impacts | best from | pays |", "|---|---:|---|---|---:|---|---|---:|---|---:|---|---|"]
    for r in sorted(rows, key=lambda r: (r["scene"], r["pair"], ACTUATIONS.index(r["actuation"]), r["objective"])):
        ob = r["objective"]

        def show(sol):
            return f"{value(sol, ob):.3g}" if sol.ok else sol.status.replace("|", "\\|")
        wit = (f"{r['witness']['steps']} steps, {r['witness']['impacts']} impacts" if r["witness"]["certified"]
               else r["witness"]["reason"].replace("|", "/"))
        lb = "-"
        if ob == "time":
            k, _ = lower_bound(r)
            lb = "none feasible" if k > 4000 else f"{k * r['with'].dt:.3g}"
        verdict = "certified" if certified(r) else (
            "feasible only with impacts (T2)" if pays(r) and infeasible_by_theorem(r["without"]) else
            "yes" if pays(r) else ("impact-free solve failed" if solve_failed(r["without"]) else "no"))
        lines.append(f"| {r['scene']} | {r['pair']} | {r['actuation']} | {ob} | {r['horizon']} | {wit} | "
                     f"{show(r['without'])} | {lb} | {show(r['with'])} | {r['with'].impacts if r['with'].ok else '-'} | "
                     f"{r['with_source'] or '-'} | {verdict} |")
    # minimum-time rows without an impact-free plan although the witness's certified episode had no impact
    unseeded = sum(1 for r in rows if not r['without'].ok and r['witness']['certified'] and r['witness']['impacts'] == 0
                   and r['objective'] == 'time')
    lines += ["", "## What waits", "",
              "- A plan with the impact count fixed per mode (multiple shooting with one segment per impact-free "
              "arc and the impact as a switching constraint) is not built: the multi-start above reaches different "
              "impact sequences only through its starts.",
              "- The impact-free search is not seeded from the witness. A witness episode without impacts (the "
              "both-controls feedback witness hit the wall in "
              f"{sum(r['witness']['impacts'] > 0 for r in rows if r['actuation'] == 'both' and r['objective'] == 'time')}"
              f" of its {sum(r['actuation'] == 'both' and r['objective'] == 'time' for r in rows)} episodes here) is an "
              "impact-free candidate if it keeps the margin: "
              f"{unseeded} "
              "minimum-time row(s) have no impact-free plan found although the witness's episode had no impact; "
              "they count as paying only where the plan with impacts hits the wall.",
              "- Laws other than elastic (the probes' plastic and e = 0.5 walls) and the circle and rounded "
              "rectangle tables are not run here."]
    rep.write(lines)
    write_certificates(rows, out.with_name(out.stem + "_certificates.json"))
    return summary


def write_certificates(rows, path):
    """The certified minimum-time pairs as data (start, target, the plan with impacts as scaled torques, its rows and
    impacts, the impact-free bound and its reason, the env replay), so a test can replay each plan in the probe's
    environment and recompute its bound."""
    import json

    out = []
    for r in rows:
        if r["actuation"] == "steer" or not certified(r):
            continue
        k, why = lower_bound(r)
        v, ok, steps, n_imp, how, margin = env_certified_plan(r)
        out.append({"scene": r["scene"], "pair": r["pair"], "actuation": r["actuation"], "task": r["task"],
                    "start": [float(x) for x in r["start"]], "target": [float(x) for x in r["target"]],
                    "plan": np.asarray(v).tolist(), "plan_from": how, "rows": int(r["with"].rows),
                    "impacts": int(r["with"].impacts), "bound_rows": int(k), "bound": why,
                    "env_success": ok, "env_steps": int(steps), "env_impacts": int(n_imp),
                    "env_margin": float(margin)})
    path.write_text(json.dumps(out, indent=1) + "\n")


def main(argv=None):
    from lab.common import report_command

    def options(ap):
        ap.add_argument("--pairs", type=int, default=10, help="pairs per table (default 10)")
        ap.add_argument("--seed", type=int, default=0)
        ap.add_argument("--workers", type=int, default=1)
        ap.add_argument("--actuations", nargs="+", default=list(ACTUATIONS), help="subset of both steer drive")
        ap.add_argument("--scenes", nargs="+", default=list(SCENES), help="tables: subset of ellipse stadium")
        ap.add_argument("--runs", type=Path, default=None, help="where the solved rows are saved (default "
                        "runs/impact_oc; --quick: beside the report)")
        ap.add_argument("--report-only", action="store_true", help="rewrite the report from the saved rows.pkl")
        ap.add_argument("--recertify", action="store_true", help="replay the committed certificates "
                        "(docs/optimal_control_certificates.json) with the margin rule and rewrite them (minutes)")
    rep = report_command("studies.impact_oc", "optimal_control.md", __doc__.split("\n\n")[0], argv, options=options,
                         docs_default=True, quick="1 ellipse pair, every actuation, short horizons")
    args, argv, out = rep.args, rep.argv, rep.out
    if args.recertify:
        path = ROOT / "docs" / "optimal_control_certificates.json"
        certs = recertify(path)
        print(f"wrote {path}: {sum(c['env_success'] for c in certs)}/{len(certs)} replayed with a margin >= "
              f"{REPLAY_MARGIN:g}; smallest margin {min(c['env_margin'] for c in certs):.3g}")
        n = recertify_report(ROOT / "docs" / "optimal_control.md", certs)
        print(f"docs/optimal_control.md: {n} replay lines name their re-solved plans")
        return path
    for name in ("pairs", "workers"):
        if getattr(args, name) < 1:
            raise SystemExit(f"--{name} must be >= 1, got {getattr(args, name)}")
    try:
        for a in args.actuations:
            check_choice("--actuations", a, ACTUATIONS)
        for s in args.scenes:
            check_choice("--scenes (table)", s, SCENES)
    except ValueError as exc:
        raise SystemExit(str(exc)) from None
    docs = ROOT / "docs"
    if args.quick:
        settings = dict(n_pairs=1, scenes=("ellipse",), horizon={"both": 30, "drive": 60, "steer": 80}, maxiter=40,
                        random_starts=0, budget=2, objectives=("time",))
    else:
        settings = dict(n_pairs=args.pairs, scenes=tuple(args.scenes))
    runs = args.runs or (out.parent if args.quick else ROOT / "runs" / "impact_oc")
    saved = runs / "rows.pkl"
    meta = {"pairs": settings["n_pairs"], "scenes": settings["scenes"], "seed": args.seed, "workers": args.workers,
            "maxiter": settings.get("maxiter", 100), "random_starts": settings.get("random_starts", 2),
            "budget": settings.get("budget", 8)}
    if args.report_only:
        if not saved.is_file():
            raise SystemExit(f"no saved solves at {saved} (run without --report-only first)")
        with open(saved, "rb") as f:
            rows, seconds, meta, argv = pickle.load(f)
        meta = dict(meta, rewritten=time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()))
    else:
        t0 = time.perf_counter()
        rows = study(seed=args.seed, actuations=tuple(args.actuations), workers=args.workers, **settings)
        seconds = time.perf_counter() - t0
        runs.mkdir(parents=True, exist_ok=True)
        with open(saved, "wb") as f:
            pickle.dump((rows, seconds, meta, argv), f)
    summary = write_report(rep, rows, argv, seconds, meta)
    if not args.quick and out.resolve() == (docs / "optimal_control.md").resolve():
        if rep.readme(ROOT / "README.md", README_BEGIN, README_END, readme_block(summary)):
            print("README.md: the optimal-control answer updated")
    return out


if __name__ == "__main__":
    from studies.impact_oc import main as module_main  # (rows.pkl names studies.optimal_control.Solution)

    module_main()
