"""Public single-trajectory API: simulate() and impact_map()."""
from __future__ import annotations

from dataclasses import dataclass, field
import math

import numpy as np

from .scalar import NO_ARC, flow_penny, impact_buffers, impacts_of, overflowed, relocate_inside, run_interval, scalar_model
from .flows import flow, end_kinematics, kinetic_energy
from .faults import blame, check_mapped, fault_error
from .laws import apply_law, make_law, restitution_update
from .params import PennyParams, SolverSettings
from .tables.registered import audited, check_impacts, sample
from .validation import (as_state, check_controls, check_inside, check_params, check_settings, check_speed_bound,
                         check_table, is_real, positive_count, positive_time)


@dataclass
class Trajectory:
    """Result of :func:`simulate`.

    impact_times (k,), impact_ends (k,) (+1 front, -1 back), impact_states (k, 6) (the state
    right after each impact), final_state (6,), final_time. rest_times: times at which an
    accumulation of impacts (Zeno) brought the penny to rest. complete: True when the run reached
    what it was asked for (t_final, or n_impacts impacts, whichever came first); False only when
    n_impacts were asked for without t_final and the penny provably never hits the wall again
    (uncontrolled periodic motion clear of the wall, or at rest): final_time is then the time at
    which that was proven. states_at(times) evaluates the trajectory exactly.
    """

    impact_times: np.ndarray
    impact_ends: np.ndarray
    impact_states: np.ndarray
    final_state: np.ndarray
    final_time: float
    rest_times: np.ndarray
    complete: bool
    params: PennyParams
    # piecewise description for dense output: start time, start state, accelerations
    _seg_t: np.ndarray = field(repr=False, default=None)
    _seg_s: np.ndarray = field(repr=False, default=None)
    _seg_acc: np.ndarray = field(repr=False, default=None)
    # simulate(..., sensitivities=True): see physics/sensitivity.py (None otherwise)
    jacobian: np.ndarray | None = field(repr=False, default=None)
    control_jacobian: np.ndarray | None = field(repr=False, default=None)
    jacobian_valid: bool | None = None
    jacobian_reason: str = ""
    final_time_gradient: np.ndarray | None = field(repr=False, default=None)
    final_time_control_gradient: np.ndarray | None = field(repr=False, default=None)
    impact_normal_speeds: np.ndarray | None = field(repr=False, default=None)

    @property
    def n_impacts(self) -> int:
        return int(self.impact_times.shape[0])

    def states_at(self, times) -> np.ndarray:
        """(len(times), 6) states at the given times in [0, final_time]."""
        t = np.atleast_1d(np.asarray(times, dtype=float))
        if np.any(~np.isfinite(t)) or np.any(t < 0) or np.any(t > self.final_time * (1 + 1e-12) + 1e-300):
            raise ValueError(f"times must lie in [0, final_time={self.final_time}]")
        k = np.searchsorted(self._seg_t, t, side="right") - 1
        k = np.clip(k, 0, len(self._seg_t) - 1)
        out = flow(self._seg_s[k].T, self._seg_acc[k, 0], self._seg_acc[k, 1], t - self._seg_t[k], self.params.R)
        return out.T

    def energies(self) -> np.ndarray:
        """Kinetic energy right after each impact."""
        return kinetic_energy(self.impact_states.T, self.params)


FREE_INTERVAL = 0.1  # [s] intervals of an uncontrolled run to t_final (penny_env.batch.simulate uses the same)
MAX_INTERVALS = 1_000_000  # intervals of FREE_INTERVAL in one batch.simulate call (bounded work): t_final <= 1e5 s


def interval_grid(t_final, dt):
    """(number of intervals, length of the last one) for intervals of length dt up to t_final; the
    last one ends exactly at t_final. simulate() and penny_env.batch.simulate share this grid, so
    a penny takes the same intervals (hence bitwise the same steps) in both."""
    k_steps = max(1, int(math.ceil(t_final / dt - 1e-12)))
    return k_steps, t_final - dt * (k_steps - 1)


def _free_chunk(state, params, table):
    """Uncontrolled motion is periodic (period 2 pi / |phi_dot|) or a straight line that leaves
    any table within (table width) / speed: a chunk of this length with no impact means the
    penny never hits the wall again. inf for a penny at rest."""
    w, W = abs(state[5]), abs(state[4])
    if w > 0:
        return 2 * math.pi / w
    if W > 0 and table is not None:
        return 4.0 * table.size / (params.R * W)
    return math.inf


