"""Stability report: stress cases for the simulator, each with measurements and pass/fail.

    python -m studies.stability [--quick] [--out docs/stability.md] [--only NAME ...]

Each case runs in its own process with a wall-clock budget (a hang is a failure, reported as
such). A case fails on: NaN/inf anywhere, an exception other than the documented input errors
(ValueError/TypeError raised on purpose by the API), the penny leaving the table (an end further
out than the penetration tolerance, at impacts, on dense samples, or just before each impact),
energy drift beyond tolerance (elastic) or energy gain (plastic / restitution), impact times off
the reference, or running out of time. Nothing is hidden: a failing case prints a reproducer.

Measured per case (where it applies): energy drift (max |E - E0| / E0 over impacts, elastic) or
the largest energy increase between impacts (dissipative laws); worst penetration = max h(end)
over impacts, over dense samples of the trajectory and over samples just before each impact
(tables' h is in metres); impact-time error against the reference; impacts or steps per second.
"""
from __future__ import annotations

import math
import multiprocessing as mp
import time
import traceback

import numpy as np

from lab import common
from penny_env.backends.pennies import advance_pennies
from penny_env.physics import Circle, Ellipse, PennyParams, SolverSettings, Stadium, simulate
from penny_env.physics.flows import end_kinematics, flow, kinetic_energy
from penny_env.physics.laws import make_law, normal_form
from penny_env.physics.params import MIN_GAP

EPS = 2.220446049250313e-16
# The hang detector's wall-clock budget per case [s]: at least 10 times the slowest case on the slowest machine
# we know of. The long-horizon case took 50 s on the machine that wrote docs/stability.md and 112-117 s on another
# quiet 2-core machine (its 120 s budget then reported a FAIL), so 1200 s; --quick's slowest case takes a
# few seconds there, so 300 s. A budget only tells a hang from a slow run; it measures nothing.
CASE_BUDGET = 1200.0
QUICK_CASE_BUDGET = 300.0
CASES = []


def case(name: str, what: str):
    def deco(fn):
        CASES.append((name, what, fn))
        return fn
    return deco


def pen_tol(table) -> float:
    """Penetration tolerance [m]: 1000 contact tolerances (contact_tol = 16 eps of the table size)."""
    return 1e3 * SolverSettings().contact_tol * table.size


def max_h(states, params, table) -> float:
    """Max over both ends of h(end) for (k, 6) states (-inf if none)."""
    S = np.asarray(states, float).reshape(-1, 6)
    if S.shape[0] == 0:
        return -math.inf
    S = S.T
    return max(float(np.max(table.h(*end_kinematics(S, sg, params.R)[:2]))) for sg in (1.0, -1.0))


def traj_metrics(tr, params, table, law, *, n_dense=2000, ref_state0=None):
    """NaN check, penetration (impacts, dense samples, just before impacts), energy behaviour."""
    m = {}
    arrays = [tr.impact_states, tr.final_state, tr.impact_times]
    m["finite"] = bool(all(np.all(np.isfinite(a)) for a in arrays)) and math.isfinite(tr.final_time)
    pen = max_h(tr.impact_states, params, table)
    pen = max(pen, max_h(tr.final_state, params, table))
    if tr.final_time > 0:
        ts = np.linspace(0.0, tr.final_time, n_dense)
        pen = max(pen, max_h(tr.states_at(ts), params, table))
        if tr.n_impacts:
            # the flow segment that ends at each impact, sampled just before the impact time
            before = []
            for ti in tr.impact_times[:2000]:
                before.extend([ti * (1 - 4 * EPS), ti - 1e-12, ti - 1e-10, ti - 1e-8, ti - 1e-7])
            before = np.clip(np.array(before), 0.0, tr.final_time)
            pen = max(pen, max_h(tr.states_at(before), params, table))
    m["penetration"] = pen
    if tr.n_impacts:
        E = kinetic_energy(tr.impact_states.T, params)
        E0 = float(kinetic_energy(np.asarray(ref_state0, float)[:, None], params)[0]) if ref_state0 is not None else E[0]
        if law.kind == "elastic":
            m["energy_drift"] = float(np.max(np.abs(E - E0)) / E0) if E0 > 0 else 0.0
        else:
            Es = np.concatenate([[E0], E])
            m["energy_gain"] = float(np.max(np.diff(Es)) / max(E0, 1e-300)) if Es.size > 1 else 0.0
    return m


