"""The theorems that decide cells and pairs (penny_env/analysis/controllability_theorems.py; T2.3, T2.5, T3.4, T5
of docs/controllability_theory.md): each bound proved there is checked against the simulator on random episodes,
the regions the theorems read against the environment's own draws, and the verdicts on cells no preset names
(overrides and a user ConvexTable)."""
import math

import gymnasium as gym
import numpy as np
import pytest

import penny_env  # noqa: F401  (registers the ids)
from penny_env import Circle, ConvexTable, Ellipse, PennyParams, RoundedRectangle, Stadium
from penny_env import batch
from penny_env.analysis import controllability_theorems as ct

P = PennyParams()
U1, U2 = 6.25e-7, 1.5e-5  # the scenes' torque limits (steering, rolling)
TABLES = {"ellipse": Ellipse(0.15, 0.2), "circle": Circle(0.2), "stadium": Stadium(0.1, 0.15),
          "rounded_rectangle": RoundedRectangle(0.3, 0.2, 0.04)}
STEER = "PennyProbeSteer-Ellipse-Elastic-v0"


def superellipse(s=0.45):
    """A user table: x^4 + y^4 < s^4 as a ConvexTable (not compiled)."""
    return ConvexTable(lambda x, y: (x**4 + y**4 - s**4) / (4 * s**3), lambda x, y: (x**3 / s**3, y**3 / s**3),
                       grad_bound=1.0, hessian_bound=3 / s, extent=(-1.1 * s, 1.1 * s, -1.1 * s, 1.1 * s))


def wall_distance_upper(table, points, n=200000):
    """The distance from points to a dense set of wall points: an upper bound of the distance to the wall."""
    ang = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    rho = table.wall_distance(np.cos(ang), np.sin(ang))
    wall = np.stack([rho * np.cos(ang), rho * np.sin(ang)], 1)
    return np.array([np.hypot(*(wall - p).T).min() for p in np.atleast_2d(points)])


def interior_points(table, n, rng, fraction=0.95):
    ang = rng.uniform(-np.pi, np.pi, n)
    rho = table.wall_distance(np.cos(ang), np.sin(ang)) * fraction * np.sqrt(rng.uniform(size=n))
    return np.stack([rho * np.cos(ang), rho * np.sin(ang)], 1)


@pytest.mark.parametrize("name", [*TABLES, "circle_r0.5", "superellipse"])
def test_t2_5_wall_distance_is_a_lower_bound(name):
    """wall_distance_lower never exceeds the distance to the wall (exact on the circle, a dense upper bound
    elsewhere) and is within 1e-4 of the table's size of it; region_wall_distance_lower bounds the region's points."""
    table = {"superellipse": superellipse(), "circle_r0.5": Circle(0.5)}.get(name) or TABLES[name]
    rng = np.random.default_rng(1)
    pts = interior_points(table, 300, rng)
    low = ct.wall_distance_lower(table, pts)
    if name == "circle_r0.5":
        true = 0.5 - np.hypot(*pts.T)
        assert np.all(low <= true) and np.all(true - low < 1e-4 * table.size)
    else:
        up = wall_distance_upper(table, pts)
        assert np.all(low <= up + 1e-12) and np.all(up - low < 1e-4 * table.size)
    axes = tuple(0.6 * a for a in table.spawn_axes())
    bound = ct.region_wall_distance_lower(table, axes)
    t = rng.uniform(0, 2 * np.pi, 2000)
    r = np.sqrt(rng.uniform(size=2000))
    region = np.stack([axes[0] * r * np.cos(t), axes[1] * r * np.sin(t)], 1)
    assert bound <= wall_distance_upper(table, region[:200]).min()
    assert bound <= ct.wall_distance_lower(table, region).min() + 1e-3 * table.size  # and not far below


