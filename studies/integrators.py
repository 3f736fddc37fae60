"""Other hybrid integrators for the bouncing penny (to compare penny_env with), and uniform runners for every method.

Only the integration differs between the methods: every impact is applied with penny_env's own
impact law (:func:`penny_env.physics.laws.apply_law`), so the comparison measures the flow and the
event location, not the impact maps.

* :func:`solve_ivp_hybrid` - scipy ``solve_ivp`` (RK45, DOP853, ...) on the 6-d ODE with terminal
  events h(end) = 0 (direction +1) for both ends; at an event the law is applied and the
  integration restarts from the post-impact state. A restart does not re-detect the same impact:
  scipy looks for sign changes of the event function between steps, and right after an impact the
  end's wall value starts at ~0 and moves inward (decreasing), which is not a +1 crossing
  (checked in tests/studies/test_analysis.py and counted in ``HybridResult.redetections``).
* :func:`rk4_hybrid` - fixed-step classical RK4 with a linear event locator (HybridDynamics.jl's
  default): after each step the sign of h(end) at the two step ends is checked; a crossing
  (h < 0 -> h >= 0) is located by linear interpolation of h between the step ends, the state
  there is recomputed by an RK4 step of that length, the law is applied and stepping resumes.
* :func:`run_simulate` / :func:`run_step_path` - penny_env.simulate and the environment's step path
  (penny_env.physics.advance_pennies over fixed control intervals) with the same interface.

All runners take the same stopping rules: stop once ``n_impacts`` impacts were found and the
time ``t_sample`` was passed (the state there is recorded), or at the hard stop ``t_stop``, or when
the wall-clock budget ``wall_budget`` [s] is spent (``status = "budget"``).
"""
from __future__ import annotations

from dataclasses import dataclass, field
import math
import time

import numpy as np

from penny_env.backends.pennies import advance_pennies
from penny_env.physics import SolverSettings, simulate
from penny_env.physics.flows import end_kinematics
from penny_env.physics.laws import apply_law, make_law


@dataclass
class HybridResult:
    """What a method produced: impacts, the state at t_sample, and bookkeeping."""

    impact_times: np.ndarray
    impact_ends: np.ndarray
    impact_states: np.ndarray          # (k, 6) post-impact states
    final_state: np.ndarray
    final_time: float
    state_at_sample: np.ndarray | None = None
    status: str = "ok"                 # ok | budget | failed: ... | max_impacts
    n_steps: int = 0                   # integrator steps (RK4) or rhs evaluations (solve_ivp)
    wall_at_impact: np.ndarray = field(default_factory=lambda: np.zeros(0))  # h(end) of the hitting end at each impact
    redetections: int = 0              # impacts of the same end within 1e-9 s of the previous one

    @property
    def n_impacts(self) -> int:
        return int(self.impact_times.shape[0])


def _finish(times, ends, states, s, t, sample, status, n_steps, walls, params):
    times = np.array(times, dtype=float)
    ends = np.array(ends, dtype=np.int8)
    red = 0
    if times.size > 1:
        red = int(np.sum((np.diff(times) < 1e-9) & (ends[1:] == ends[:-1])))
    return HybridResult(times, ends, np.array(states, dtype=float).reshape(-1, 6), np.array(s, dtype=float),
                        float(t), None if sample is None else np.array(sample, dtype=float), status, int(n_steps),
                        np.array(walls, dtype=float), red)


def _breakpoints(t_stop, t_sample, controls, control_dt):
    pts = [t_stop]
    if t_sample is not None:
        pts.append(t_sample)
    if controls is not None:
        pts.extend(control_dt * np.arange(1, controls.shape[0] + 1))
    return np.unique(np.array([p for p in pts if p is not None and math.isfinite(p)], dtype=float))


def _accels(t, controls, control_dt, params):
    if controls is None:
        return 0.0, 0.0
    k = min(int(math.floor(t / control_dt * (1 + 1e-13) + 1e-13)), controls.shape[0] - 1)
    return float(controls[k, 0]) / params.J, float(controls[k, 1]) / params.rolling_inertia


def _done(n_found, t, n_impacts, t_sample):
    return (n_impacts is None or n_found >= n_impacts) and (t_sample is None or t >= t_sample)