def check(m, table, *, drift_tol=1e-10, gain_tol=1e-12):
    """(passed, reasons) from traj_metrics output."""
    reasons = []
    if not m.get("finite", True):
        reasons.append("non-finite values")
    if m.get("penetration", -1) > pen_tol(table):
        reasons.append(f"penetration {m['penetration']:.3g} m > {pen_tol(table):.2g} m")
    if m.get("energy_drift", 0) > drift_tol:
        reasons.append(f"energy drift {m['energy_drift']:.3g} > {drift_tol:g}")
    if m.get("energy_gain", 0) > gain_tol:
        reasons.append(f"energy gain {m['energy_gain']:.3g} > {gain_tol:g}")
    return not reasons, reasons


def run_sim(state, params, table, law, **kw):
    t0 = time.perf_counter()
    tr = simulate(state, params=params, table=table, law=law, **kw)
    return tr, time.perf_counter() - t0


def refused_case(run, limit: str, repro=None):
    """A case beyond a documented limit (docs/physics.md#limits): it passes when run() is refused
    with a ValueError that names the limit, and fails when it runs or raises anything else."""
    try:
        run()
    except ValueError as exc:
        if limit in str(exc):
            return dict(measured={"refused": f"ValueError naming {limit} (documented limit)"}, passed=True, reasons=[],
                        repro=repro)
        return dict(measured={"raised": f"ValueError: {exc}"}, passed=False,
                    reasons=[f"refused without naming the limit {limit}"], repro=repro)
    return dict(measured={"raised": "nothing"}, passed=False, reasons=[f"accepted beyond the limit {limit}"], repro=repro)


def sim_case(state, params, table, law, *, drift_tol=1e-10, repro=None, extra=None, **kw):
    """Run and check one case; a table narrower than R (1 + MIN_GAP) must be refused instead."""
    if table is not None and table.inradius < params.R * (1.0 + MIN_GAP):
        return refused_case(lambda: run_sim(state, params, table, law, **kw), "MIN_GAP", repro)
    law_o = make_law(law)
    tr, wall = run_sim(state, params, table, law, **kw)
    m = traj_metrics(tr, params, table, law_o, ref_state0=state)
    if kw.get("controls") is not None:  # the torques do work: energy is not conserved
        m.pop("energy_drift", None)
        m.pop("energy_gain", None)
    m["impacts"] = tr.n_impacts
    m["impacts_per_s"] = tr.n_impacts / wall if wall > 0 else float("nan")
    m["wall_s"] = wall
    m["sim_time"] = tr.final_time
    m["rests"] = int(tr.rest_times.size)
    ok, why = check(m, table, drift_tol=drift_tol)
    if tr.rest_times.size and law_o.kind == "elastic" and "energy_drift" in m and m["energy_drift"] > drift_tol:
        zs = kw.get("settings") or SolverSettings()
        k = np.searchsorted(tr.impact_times, tr.rest_times[0])
        gap = float(np.median(np.diff(tr.impact_times[max(0, k - 100):k + 1]))) if k > 1 else float("nan")
        why.append(f"elastic penny brought to rest at t = {tr.rest_times[0]:.6g} s by the accumulation guard after "
                   f"{k} impacts (median gap before it {gap:.3g} s; max_events_per_interval = "
                   f"{zs.max_events_per_interval}, documented degenerate behaviour): kinetic energy lost")
    if extra:
        ok2, why2 = extra(tr, m)
        ok, why = ok and ok2, why + why2
    return dict(measured=m, passed=ok, reasons=why, repro=repro)