@pytest.mark.parametrize("env_id, overrides", [
    (STEER, {}), (STEER, {"table": {"kind": "circle", "radius": 0.5}, "law": 0.5}),
    ("PennyProbeDrive-Stadium-Elastic-v0", {}), ("PennyProbeBoth-Stadium-E05-v0", {"scene": "rounded_rectangle"}),
    ("PennyProbeSteer-Plane-v0", {}), (STEER, {"table": superellipse(), "max_episode_steps": 50}),
])
def test_cell_numbers_are_the_envs_draws(env_id, overrides):
    """The regions, speeds and time limit the theorems read (cell_numbers) contain every start and target the
    environment draws, and the time limit is the episode's."""
    scene, task = ct.resolve_id(env_id, **overrides)
    c = ct.cell_numbers(scene, task)
    env = gym.make(env_id, backend="python", **overrides)
    assert c.horizon == pytest.approx(env.spec.max_episode_steps * scene.control_dt)
    lo, hi = scene.init["theta_dot"]
    for seed in range(150):
        env.reset(seed=seed)
        s, g = env.unwrapped.state, env.unwrapped.target
        for p, (ax, ay) in ((s[:2], c.spawn_axes), (g, c.target_axes)):
            assert (p[0] / ax) ** 2 + (p[1] / ay) ** 2 <= 1 + 1e-12 if ax * ay > 0 else np.allclose(p, 0)
        assert lo <= s[4] <= hi
    env.close()


def _steer_run(table, law, rng, n=16, K=80, dt=0.05, W=(4.0, 12.0)):
    """Steer-only episodes with random torques, step by step (batch.simulate): per penny the start, the impact
    times, and per step end (time, state, impacts so far)."""
    S0 = []
    while len(S0) < n:
        p = interior_points(table, 1, rng, 0.9)[0]
        phi = rng.uniform(-np.pi, np.pi)
        ends = [p + s * P.R * np.array([math.cos(phi), math.sin(phi)]) for s in (1, -1)]
        if max(float(table.h(*e)) for e in ends) < -1e-4:
            S0.append([*p, 0.0, phi, rng.choice([-1, 1]) * rng.uniform(*W), rng.uniform(-2, 2)])
    S = np.array(S0)
    out = {"start": S.copy(), "first": np.full(n, np.inf), "last": np.full(n, -np.inf), "steps": []}
    for k in range(K):
        u = np.zeros((1, n, 2))
        u[0, :, 0] = rng.uniform(-U1, U1, n)
        res = batch.simulate(S, table=table, law=law, t_final=dt, controls=u, control_dt=dt)
        for i, t in zip(res.impact_env, res.impact_times):
            out["first"][i] = min(out["first"][i], k * dt + t)
            out["last"][i] = max(out["last"][i], k * dt + t)
        S = res.final_states
        out["steps"].append(((k + 1) * dt, S.copy(), out["last"].copy()))
    return out


@pytest.mark.parametrize("name", TABLES)
@pytest.mark.parametrize("law", ["elastic", 0.5, "plastic"], ids=str)
def test_t2_5_bounds_hold_on_random_steer_episodes(name, law):
    """T2.5 against the simulator, random steering torques from random starts: the first impact comes no earlier
    than first_impact_time(lower bound of d0, R, |R theta_dot0|), and after the last impact t_last the contact point
    is within R + |R theta_dot| (t - t_last) of the wall (T2.2 with T2.1), so within R + v_tol (T - t1) whenever the
    penny rolls slower than v_tol: the bound a park needs."""
    table = TABLES[name]
    rng = np.random.default_rng(3)
    run = _steer_run(table, law, rng)
    S0 = run["start"]
    d0 = ct.wall_distance_lower(table, S0[:, :2])
    t1 = np.array([ct.first_impact_time(float(d), P.R, abs(P.R * W)) for d, W in zip(d0, S0[:, 4])])
    assert np.all(run["first"] >= t1 - 1e-12)
    hit = np.isfinite(run["first"])
    assert hit.sum() >= 4  # the statement was exercised
    checked = 0
    for t, S, last in run["steps"]:
        after = np.isfinite(last)
        if not after.any():
            continue
        dist = wall_distance_upper(table, S[after, :2], n=20000) - 1e-6 * table.size  # (the dense set's resolution)
        v = np.abs(P.R * S[after, 4])
        assert np.all(dist <= P.R + v * (t - last[after]) + 1e-12)
        assert np.all(t1[after] <= last[after] + 1e-12)
        checked += after.sum()
    assert checked > 100