def _check_stop(n_impacts, t_stop, t_sample):
    if t_stop is None or not math.isfinite(t_stop):
        raise ValueError("t_stop (a finite hard stop) is required")
    if t_sample is not None and t_sample > t_stop:
        raise ValueError("t_sample must not exceed t_stop")


def _hit_wall(s, sigma, params, table):
    px, py, _, _ = end_kinematics(np.asarray(s, float)[:, None], float(sigma), params.R)
    return float(table.h(px, py)[0])


# ----------------------------------------------------------------------------------------------
# scipy solve_ivp with terminal events
# ----------------------------------------------------------------------------------------------

def solve_ivp_hybrid(state, *, params, table, law, method="DOP853", rtol=1e-12, atol=None,
                     n_impacts=None, t_stop, t_sample=None, controls=None, control_dt=None,
                     wall_budget=None, max_impacts=100_000) -> HybridResult:
    """Hybrid integration with scipy.integrate.solve_ivp and terminal events for both ends.

    atol defaults to rtol * 1e-3 * (L, L, 1, 1, 1, 1) with L the table size (metres for x, y;
    radians and rad/s for the rest)."""
    from scipy.integrate import solve_ivp

    _check_stop(n_impacts, t_stop, t_sample)
    law = make_law(law)
    R = params.R
    L = table.size
    if atol is None:
        atol = rtol * 1e-3 * np.array([L, L, 1.0, 1.0, 1.0, 1.0])
    controls = None if controls is None else np.asarray(controls, float)

    def rhs(t, s, a1, a2):
        W = s[4]
        return np.array([R * W * math.cos(s[3]), R * W * math.sin(s[3]), W, s[5], a2, a1])

    def make_event(sigma):
        sR = sigma * R

        def ev(t, s, a1, a2):
            return float(table.h(s[0] + sR * math.cos(s[3]), s[1] + sR * math.sin(s[3])))
        ev.terminal = True
        ev.direction = 1.0
        return ev

    events = [make_event(1.0), make_event(-1.0)]
    bps = _breakpoints(t_stop, t_sample, controls, control_dt)
    t = 0.0
    s = np.array(state, dtype=float)
    times, ends, states, walls = [], [], [], []
    sample = None
    nfev = 0
    status = "ok"
    start = time.perf_counter()
    while True:
        if t_sample is not None and sample is None and t >= t_sample:
            sample = s.copy()
        if t >= t_stop or _done(len(times), t, n_impacts, t_sample):
            break
        if wall_budget is not None and time.perf_counter() - start > wall_budget:
            status = "budget"
            break
        if len(times) >= max_impacts:
            status = "max_impacts"
            break
        t_b = float(bps[np.searchsorted(bps, t, side="right")])
        a1, a2 = _accels(t, controls, control_dt, params)
        sol = solve_ivp(rhs, (t, t_b), s, method=method, rtol=rtol, atol=atol, events=events, args=(a1, a2))
        nfev += sol.nfev
        if sol.status == -1:
            status = f"failed: {sol.message}"
            s, t = sol.y[:, -1], float(sol.t[-1])
            break
        if sol.status == 1:
            k = 0 if len(sol.t_events[0]) else 1
            t_ev = float(sol.t_events[k][0])
            pre = np.array(sol.y_events[k][0], dtype=float)
            sigma = 1.0 if k == 0 else -1.0
            walls.append(_hit_wall(pre, sigma, params, table))
            s = apply_law(pre[:, None], sigma, params, table, law)[:, 0]
            t = t_ev
            if t_sample is not None and sample is None and t >= t_sample:
                sample = pre.copy()  # impact exactly at the sample time (measure zero)
            times.append(t)
            ends.append(int(sigma))
            states.append(s.copy())
        else:
            s = sol.y[:, -1].copy()
            t = t_b
    return _finish(times, ends, states, s, t, sample, status, nfev, walls, params)


# ----------------------------------------------------------------------------------------------
# fixed-step RK4 with a linear event locator
# ----------------------------------------------------------------------------------------------