def repro_sim(state, params, table, law, **kw):
    args = ", ".join(f"{k}={v!r}" for k, v in kw.items())
    return (f"penny_env.simulate({[float(v) for v in state]!r}, params={params!r}, table=penny_env.{table!r}, "
            f"law={law!r}, {args})")


# ------------------------------------------------------------------------------------------------
# cases
# ------------------------------------------------------------------------------------------------

@case("grazing cascades (paper, plastic scenes)",
      "the paper's plastic scenes (25 impacts, normal velocities decaying geometrically): impact-time error and missed "
      "impacts vs the reference (impacts below float64 resolution, i.e. whose wall excursion is within the contact "
      "tolerance, may be missed), penetration, energy")
def _grazing(quick):
    from studies.matching import match_impacts, unresolvable_mask
    from studies.reference import paper_scenes
    out = []
    for sc in paper_scenes():
        if sc.law.kind != "plastic":
            continue
        r = sim_case(sc.initial_state, sc.params, sc.table, sc.law, n_impacts=sc.n_impacts,
                     repro=repro_sim(sc.initial_state, sc.params, sc.table, "plastic", n_impacts=sc.n_impacts))
        tr, _ = run_sim(sc.initial_state, sc.params, sc.table, sc.law, n_impacts=sc.n_impacts)
        unres = unresolvable_mask(sc)
        mt = match_impacts(sc.impact_times, sc.impact_ends, tr.impact_times, tr.impact_ends, t_end=tr.final_time,
                           unresolvable=unres)
        r["measured"]["impact_time_err"] = mt.max_abs_err
        r["measured"]["missed/spurious"] = f"{mt.missed}/{mt.spurious} of {mt.n_ref}"
        r["measured"]["reference impacts below float64 resolution"] = int(unres.sum())
        r["measured"]["missed resolvable"] = mt.missed_resolvable
        r["measured"]["min rel. normal speed"] = float(np.nanmin(sc.rel_normal_speed))
        if mt.missed_resolvable or mt.spurious:
            r["passed"] = False
            r["reasons"].append(f"{mt.missed_resolvable} missed (resolvable), {mt.spurious} spurious impacts vs the "
                                f"reference (first unmatched reference impact #{mt.first_divergence + 1})")
        if not (mt.max_abs_err <= 1e-6):
            r["passed"] = False
            r["reasons"].append(f"impact-time error {mt.max_abs_err:.3g} s > 1e-6 s")
        r["label"] = sc.name
        out.append(r)
    return out


def _tangent_state(r, d, W=10.0, w=2.0, R=0.01):
    """Uncontrolled state on Circle(r) whose ends' common circle passes at distance d inside the wall
    (d < 0: it crosses the wall by |d|). Ends move on a circle of radius sqrt(R^2 + rho^2) about c."""
    rho = R * W / w
    rho_e = math.hypot(R, rho)
    cx = r - rho_e - d
    phi0 = math.pi  # start with the ends on the far side from the tangency point
    # c = z0 + i rho e^{i phi0}  =>  z0 = c - i rho e^{i phi0}
    z0 = complex(cx, 0.0) - 1j * rho * complex(math.cos(phi0), math.sin(phi0))
    return [z0.real, z0.imag, 0.0, phi0, W, w], 2 * math.pi / w


@case("near-tangent approaches",
      "detection of impacts whose path crosses the wall by |d| (d < 0) or misses it by d (d > 0); penetration")
def _near_tangent(quick):
    table = Circle(0.2)
    params = PennyParams()
    out = []
    ds = [1e-6, 1e-10, 1e-13, -1e-13, -1e-10, -1e-6] if not quick else [1e-10, -1e-10]
    for d in ds:
        s0, period = _tangent_state(0.2, d)
        kw = dict(t_final=1.5 * period)

        def extra(tr, m, d=d):
            expect = d < 0
            got = tr.n_impacts > 0
            m["expected impact"] = expect
            m["first impact t"] = float(tr.impact_times[0]) if got else float("nan")
            return (expect == got), ([] if expect == got else [f"impact {'expected' if expect else 'not expected'} "
                                                               f"but {tr.n_impacts} found"])
        r = sim_case(s0, params, table, "elastic", extra=extra, repro=repro_sim(s0, params, table, "elastic", **kw), **kw)
        r["label"] = f"d = {d:g} m"
        out.append(r)
    return out