@pytest.mark.parametrize("name", [*TABLES, "plane"])
@pytest.mark.parametrize("actuation", ["both", "steer", "drive"])
def test_t5_speed_and_travel_bounds_hold_on_random_episodes(name, actuation):
    """T5.1 / T5.2 against the simulator: with the torques at random signs at their limits (every law by turn),
    the metric speed rho = sqrt((I + m R^2) theta_dot^2 + J phi_dot^2) stays below rho0 + k t (impacts never add
    energy) and the contact point within travel_bound(t) of its start."""
    table = TABLES.get(name)
    rng = np.random.default_rng(4)
    n, K, dt = 12, 40, 0.05
    rows = []
    tab = table if table is not None else TABLES["ellipse"]
    while len(rows) < n:
        p = interior_points(tab, 1, rng, 0.8)[0]
        phi = rng.uniform(-np.pi, np.pi)
        ends = [p + s * P.R * np.array([math.cos(phi), math.sin(phi)]) for s in (1, -1)]
        if max(float(tab.h(*e)) for e in ends) < -1e-4:
            rows.append([*p, 0.0, phi, rng.uniform(-8, 8), rng.uniform(-3, 3)])
    S0 = S = np.array(rows)
    a1 = U1 / P.J if actuation in ("both", "steer") else 0.0
    a2 = U2 / P.rolling_inertia if actuation in ("both", "drive") else 0.0
    scene, task = ct.resolve_id("PennyProbeBoth-Ellipse-Elastic-v0", actuation=actuation)
    c = ct.cell_numbers(scene, task)
    assert (c.a1, c.a2) == pytest.approx((a1, a2))
    rho0 = np.sqrt(P.rolling_inertia * S0[:, 4] ** 2 + P.J * S0[:, 5] ** 2)
    k = math.sqrt(P.rolling_inertia * a2 ** 2 + P.J * a1 ** 2)
    impacts = 0
    for step in range(K):
        law = ("elastic", 0.5, "plastic", 0.0)[step % 4]
        u = np.zeros((1, n, 2))
        u[0, :, 0] = rng.choice([-1, 1], n) * U1 * (a1 > 0)
        u[0, :, 1] = rng.choice([-1, 1], n) * U2 * (a2 > 0)
        res = batch.simulate(S, table=table, law=law, t_final=dt, controls=u, control_dt=dt)
        impacts += res.impact_counts.sum()
        S = res.final_states
        t = (step + 1) * dt
        rho = np.sqrt(P.rolling_inertia * S[:, 4] ** 2 + P.J * S[:, 5] ** 2)
        assert np.all(rho <= (rho0 + k * t) * (1 + 1e-12))
        moved = np.hypot(*(S[:, :2] - S0[:, :2]).T)
        bound = np.array([ct.travel_bound(c, W, w, t) for W, w in S0[:, 4:]])
        assert np.all(moved <= bound * (1 + 1e-12))
    assert table is None or impacts > 0


def test_t2_5_decides_the_circle_of_radius_half_and_some_pairs_of_a_smaller_one():
    """The issue's cell: steering only on a circle of radius 0.5 m with e = 0.5 walls is impossible by T2.5 (the
    targets lie >= 0.206 m from the wall, the theorem allows at most 0.202 m), and every pair the env draws is
    excluded pair by pair; on a circle of radius 0.35 m the cell is open and only some pairs are excluded; on the
    probes' own tables no pair is."""
    scene, task = ct.resolve_id(STEER, table={"kind": "circle", "radius": 0.5}, law=0.5)
    cell = ct.cell_theorem(scene, task)
    assert cell is not None and cell.id == "T2.5" and set(cell.conditions) == {"speed", "time"}
    assert "= 0.202 m of the wall" in cell.reason and ">= 0.206 m from it" in cell.reason
    for overrides, expect in (({"table": {"kind": "circle", "radius": 0.5}, "law": 0.5}, "all"),
                              ({"table": {"kind": "circle", "radius": 0.35}, "law": 0.5}, "some"),
                              ({}, "none"), ({"scene": "stadium"}, "none"), ({"scene": "rounded_rectangle"}, "none")):
        scene, task = ct.resolve_id(STEER, **overrides)
        env = gym.make(STEER, backend="python", **overrides)
        got = []
        for seed in range(40):
            env.reset(seed=seed)
            v = ct.pair_theorem(scene, task, env.unwrapped.state, env.unwrapped.target)
            got.append(v is not None and v.id == "T2.5")
        env.close()
        assert {"all": all(got), "some": 0 < sum(got) < len(got), "none": not any(got)}[expect], (overrides, sum(got))
        if expect != "all":
            assert ct.cell_theorem(scene, task) is None