def rk4_hybrid(state, *, params, table, law, dt, n_impacts=None, t_stop, t_sample=None, controls=None,
               control_dt=None, wall_budget=None, max_impacts=100_000) -> HybridResult:
    """Fixed-step RK4 (step dt) with a linear event locator on h(end) at the step ends."""
    _check_stop(n_impacts, t_stop, t_sample)
    if not dt > 0:
        raise ValueError("dt must be positive")
    law = make_law(law)
    R = params.R
    controls = None if controls is None else np.asarray(controls, float)
    bps = _breakpoints(t_stop, t_sample, controls, control_dt)
    cos, sin = math.cos, math.sin
    th_ = table.h

    def step(x, y, th, ph, W, w, a1, a2, hh):
        # classical RK4 on (x, y, theta, phi, W, w)' = (R W cos phi, R W sin phi, W, w, a2, a1)
        k1x, k1y = R * W * cos(ph), R * W * sin(ph)
        W2, ph2 = W + 0.5 * hh * a2, ph + 0.5 * hh * w
        w2 = w + 0.5 * hh * a1
        k2x, k2y = R * W2 * cos(ph2), R * W2 * sin(ph2)
        ph3 = ph + 0.5 * hh * w2
        k3x, k3y = R * W2 * cos(ph3), R * W2 * sin(ph3)
        W4 = W + hh * a2
        w3 = w2  # w + hh/2 a1
        ph4 = ph + hh * w3
        k4x, k4y = R * W4 * cos(ph4), R * W4 * sin(ph4)
        c = hh / 6.0
        x1 = x + c * (k1x + 2 * k2x + 2 * k3x + k4x)
        y1 = y + c * (k1y + 2 * k2y + 2 * k3y + k4y)
        th1 = th + c * (W + 4 * W2 + W4)
        ph1 = ph + c * (w + 4 * w2 + (w + hh * a1))
        return x1, y1, th1, ph1, W4, w + hh * a1

    def walls(x, y, ph):
        c, sn = R * cos(ph), R * sin(ph)
        return float(th_(x + c, y + sn)), float(th_(x - c, y - sn))

    x, y, th, ph, W, w = (float(v) for v in state)
    t = 0.0
    gf, gb = walls(x, y, ph)
    times, ends, states, hits = [], [], [], []
    sample = None
    n_steps = 0
    status = "ok"
    start = time.perf_counter()
    ib = 0
    while True:
        if t_sample is not None and sample is None and t >= t_sample:
            sample = np.array([x, y, th, ph, W, w])
        if t >= t_stop or _done(len(times), t, n_impacts, t_sample):
            break
        if (n_steps & 1023) == 0 and wall_budget is not None and time.perf_counter() - start > wall_budget:
            status = "budget"
            break
        if len(times) >= max_impacts:
            status = "max_impacts"
            break
        while bps[ib] <= t:
            ib += 1
        t_b = float(bps[ib])
        a1, a2 = _accels(t, controls, control_dt, params)
        hh = min(dt, t_b - t)
        new = step(x, y, th, ph, W, w, a1, a2, hh)
        n_steps += 1
        nf, nb = walls(new[0], new[1], new[3])
        theta_f = -gf / (nf - gf) if (gf < 0.0 <= nf) else math.inf
        theta_b = -gb / (nb - gb) if (gb < 0.0 <= nb) else math.inf
        if theta_f == math.inf and theta_b == math.inf:
            x, y, th, ph, W, w = new
            gf, gb = nf, nb
            t = t_b if hh == t_b - t else t + hh
            continue
        sigma = 1.0 if theta_f <= theta_b else -1.0
        frac = min(theta_f, theta_b)
        pre = step(x, y, th, ph, W, w, a1, a2, frac * hh)
        n_steps += 1
        pre = np.array(pre)
        hits.append(_hit_wall(pre, sigma, params, table))
        post = apply_law(pre[:, None], sigma, params, table, law)[:, 0]
        t = t + frac * hh
        if t_sample is not None and sample is None and t >= t_sample:
            sample = pre.copy()
        x, y, th, ph, W, w = (float(v) for v in post)
        gf, gb = walls(x, y, ph)
        times.append(t)
        ends.append(int(sigma))
        states.append(post.copy())
    return _finish(times, ends, states, [x, y, th, ph, W, w], t, sample, status, n_steps, hits, params)


# ----------------------------------------------------------------------------------------------
# penny_env itself, same interface
# ----------------------------------------------------------------------------------------------