@case("both ends touching at once",
      "thin ellipse with b slightly above R, penny across it (spinning and rolling): NaN, penetration, energy, rests; "
      "b below R (1 + MIN_GAP) must be refused (documented limit)")
def _both_ends(quick):
    params = PennyParams()
    R = params.R
    out = []
    for rel in ([1e-3, 1e-9] if not quick else [1e-3]):
        table = Ellipse(0.05, R * (1 + rel))
        s0 = [0.0, 0.0, 0.0, math.pi / 2, 1.0, 0.5]
        for law in ("elastic", "plastic"):
            kw = dict(t_final=2.0 if not quick else 0.5)
            r = sim_case(s0, params, table, law, repro=repro_sim(s0, params, table, law, **kw), **kw)
            r["label"] = f"b = R (1 + {rel:g}), {law}"
            out.append(r)
    return out


@case("fast spin / fast rolling / tiny speeds",
      "|phi_dot| up to 1e4 rad/s, theta_dot up to 1e3 rad/s, speeds down to 1e-9: energy drift, penetration, "
      "impacts per second")
def _speeds(quick):
    params = PennyParams()
    table = Circle(0.2)
    out = []
    for w in ([1e2, 1e3, 1e4] if not quick else [1e4]):
        s0 = [0.195, 0.0, 0.0, math.pi / 2, 10.0, w]
        kw = dict(t_final=0.2 if not quick else 0.02)
        r = sim_case(s0, params, table, "elastic", repro=repro_sim(s0, params, table, "elastic", **kw), **kw)
        r["label"] = f"phi_dot = {w:g} near the wall"
        out.append(r)
    ell = Ellipse(0.15, 0.2)
    for W in ([1e2, 1e3] if not quick else [1e3]):
        s0 = [0.0, 0.0, 0.0, 0.3, W, 3.0]
        kw = dict(t_final=1.0 if not quick else 0.1)
        r = sim_case(s0, params, ell, "elastic", repro=repro_sim(s0, params, ell, "elastic", **kw), **kw)
        r["label"] = f"theta_dot = {W:g}"
        out.append(r)
    for W, w in ([(1e-9, 1e-9), (1e-9, 0.0), (0.0, 1e-9)] if not quick else [(1e-9, 0.0)]):
        s0 = [0.05, 0.03, 0.0, 0.3, W, w]
        kw = dict(n_impacts=3, t_final=1e13)
        r = sim_case(s0, params, ell, "elastic", repro=repro_sim(s0, params, ell, "elastic", **kw), **kw)
        r["label"] = f"tiny speeds theta_dot = {W:g}, phi_dot = {w:g}"
        out.append(r)
    return out


@case("stiff inertia ratios",
      "J/(m R^2) and I/(m R^2) from 1e-4 to 1e2 on the paper's ellipse, elastic and plastic: energy, penetration")
def _inertia(quick):
    out = []
    ratios = [1e-4, 1e-2, 1.0, 1e2] if not quick else [1e-4, 1e2]
    table = Ellipse(0.15, 0.2)
    for ri in ratios:
        for rj in ratios:
            m, R = 0.0025, 0.01
            params = PennyParams(R=R, m=m, I=ri * m * R * R, J=rj * m * R * R)
            s0 = [0.0, 0.0, 0.0, math.pi / 2, 10.0, 0.2]
            for law in ("elastic", "plastic"):
                kw = dict(n_impacts=200 if not quick else 30, t_final=2000.0)
                r = sim_case(s0, params, table, law, repro=repro_sim(s0, params, table, law, **kw), **kw)
                r["label"] = f"I/mR^2 = {ri:g}, J/mR^2 = {rj:g}, {law}"
                out.append(r)
    return out