def test_t2_5_needs_its_hypotheses():
    """T2.5 reads the speeds and the time limit: starts that may roll slower than speed_tolerance (they may creep
    to the target without an impact) or a longer episode leave the r = 0.5 cell undecided; a shorter one decides
    the r = 0.35 cell; a user ConvexTable is decided the same way."""
    big = {"table": {"kind": "circle", "radius": 0.5}, "law": 0.5}
    assert ct.theorem_for(STEER, **big, init={"theta_dot": [0.5, 5.0]}) is None
    assert ct.theorem_for(STEER, **big, max_episode_steps=800) is None
    assert ct.theorem_for(STEER, **big, speed_tolerance=0.02) is None
    assert ct.theorem_for(STEER, table={"kind": "circle", "radius": 0.35}, law=0.5, max_episode_steps=200).id == "T2.5"
    assert ct.theorem_for(STEER, table=superellipse(0.45), max_episode_steps=300).id == "T2.5"
    assert ct.theorem_for(STEER, table=superellipse(0.2)) is None


def test_t3_4_decides_a_circle_whose_starts_are_its_centre():
    """T3.4 on a circle: from its centre every heading line is a diameter, invariant for a drive-only penny that
    does not spin; a cell whose starts are all the centre (spawn_fraction 0) is impossible, and the simulator keeps
    the contact point on the diameter under random rolling torques for 10 s."""
    over = {"table": {"kind": "circle", "radius": 0.15}, "init": {"spawn_fraction": 0.0, "theta_dot": 0.0, "phi_dot": 0.0}}
    assert ct.theorem_for("PennyProbeDrive-Ellipse-Elastic-v0", **over).id == "T3.4"
    assert ct.theorem_for("PennyProbeDrive-Ellipse-Elastic-v0", table={"kind": "circle", "radius": 0.15}) is None
    env = gym.make("PennyProbeDrive-Ellipse-Elastic-v0", backend="python", **over)
    rng = np.random.default_rng(5)
    scene, task = ct.resolve_id("PennyProbeDrive-Ellipse-Elastic-v0", **over)
    for seed in range(3):
        env.reset(seed=seed)
        s0 = env.unwrapped.state.copy()
        assert ct.pair_theorem(scene, task, s0, env.unwrapped.target).id == "T3.4"
        impacts, done = 0, False
        while not done:
            _, _, term, trunc, info = env.step(rng.uniform(-1, 1, 1))
            impacts += info["impacts"]
            s = env.unwrapped.state
            assert abs(s[0] * math.sin(s0[3]) - s[1] * math.cos(s0[3])) < 1e-12
            done = term or trunc
        assert impacts > 0 and not info["is_success"]
    env.close()


def test_t5_2_decides_pairs_under_a_short_time_limit():
    """T5.2 reads the time limit and the torque limits: with 2 steps (0.1 s) of both torques no pair whose target
    is farther than tolerance + the travel bound can be reached, and the env indeed never reaches one."""
    over = {"max_episode_steps": 2}
    env_id = "PennyProbeBoth-Ellipse-Elastic-v0"
    scene, task = ct.resolve_id(env_id, **over)
    c = ct.cell_numbers(scene, task)
    assert ct.cell_theorem(scene, task) is None  # the regions overlap: some pairs are reachable
    env = gym.make(env_id, backend="python", **over)
    rng = np.random.default_rng(6)
    excluded = 0
    for seed in range(30):
        env.reset(seed=seed)
        s, g = env.unwrapped.state.copy(), env.unwrapped.target.copy()
        v = ct.pair_theorem(scene, task, s, g)
        bound = ct.travel_bound(c, s[4], s[5], c.horizon)
        assert (v is not None) == (np.hypot(*(g - s[:2])) >= task.tolerance + bound)
        if v is not None:
            assert v.id == "T5.2" and "time" in v.conditions
            excluded += 1
            for _ in range(3):
                env.reset(seed=seed)
                done = False
                while not done:
                    _, _, term, trunc, info = env.step(rng.uniform(-1, 1, 2))
                    done = term or trunc
                assert not info["is_success"]
    assert excluded > 20
    env.close()


def test_theorem_verdicts_name_their_conditions_and_links():
    v = ct.theorem_for("PennyProbeSteer-Plane-v0")
    assert v.label == "impossible (theorem T2.3)" and v.conditions == ("speed",)
    assert v.link() == "docs/controllability_theory.md#t2-steer-only"
    assert ct.theorem_for("PennyProbeDrive-Plane-v0").conditions == ("position",)
    assert set(ct.ANCHORS) == {"T2", "T3", "T4", "T5"}
    assert ct.first_impact_time(0.005, 0.01, 0.0) == 0.0 and ct.first_impact_time(0.2, 0.01, 0.0) == math.inf