def elastic_impact_period(state, params, table) -> float:
    """An upper bound [s] of the time between two impacts of an uncontrolled penny on ``table`` under the elastic
    law, from its state: inf at rest.

    Between impacts each end moves at the constant speed R sqrt(theta_dot^2 + phi_dot^2) (the rolling and the
    turning velocities are orthogonal) along a circle or a line. Right after an impact the end crosses the wall
    inward, so its path leaves the table again within one turn of a circle of radius at most D, the diameter of the
    extent, or, on a larger circle or a line, within a minor arc of chord at most D: a path of at most 2 pi D. The
    elastic law keeps (I + m R^2) theta_dot^2 + J phi_dot^2, hence theta_dot^2 + phi_dot^2 >= that / max(I + m R^2,
    J). Twice that time, for round-off."""
    energy2 = params.rolling_inertia * state[4] * state[4] + params.J * state[5] * state[5]
    if not energy2 > 0.0:
        return math.inf
    xmin, xmax, ymin, ymax = (float(v) for v in table.extent)
    diameter = math.hypot(xmax - xmin, ymax - ymin)
    end_speed = params.R * math.sqrt(energy2 / max(params.rolling_inertia, params.J))
    return 2.0 * (2.0 * math.pi * diameter) / end_speed


def _check_reachable(t_final, t_hit, recorded, state, params, table, law, settings) -> None:
    """Refuse, right after the first impact of an uncontrolled elastic run to t_final, a run that provably needs more
    than SolverSettings.max_impacts impacts (elastic_impact_period), rather than after recording them all (t_final =
    1e12 took 87 s to reach the limit)."""
    if t_final is None or not (law.update is restitution_update and law.e == 1.0):
        return
    period = elastic_impact_period(state, params, table)
    needed = recorded + math.floor((t_final - t_hit) / period)
    if needed > settings.max_impacts:
        reach = t_hit + period * (settings.max_impacts - recorded)
        raise ValueError(f"t_final={t_final!r}: an elastic penny that hits the wall hits it again at least every "
                         f"{period:.3g} s (elastic_impact_period), so this run needs at least {needed:.3g} impacts, "
                         f"beyond SolverSettings.max_impacts = {settings.max_impacts} (bounded memory; no run of this "
                         f"penny past t = {reach:.3g} s fits in it): ask for less, continue from a shorter run's "
                         "final_state, or raise SolverSettings.max_impacts")