def _outward_after(tr, params, table):
    """Largest normal velocity (a W + b w) of the hitting end right after an impact (> 0: moving out)."""
    if tr.n_impacts == 0:
        return -math.inf
    S = tr.impact_states.T
    a, b, _ = normal_form(S, tr.impact_ends.astype(float), params, table)
    return float(np.max(a * S[4] + b * S[5]))


@case("plastic sticking (I > m R^2)",
      "plastic law with I = 3 and 10 m R^2: the end must not keep moving outward after an impact; energy never increases")
def _sticking(quick):
    out = []
    table = Ellipse(0.15, 0.2)
    for ri in ([3.0, 10.0] if not quick else [10.0]):
        m, R = 0.0025, 0.01
        params = PennyParams(R=R, m=m, I=ri * m * R * R, J=0.25 * m * R * R)
        s0 = [0.0, 0.0, 0.0, math.pi / 2, 10.0, 0.2]
        kw = dict(n_impacts=100 if not quick else 20, t_final=500.0)

        def extra(tr, mm, params=params):
            v = _outward_after(tr, params, table)
            mm["max normal velocity after impact"] = v
            tol = 1e-12 * params.R * (abs(s0[4]) + abs(s0[5]))
            return v <= tol, ([] if v <= tol else [f"end moving outward after impact ({v:.3g} m/s)"])
        r = sim_case(s0, params, table, "plastic", extra=extra, repro=repro_sim(s0, params, table, "plastic", **kw), **kw)
        r["label"] = f"I/mR^2 = {ri:g}"
        out.append(r)
    return out


@case("Zeno accumulation",
      "restitution 0.5 (and plastic) with a control torque pushing the front end into the wall: finishes, rest detected, "
      "no penetration")
def _zeno(quick):
    params = PennyParams()
    table = Circle(0.2)
    out = []
    x0 = 0.2 - params.R - 1e-3
    for law, u2 in (("restitution 0.5", 1e-5), ("restitution 0.5", 1e-4), ("plastic", 1e-5)):
        lw = 0.5 if law.startswith("restitution") else "plastic"
        s0 = [x0, 0.0, 0.0, 0.0, 1.0, 0.0]
        K = 20
        controls = np.tile([[0.0, u2]], (K, 1))
        kw = dict(controls=controls, control_dt=0.05)

        def extra(tr, m):
            m["rest at t"] = float(tr.rest_times[0]) if tr.rest_times.size else float("nan")
            why = [] if tr.rest_times.size else ["no accumulation / rest detected"]
            if tr.n_impacts > 1:
                per = np.bincount(np.floor(tr.impact_times / 0.05 + 1e-9).astype(int))
                gaps = np.diff(tr.impact_times)
                m["max impacts in one control interval"] = int(per.max())
                m["median gap between impacts"] = float(np.median(gaps))
                zs = SolverSettings()
                if per.max() > 100 * zs.zeno_impacts:
                    why.append(f"{int(per.max())} impacts in one 0.05 s control interval: the gaps settle at "
                               f"~{np.median(gaps):.3g} s (> zeno_window = {zs.zeno_window:g} s), so the Zeno detector "
                               f"(zeno_impacts = {zs.zeno_impacts}) does not trigger; rest comes only from "
                               f"max_events_per_interval = {zs.max_events_per_interval}")
            return not why, why
        r = sim_case(s0, params, table, lw, extra=extra,
                     repro=repro_sim(s0, params, table, lw, controls=f"np.tile([[0.0, {u2!r}]], ({K}, 1))", control_dt=0.05),
                     **kw)
        r["label"] = f"{law}, u2 = {u2:g} N m"
        out.append(r)
    return out


@case("thin tables",
      "ellipse with b close to R (inradius just above R), penny along the long axis rolling and spinning; tables with "
      "inradius <= R, and those narrower than R (1 + MIN_GAP), must be refused with ValueError (documented limit)")