def run_simulate(state, *, params, table, law, n_impacts=None, t_stop, t_sample=None, controls=None,
                 control_dt=None, settings: SolverSettings | None = None, wall_budget=None) -> HybridResult:
    """penny_env.simulate: n_impacts impacts (or up to t_stop) and the exact state at t_sample."""
    _check_stop(n_impacts, t_stop, t_sample)
    if controls is not None:
        horizon = controls.shape[0] * control_dt
        tr = simulate(state, params=params, table=table, law=law, t_final=min(t_stop, horizon),
                      controls=controls, control_dt=control_dt, settings=settings)
    else:
        tr = simulate(state, params=params, table=table, law=law, n_impacts=n_impacts, t_final=t_stop,
                      settings=settings)
    sample = None
    if t_sample is not None:
        if tr.final_time >= t_sample:
            sample = tr.states_at([t_sample])[0]
        else:  # stopped at the n-th impact before t_sample: continue to t_sample
            tr2 = simulate(state, params=params, table=table, law=law, t_final=t_sample, settings=settings)
            sample = tr2.final_state
    walls = [_hit_wall(s, e, params, table) for s, e in zip(tr.impact_states, tr.impact_ends)]
    times, ends, states = tr.impact_times, tr.impact_ends, tr.impact_states
    if n_impacts is not None and times.shape[0] > n_impacts:
        times, ends, states = times[:n_impacts], ends[:n_impacts], states[:n_impacts]
    return _finish(list(times), list(ends), list(states), tr.final_state, tr.final_time, sample, "ok", 0,
                   walls, params)


def run_step_path(state, *, params, table, law, n_impacts=None, t_stop, t_sample=None, controls=None,
                  control_dt=None, env_dt=0.05, settings: SolverSettings | None = None,
                  wall_budget=None, scalar: bool = False) -> HybridResult:
    """The environment's step path: penny_env.physics.advance_pennies on a batch of one over intervals of env_dt
    (scalar=True: penny_env.physics.scalar.advance_interval, the plain-float event loop of the single env's fast
    path, bitwise equal to advance_pennies)."""
    if scalar:
        from penny_env.physics.scalar import advance_interval
    _check_stop(n_impacts, t_stop, t_sample)
    settings = SolverSettings() if settings is None else settings
    law = make_law(law)
    controls = None if controls is None else np.asarray(controls, float)
    bps = _breakpoints(t_stop, t_sample, controls, control_dt)
    S = np.array(state, dtype=float)[:, None]
    t = 0.0
    k = 0
    times, ends, states, walls = [], [], [], []
    sample = None
    status = "ok"
    start = time.perf_counter()
    while True:
        if t_sample is not None and sample is None and t >= t_sample:
            sample = S[:, 0].copy()
        if t >= t_stop or _done(len(times), t, n_impacts, t_sample):
            break
        if wall_budget is not None and time.perf_counter() - start > wall_budget:
            status = "budget"
            break
        t_env = (k + 1) * env_dt
        t_b = float(bps[np.searchsorted(bps, t * (1 + 1e-15), side="right")]) if bps.size else math.inf
        t_next = min(t_env, t_b)
        a1, a2 = _accels(t, controls, control_dt, params)
        if scalar:
            st, impacts, _, _ = advance_interval(tuple(float(v) for v in S[:, 0]), a1, a2, t_next - t, params, table, law,
                                         settings)
            S = np.array(st, dtype=float)[:, None]
            for ti, end, post in impacts:
                times.append(t + float(ti))
                ends.append(int(end))
                states.append(np.array(post, dtype=float))
        else:
            S, log, _ = advance_pennies(S, a1, a2, t_next - t, params, table, law, settings, backend="auto")
            for i in range(log.time.shape[0]):
                times.append(t + float(log.time[i]))
                ends.append(int(log.end[i]))
                states.append(log.state[i].copy())
        t = t_next
        if t >= t_env * (1 - 1e-15):
            k += 1
    if n_impacts is not None and len(times) > n_impacts:
        times, ends, states = times[:n_impacts], ends[:n_impacts], states[:n_impacts]
    walls = [_hit_wall(p, e, params, table) for p, e in zip(states, ends)]
    return _finish(times, ends, states, S[:, 0], t, sample, status, k, walls, params)