def simulate(state, *, params=None, table, law="elastic", t_final=None, n_impacts=None,
             controls=None, control_dt=None, settings: SolverSettings | None = None,
             sensitivities: bool = False) -> Trajectory:
    """Simulate the (controlled) bouncing penny exactly, impact by impact.

    state: (x, y, theta, phi, theta_dot, phi_dot). table: Ellipse/Circle/Stadium/ConvexTable or
    None (open plane). law: "elastic", "plastic" or a restitution coefficient e in [0, 1].
    Stops at t_final, or right after the n_impacts-th impact, whichever comes first (at least
    one must be given; with controls, t_final defaults to len(controls) * control_dt).
    controls: (K, 2) rows of torques (u1, u2), row k held on [k, k+1) * control_dt.
    settings: SolverSettings. Work and memory are bounded: inputs beyond the documented limits
    (speeds, steering phase per interval, SolverSettings.max_impacts; docs/physics.md, Limits)
    raise a ValueError naming the field and the limit.
    A law or a table that breaks its contract at an impact (a non-finite velocity, an energy gain, an
    end found outside the wall: the event loop's run-time guard, physics/faults.py) raises a ValueError
    naming the law or the table and the bound to fix.
    sensitivities: also return jacobian (d final_state / d state, 6 x 6) and, with controls,
    control_jacobian (6 x 2K), exact through every impact; jacobian_valid False (NaN matrices,
    jacobian_reason says why) where no derivative exists (physics/sensitivity.py).
    """
    params = check_params(params)
    table = check_table(table, params)
    law = make_law(law)
    settings = check_settings(settings)
    if not isinstance(sensitivities, (bool, np.bool_)):
        raise TypeError(f"sensitivities must be a bool, got {type(sensitivities).__name__}")
    s = as_state(state)
    u, cdt = check_controls(controls, control_dt)
    if t_final is not None:
        t_final = positive_time(t_final, "t_final")
    if n_impacts is not None:
        n_impacts = positive_count(n_impacts, "n_impacts")
        if table is None:
            raise ValueError("n_impacts needs a table: the open plane has no impacts")
        if n_impacts > settings.max_impacts:
            raise ValueError(f"n_impacts={n_impacts} is beyond the limit SolverSettings.max_impacts = "
                             f"{settings.max_impacts} (bounded memory); raise it or split the run")
    if u is not None:
        horizon = u.shape[0] * cdt
        if t_final is None:
            t_final = horizon
        elif t_final > horizon * (1 + 1e-12):
            raise ValueError(f"t_final={t_final} is beyond the controls' horizon {horizon} (len(controls) * control_dt)")
    if t_final is None and n_impacts is None:
        raise ValueError("give t_final or n_impacts (or controls)")
    S = s[:, None]
    check_inside(S, params, table)
    state = tuple(float(v) for v in S[:, 0])
    if table is not None:
        state = relocate_inside(state, scalar_model(params, table, law, settings))

    # the intervals: the control intervals; without controls, batch.simulate's grid of FREE_INTERVAL
    # for runs to t_final alone that it would accept (so that both give bitwise the same), else one
    # free period each (see _free_chunk), which lets a run with rare impacts take few intervals
    grid = cdt
    if u is None and n_impacts is None and interval_grid(t_final, FREE_INTERVAL)[0] <= MAX_INTERVALS:
        grid = FREE_INTERVAL
    if grid is not None:
        k_steps, last_dt = interval_grid(t_final, grid)
        if u is not None and k_steps > u.shape[0]:
            raise ValueError(f"t_final={t_final} is beyond the controls' horizon {u.shape[0] * cdt} (len(controls) * control_dt)")
    model = scalar_model(params, table, law, settings)
    buf = impact_buffers(1, 64)
    times, ends, states, rests = [], [], [], []
    # dense output: segments (start time, start state, accelerations), one per impact and per control
    # interval (free motion needs none at interval boundaries: the flow from the last start is exact)
    seg_t, seg_s, seg_acc = [0.0], [state], [(0.0, 0.0)]
    t0 = 0.0          # start of the current interval
    complete = True
    k = 0
    while True:
        acc1 = acc2 = 0.0
        if u is not None:
            acc1, acc2 = float(u[k, 0]) / params.J, float(u[k, 1]) / params.rolling_inertia
        if grid is not None:
            dt = grid if k < k_steps - 1 else last_dt
        else:  # one free period per interval (see _free_chunk)
            dt = _free_chunk(state, params, table)
            if t_final is not None:
                dt = min(dt, t_final - t0)
        seg_acc[-1] = (acc1, acc2)
        if dt == math.inf:  # at rest without controls and without t_final: no impact ever
            complete = False
            t = t0
            break
        check_speed_bound(state, acc1, acc2, dt, params, "controls" if u is not None else "state",
                          k if u is not None else None)
        # the interval, resumed wherever the per-call event cap stopped it (scalar.run_interval, the
        # event loop's one driver), stopping after the n_impacts-th impact
        left = 0 if n_impacts is None else n_impacts - len(times)
        def drive(b):
            try:
                return run_interval(state, math.cos(state[3]), math.sin(state[3]), acc1, acc2, dt, model,
                                    table is None, True, left, b, 0, NO_ARC)
            except Exception as exc:  # a user's law or table raising in plain Python: named (faults.blame)
                named = blame(exc, law, table, f"t = {t0:.6g} s")
                if named is None:
                    raise
                raise named from exc
        s1, elapsed = drive(buf)
        if len(times) + buf.count[0] > settings.max_impacts:
            asked = f"t_final={t_final!r}" if n_impacts is None else f"n_impacts={n_impacts}"
            raise ValueError(f"{asked}: the run passed SolverSettings.max_impacts = {settings.max_impacts} "
                             f"impacts by t = {t0 + elapsed:.6g} s (bounded memory); ask for fewer, continue "
                             "from a shorter run's final_state, or raise SolverSettings.max_impacts")
        if overflowed(buf)[0]:  # more impacts than the buffer holds: the same pure call with room for all
            buf = impact_buffers(1, int(buf.count[0]))
            s1, elapsed = drive(buf)
        if buf.fault[0]:  # the event loop's guard stopped at an impact: a law or table that breaks its contract
            raise fault_error(buf.fault[0], law, table, s1, params.R, f"t = {t0 + elapsed:.6g} s")
        state = s1
        impacts, rest_events = impacts_of(buf, 0)
        for ti, end, post in impacts:
            times.append(t0 + ti)
            ends.append(end)
            states.append(post)
            seg_t.append(times[-1])
            seg_s.append(post)
            seg_acc.append((acc1, acc2))
        for tr, pinned in rest_events:
            rests.append(t0 + tr)
            if pinned:  # held against the wall until the interval ends
                seg_acc[-1] = (0.0, 0.0)
        hit = bool(impacts)
        if hit and u is None and n_impacts is None and len(times) == len(impacts):  # (the run's first impacts)
            _check_reachable(t_final, times[0], len(times), state, params, table, law, settings)
        if n_impacts is not None and len(times) >= n_impacts:
            t = times[-1]
            break
        if grid is None and t_final is None and state[4] == 0.0 and state[5] == 0.0:
            complete = False  # brought to rest (rest_times): n_impacts cannot be reached
            t = times[-1]
            break
        t0 += dt
        if (grid is not None and k >= k_steps - 1) or (grid is None and t_final is not None and t0 >= t_final * (1 - 1e-15)):
            t = t_final
            break
        k += 1
        if u is None and not hit and (grid is None or (state[4] == 0.0 and state[5] == 0.0)):
            # no impact ever again: a free period without one (_free_chunk), or at rest. (On the grid, a
            # penny on an orbit tangent to the wall can still graze it after round-off, so the grid
            # runs on, as batch.simulate does.)
            if t_final is None:
                complete = False  # n_impacts cannot be reached
                t = t0
            else:  # one flow to t_final (batch.simulate would take the remaining FREE_INTERVAL steps)
                state = flow_penny(state, 0.0, 0.0, t_final - t0, params.R)
                t = t_final
            break
        if u is not None:  # the next control interval starts a new segment
            seg_t.append(t0)
            seg_s.append(state)
            seg_acc.append((0.0, 0.0))  # set at the top of the loop
    if audited(table):  # a user's registered shape: its formulas against its own h where the penny hit
        pick = sample(len(states))
        check_impacts(table, np.array(states).reshape(-1, 6)[pick], np.array(ends)[pick], params.R,
                      row_names=[f"simulate, t = {times[j]:.6g} s" for j in pick])
    S = np.array(state, dtype=float)[:, None]
    final = S[:, 0].copy()
    traj = Trajectory(np.array(times), np.array(ends, dtype=np.int8), np.array(states).reshape(-1, 6),
                  final, float(t), np.array(rests), complete, params,
                  np.array(seg_t), np.array(seg_s).reshape(-1, 6), np.array(seg_acc))
    if sensitivities:
        _attach_sensitivities(traj, table, law, u, n_impacts, t_final)
    return traj