def _thin(quick):
    params = PennyParams()
    R = params.R
    out = []
    for rel in ([1e-2, 1e-6, 1e-12] if not quick else [1e-6]):
        table = Ellipse(0.1, R * (1 + rel))
        s0 = [0.0, 0.0, 0.0, 0.0, 5.0, 0.3]
        for law in ("elastic", "plastic"):
            kw = dict(t_final=4.0)
            r = sim_case(s0, params, table, law, repro=repro_sim(s0, params, table, law, **kw), **kw)
            r["label"] = f"Ellipse(0.1, R (1 + {rel:g})), {law}"
            out.append(r)
    for b in (R, 0.9 * R):
        try:
            simulate([0, 0, 0, 0, 1.0, 0.0], table=Ellipse(0.1, b), t_final=1.0)
            res = dict(measured={"raised": "nothing"}, passed=False, reasons=["table with inradius <= R accepted"])
        except ValueError as exc:
            res = dict(measured={"raised": f"ValueError: {exc}"}, passed=True, reasons=[])
        res["label"] = f"Ellipse(0.1, {b / R:g} R) refused"
        res["repro"] = f"penny_env.simulate([0, 0, 0, 0, 1.0, 0.0], table=penny_env.Ellipse(0.1, {b!r}), t_final=1.0)"
        out.append(res)
    return out


@case("R close to the table's size",
      "circle of radius R (1 + eps) and a stadium barely wider than the penny: NaN, penetration, energy; radii below "
      "R (1 + MIN_GAP) must be refused (documented limit)")
def _tight(quick):
    params = PennyParams()
    R = params.R
    out = []
    for rel in ([1e-3, 1e-8] if not quick else [1e-3]):
        table = Circle(R * (1 + rel))
        s0 = [0.0, 0.0, 0.0, 0.7, 2.0, 1.0]
        for law in ("elastic", "plastic"):
            kw = dict(t_final=1.0 if not quick else 0.2)
            r = sim_case(s0, params, table, law, repro=repro_sim(s0, params, table, law, **kw), **kw)
            r["label"] = f"Circle(R (1 + {rel:g})), {law}"
            out.append(r)
    table = Stadium(R * (1 + 1e-4), 0.1)
    s0 = [0.0, 0.0, 0.0, 0.0, 5.0, 0.5]
    kw = dict(t_final=1.0 if not quick else 0.2)
    r = sim_case(s0, params, table, "elastic", repro=repro_sim(s0, params, table, "elastic", **kw), **kw)
    r["label"] = "Stadium(R (1 + 1e-4), 0.1), elastic"
    out.append(r)
    return out


@case("long horizon (batched advance)",
      "N elastic pennies on the paper's ellipse advanced with penny_env.physics.advance_pennies (intervals of 0.25 s) "
      "until N x K impacts in total (1000 x 1000 = 1e6; --quick: 100 x 100): energy drift, penetration, impacts per second")
def _long(quick):
    N, K = (1000, 1000) if not quick else (100, 100)
    params = PennyParams()
    table = Ellipse(0.15, 0.2)
    law = make_law("elastic")
    settings = SolverSettings()
    rng = np.random.default_rng(12345)
    S = np.zeros((6, N))
    S[0] = rng.uniform(-0.05, 0.05, N)
    S[1] = rng.uniform(-0.05, 0.05, N)
    S[3] = rng.uniform(0, 2 * np.pi, N)
    S[4] = rng.uniform(40.0, 60.0, N) * rng.choice([-1.0, 1.0], N)
    S[5] = rng.uniform(-3.0, 3.0, N)
    E0 = kinetic_energy(S, params)
    counts = np.zeros(N, dtype=np.int64)
    pen = -math.inf
    t0 = time.perf_counter()
    calls = 0
    finite = True
    while counts.sum() < N * K:
        # the plain-Python per-penny loop: cases run in forked workers, where numba's OpenMP
        # threads (used by the parent earlier) would abort the child
        S, log, _ = advance_pennies(S, 0.0, 0.0, 0.25, params, table, law, settings, backend="python")
        calls += 1
        counts += log.counts(N)
        if log.state.shape[0]:
            pen = max(pen, max_h(log.state, params, table))
        pen = max(pen, max_h(S.T, params, table))
        finite &= bool(np.all(np.isfinite(S)))
        if not finite or calls > 100 * K:
            break
    wall = time.perf_counter() - t0
    E = kinetic_energy(S, params)
    drift = float(np.max(np.abs(E - E0) / E0))
    m = dict(pennies=N, impacts=int(counts.sum()), min_impacts_per_penny=int(counts.min()), advance_calls=calls,
             wall_s=wall, impacts_per_s=counts.sum() / wall, energy_drift=drift, penetration=pen, finite=finite)
    ok, why = check(m, table, drift_tol=1e-10)
    repro = (f"see studies/stability.py::_long (N={N}, K={K}, seed 12345, advance_pennies(S, 0, 0, 0.25, ...))")
    return [dict(measured=m, passed=ok, reasons=why, repro=repro, label=f"{N} pennies, {N * K:.0e} impacts in total")]


@case("controlled flow near the cancellation points",
      "penny_env.physics.flow and simulate(table=None) vs the reference flow_cases.json (u1 -> 0, phi_dot -> 0, "
      "fast spin, long times)")
def _flows(quick):
    from studies.reference import flow_cases
    out = []
    worst = []
    for fc in flow_cases():
        p = fc.params
        acc1, acc2 = fc.u1 / p.J, fc.u2 / p.rolling_inertia
        s = flow(fc.state0[:, None], acc1, acc2, fc.t, p.R)[:, 0]
        tr = simulate(fc.state0, params=p, table=None, controls=[[fc.u1, fc.u2]], control_dt=fc.t)
        scale = p.R * (abs(fc.state0[4]) + abs(acc2) * fc.t) * fc.t + p.R  # path length scale [m]
        e_pos = max(float(np.hypot(*(s[:2] - fc.state_t[:2]))), float(np.hypot(*(tr.final_state[:2] - fc.state_t[:2]))))
        ang_scale = 1.0 + np.abs(fc.state_t[2:])
        e_ang = float(np.max(np.abs(np.stack([s[2:], tr.final_state[2:]]) - fc.state_t[2:]) / ang_scale))
        worst.append((e_pos / scale, e_ang, fc.tag, e_pos))
    # one row per family
    fams = {}
    for rel, ea, tag, e in worst:
        fam = tag.split("_")[0] if not tag.startswith("random") else "random"
        fams.setdefault(fam, []).append((rel, ea, tag, e))
    for fam, rows in fams.items():
        rel, ea, tag, e = max(rows)
        m = {"cases": len(rows), "worst position err / path scale": rel, "worst abs position err [m]": max(r[3] for r in rows),
             "worst angle/velocity rel err": max(r[1] for r in rows), "worst case": tag}
        ok = rel <= 1e-12 and max(r[1] for r in rows) <= 1e-13
        out.append(dict(measured=m, passed=ok,
                        reasons=[] if ok else [f"flow error {rel:.3g} (relative to the path scale) in {tag}"],
                        repro=f"compare penny_env.physics.flow with flow_cases.json case {tag!r}", label=f"family {fam}"))
    return out


# ------------------------------------------------------------------------------------------------
# runner
# ------------------------------------------------------------------------------------------------

def _worker(fn, quick, conn):
    try:
        conn.send(("ok", fn(quick)))
    except BaseException as exc:  # reported as a failure with the traceback
        conn.send(("error", f"{type(exc).__name__}: {exc}\n{traceback.format_exc(limit=6)}"))
    finally:
        conn.close()


def run_case(name, fn, quick, budget):
    ctx = mp.get_context("fork")
    parent, child = ctx.Pipe(duplex=False)
    p = ctx.Process(target=_worker, args=(fn, quick, child), daemon=True)
    t0 = time.perf_counter()
    p.start()
    child.close()
    msg = None
    if parent.poll(budget):
        try:
            msg = parent.recv()
        except EOFError:
            msg = None
    wall = time.perf_counter() - t0
    if p.is_alive():
        p.terminate()
        p.join(5)
        if p.is_alive():
            p.kill()
    else:
        p.join()
    if msg is None:
        what = f"no result within the {budget:g} s budget (hang?)" if wall >= budget else f"worker died (exit code {p.exitcode})"
        return [dict(label="(whole case)", measured={}, passed=False, reasons=[what], repro=f"stability case {name!r}")], wall
    kind, payload = msg
    if kind == "error":
        return [dict(label="(whole case)", measured={}, passed=False, reasons=[f"raised {payload.splitlines()[0]}"],
                     repro=payload)], wall
    return payload, wall