def _attach_sensitivities(traj, table, law, controls, n_impacts, t_final):
    from .sensitivity import trajectory_jacobians

    sens = trajectory_jacobians(traj, table, law, controls, n_impacts, t_final)
    traj.jacobian, traj.control_jacobian = sens.jacobian, sens.control_jacobian
    traj.jacobian_valid, traj.jacobian_reason = sens.valid, sens.reason
    traj.final_time_gradient, traj.final_time_control_gradient = sens.time_gradient, sens.control_time_gradient
    traj.impact_normal_speeds = sens.normal_speeds


def impact_map(state, *, params=None, table, end, law="elastic") -> np.ndarray:
    """Post-impact state for a state whose given end (+1 front, -1 back) lies on the wall.

    The law's formula is applied as a map on the impact surface whatever the sign of the
    normal velocity (the simulator only calls it for ends moving outward). For the plastic law
    an end left moving outward (possible when I > m R^2 or J > m R^2, see laws.py) gets its
    normal velocity removed. A law that returns a non-finite velocity, or adds kinetic energy where the end
    moves outward, raises a ValueError naming it (physics/faults.py)."""
    params = check_params(params)
    if table is None:
        raise ValueError("table is required for impact_map")
    table = check_table(table, params)
    law = make_law(law)
    s = as_state(state)
    if not is_real(end):
        raise TypeError(f"end must be +1 (front) or -1 (back), got {type(end).__name__}")
    if end not in (1, -1):
        raise ValueError(f"end must be +1 (front) or -1 (back), got {end!r}")
    S = s[:, None]
    px, py, _, _ = end_kinematics(S, float(end), params.R)
    g = float(table.h(px, py)[0])
    if abs(g) > 1e-8 * table.size:
        label = "front" if end == 1 else "back"
        raise ValueError(f"state: the {label} end is not on the wall (h = {g:.3g})")
    try:
        post = apply_law(S, float(end), params, table, law)
    except Exception as exc:  # a user's law raising: named (faults.blame)
        named = blame(exc, law, table, "state")
        if named is None:
            raise
        raise named from exc
    check_mapped(S, post, float(end), params, table, law, "state")  # (the guard of the event loop, for the map)
    return post[:, 0]