def _fmt_measured(m: dict) -> str:
    parts = []
    for k, v in m.items():
        if isinstance(v, (bool, np.bool_)):
            v = str(bool(v))
        elif isinstance(v, (int, float, np.integer, np.floating)):
            v = common.fmt(v)
        parts.append(f"{k}: {v}")
    return "; ".join(parts)


def report(results, argv, total_wall) -> list[str]:
    L = common.header("Stability of the penny simulator: stress cases", "studies.stability", argv)
    n_pass = sum(r["passed"] for _, _, rs, _ in results for r in rs)
    n_all = sum(len(rs) for _, _, rs, _ in results)
    L += [f"**{n_pass} of {n_all} checks passed** (total {total_wall:.1f} s). Each case runs in its own process with "
          "a wall-clock budget. Penetration = max h(end) over impacts, dense samples and samples just before each "
          "impact (h in metres; tolerance 1000 x contact_tol x table size, i.e. 7e-13 m on the paper's tables). "
          "Energy drift = max |E - E0| / E0 over impacts (elastic; tolerance 1e-10); energy gain = largest relative "
          "increase between impacts (dissipative laws; tolerance 1e-12).", ""]
    rows = []
    for name, what, rs, wall in results:
        for r in rs:
            rows.append([name, r.get("label", ""), _fmt_measured(r["measured"]).replace("|", "/"),
                         "PASS" if r["passed"] else "**FAIL**: " + "; ".join(r["reasons"]).replace("|", "/")])
    L += common.table(["case", "variant", "measured", "result"], rows)
    L += ["", "## What each case measures", ""]
    for name, what, rs, wall in results:
        L.append(f"- **{name}** ({wall:.1f} s): {what}.")
    fails = [(name, r) for name, _, rs, _ in results for r in rs if not r["passed"]]
    if fails:
        L += ["", "## Failures and reproducers", ""]
        for name, r in fails:
            L.append(f"- {name} / {r.get('label', '')}: {'; '.join(r['reasons'])}")
            L += ["", "  ```python", *("  " + line for line in str(r.get("repro", "")).splitlines()), "  ```", ""]
    return L


def main(argv=None):
    def options(ap):
        ap.add_argument("--budget", type=float, default=None,
                        help=f"wall-clock budget per case, a hang detector [s] (default {CASE_BUDGET:g}, --quick "
                             f"{QUICK_CASE_BUDGET:g}: 10 times the slowest case on a slow machine)")
        ap.add_argument("--only", nargs="*", default=None, help="run only cases whose name contains one of these")
    rep = common.report_command("studies.stability", "stability.md", "stress cases of the penny simulator with "
                                "pass/fail", argv, quick="fewer and shorter cases", options=options)
    args = rep.args
    budget = args.budget or (QUICK_CASE_BUDGET if args.quick else CASE_BUDGET)
    t0 = time.perf_counter()
    results = []
    selected = [c for c in CASES if not args.only or any(o.lower() in c[0].lower() for o in args.only)]
    for name, what, fn in common.progress(selected, desc="stability cases"):
        rs, wall = run_case(name, fn, args.quick, budget)
        results.append((name, what, rs, wall))
        for r in rs:
            status = "PASS" if r["passed"] else "FAIL: " + "; ".join(r["reasons"])
            print(f"[{name}] {r.get('label', '')}: {status}  ({_fmt_measured(r['measured'])})", flush=True)
    total = time.perf_counter() - t0
    rep.write(report(results, rep.argv, total))
    print(f"total {total:.1f} s")
    return results


if __name__ == "__main__":
    main()
