"""Bounded work per step, always (issue 24.4): a scene's configured ranges are checked at
construction against the physics' documented limits, and the env step (single and vector env,
compiled and plain) ends the episode, truncated with info["limit"], where the physics reaches a
documented limit (the speed limit, the event cap of one period) instead of doing unbounded work."""
import math

import gymnasium as gym
import numpy as np
import pytest

import penny_env  # noqa: F401  (registers the ids)
from penny_env import PennyEnv, PennyVectorEnv
from penny_env.step import functional
from penny_env.envs.scene import ConfigError, Scene, env_presets, resolve
from penny_env.backends.choice import available
from penny_env.physics.params import MAX_ANGULAR_SPEED, MAX_STEERED_PHASE, SolverSettings
from penny_env.physics.validation import check_speed_bound

BACKENDS = ["numba", "python"] if available() else ["python"]
CAP = SolverSettings().max_events_per_interval


@pytest.mark.parametrize("field, value", [("theta_dot", 1e10), ("phi_dot", 1e300), ("phi_dot", [0.0, 1e10]),
                                          ("theta_dot", [-2e5, 0.0])])
def test_initial_speed_ranges_are_checked_at_construction(field, value):
    # init phi_dot 1e10 made a step take 20 s, 1e300 never returned (and Ctrl-C cannot stop compiled code)
    with pytest.raises(ConfigError, match=f"scene.init.{field}"):
        Scene(init={field: value})
    with pytest.raises(ConfigError, match=f"scene.init.{field}"):
        gym.make("PennySteer-Plane-v0", init={field: value})
    with pytest.raises(ConfigError, match=f"scene.init.{field}"):
        gym.make_vec("PennyReach-Ellipse-v0", num_envs=2, init={field: value})


def test_initial_speed_bound_is_the_step_limit():
    # the largest |speed| accepted is the one from which a step at the torque limits reaches exactly the limit
    sc = Scene(control_dt=10.0, table={"kind": "none"})
    W_max, w_max = sc.step_speed_limits()
    assert W_max == MAX_ANGULAR_SPEED - sc.torque_limits["u2"] * 10.0 / sc.make_params().rolling_inertia
    assert w_max == MAX_STEERED_PHASE / 10.0 - sc.torque_limits["u1"] * 10.0 / sc.make_params().J  # the phase limit
    Scene(control_dt=10.0, table={"kind": "none"}, init={"theta_dot": W_max, "phi_dot": -w_max})
    with pytest.raises(ConfigError, match="init.phi_dot"):
        Scene(control_dt=10.0, table={"kind": "none"}, init={"phi_dot": math.nextafter(w_max, math.inf)})
    # without a steering torque the heading's phase is not limited (closed-form flow)
    assert Scene(actuation="drive").step_speed_limits()[1] == MAX_ANGULAR_SPEED


@pytest.mark.parametrize("backend", BACKENDS)
def test_reset_state_beyond_the_step_limits_is_refused(backend):
    for env in (PennyEnv("plane", "reach", backend=backend), PennyVectorEnv(2, "plane", "reach", backend=backend)):
        W_max, w_max = env.scene.step_speed_limits()
        with pytest.raises(ValueError, match=r"options\['state'\].*phi_dot"):
            env.reset(seed=0, options={"state": [0, 0, 0, 0, 0, w_max * (1 + 1e-12)]})
        with pytest.raises(ValueError, match=r"options\['state'\].*theta_dot"):
            env.reset(seed=0, options={"state": [0, 0, 0, 0, -W_max * (1 + 1e-12), 0]})


@pytest.mark.parametrize("backend", BACKENDS)
def test_constant_torque_ends_at_the_speed_limit(backend):
    # PennySteer-Plane-v0 with no time limit and the action +1 passed the documented 1e5 rad/s (2e5
    # after 400k steps, each step 150 times slower); the episode now ends, truncated, with
    # info["limit"] == "speed", and no state ever passes MAX_ANGULAR_SPEED
    env = gym.make("PennySteer-Plane-v0", max_episode_steps=-1, backend=backend).unwrapped  # (no TimeLimit)
    vec = PennyVectorEnv(3, "plane", "reach", actuation="steer", backend=backend, max_episode_steps=10**9)
    _, w_max = env.scene.step_speed_limits()
    start = [0.0, 0.0, 0.0, 0.0, 5.0, w_max - 2.0]
    env.reset(seed=0, options={"state": start})
    vec.reset(seed=0, options={"state": start})
    for k in range(10):
        _, _, term, trunc, info = env.step(np.ones(1, np.float32))
        _, _, vterm, vtrunc, vinfo = vec.step(np.ones((3, 1), np.float32))
        assert abs(env.state[5]) <= MAX_ANGULAR_SPEED and np.all(np.abs(vec.states[:, 5]) <= MAX_ANGULAR_SPEED)
        assert np.all(vtrunc == trunc) and np.all(vinfo["limit"] == info["limit"])
        if trunc:
            break
        assert info["limit"] == functional.LIMIT_NONE
    assert trunc and not term and info["limit"] == functional.LIMIT_SPEED and k == 4  # 0.5 rad/s per step
    assert functional.LIMIT_NAMES[info["limit"]] == "speed" and env.state[5] > w_max
    assert vec.step(np.ones((3, 1), np.float32))[4]["limit"].tolist() == [0, 0, 0]  # (autoreset: a new episode)


def _fast_scene(**kw):
    # the rolling torque takes theta_dot from 0 to the limit in about 100 steps of 10 s
    Itot = Scene().make_params().rolling_inertia
    return dict(control_dt=10.0, torque_limits={"u2": Itot * 100.0}, init={"theta_dot": 0.0, "phi_dot": 0.0}, **kw)


@pytest.mark.skipif(not available(), reason="numba is not installed (10 000 impacts per step in plain Python)")
def test_impacts_per_step_are_capped_and_end_the_episode():
    # a table with a 10 s control period reached hundreds of thousands of impacts per step (seconds
    # per step); a step now stops at the event cap, the episode ends with info["limit"] == "impacts",
    # the state and time those right after the cap's impact (elapsed < control_dt)
    env = PennyEnv("ellipse", "reach", actuation="drive", truncate=False, max_impacts_in_info=CAP, **_fast_scene())
    vec = PennyVectorEnv(2, "ellipse", "reach", actuation="drive", max_episode_steps=10**9, **_fast_scene())
    env.reset(seed=1)
    vec.reset(seed=[1, 1])
    most = 0
    for k in range(200):
        _, _, term, trunc, info = env.step(np.ones(1, np.float32))
        vinfo = vec.step(np.ones((2, 1), np.float32))[4]
        assert info["impacts"] <= CAP and np.all(vinfo["impacts"] <= CAP)
        assert vinfo["impacts"].tolist() == [info["impacts"]] * 2 and vinfo["limit"].tolist() == [info["limit"]] * 2
        most = max(most, info["impacts"])
        if trunc:
            break
    assert info["limit"] == functional.LIMIT_IMPACTS and info["impacts"] == CAP and most == CAP
    assert info["time"] < (k + 1) * 10.0 and info["impact_times"][-1] == pytest.approx(info["time"] - k * 10.0, abs=1e-9)
    assert np.array_equal(vec._runner.st.time, [info["time"]] * 2)


@pytest.mark.parametrize("env_id", sorted(env_presets()))
def test_adversarial_actions_keep_every_step_within_the_limits(env_id):
    # every preset, its torques raised to 5000 rad/s of speed per step (the speed limit within 20
    # steps), under constant and bang-bang full torque, with no success and no time limit: no step
    # exceeds the event cap; every step that runs starts from a state the physics accepts for that
    # step's torques (validation.check_speed_bound, the physics' own limit check); and inside a step
    # impacts never add energy, so sqrt(2 E) grows by at most dt |u| in the kinetic metric
    # (Cauchy-Schwarz), which bounds both speeds (|phi_dot| <= sqrt(2 E / J)) and so the flow's work
    P = Scene().make_params()
    fast = {"u1": P.J * 1e5, "u2": P.rolling_inertia * 1e5}
    limits = 0
    for kind in ("constant", "bang-bang"):
        kind = resolve(**env_presets()[env_id])[1].kind  # (no success: each task kind's own field)
        never = {"impacts_goal": 10**9} if kind == "impacts" else {"tolerance": 1e-12}
        vec = gym.make_vec(env_id, num_envs=2, max_episode_steps=10**9, torque_limits=fast, **never).unwrapped
        c = vec._core
        growth = c.dt * math.sqrt(vec._p.gain1 ** 2 * c.J + vec._p.gain2 ** 2 * c.Itot)  # dt |u| in the metric
        vec.reset(seed=7)
        for t in range(30 if kind == "constant" else 20):
            a = np.ones((2, c.n_act), np.float32)
            if kind == "bang-bang":  # the sign flipping every 3 (first control) and 2 steps, env 1 mirrored
                a[:, 0] = 1.0 if (t // 3) % 2 == 0 else -1.0
                a[:, -1] = 1.0 if (t // 2) % 2 == 0 else -1.0
                a[1] *= -1.0
            acc1 = a[:, 0] * vec._p.gain1 if 0 in c.controls else np.zeros(2)
            acc2 = a[:, -1] * vec._p.gain2 if 1 in c.controls else np.zeros(2)
            run = ~vec._runner.st.pending  # (the others reset at this step)
            # raises a ValueError where the step's interval would pass MAX_ANGULAR_SPEED or MAX_STEERED_PHASE
            S = vec._runner.st.S
            check_speed_bound(S[:, run].copy(), acc1[run].astype(float), acc2[run].astype(float), c.dt, c.params,
                              env_id)
            before = np.sqrt(2 * (c.Itot * S[4] ** 2 + c.J * S[5] ** 2))
            info = vec.step(a)[4]
            after = np.sqrt(2 * info["kinetic_energy"])
            assert np.all(info["impacts"] <= CAP), env_id
            assert np.all(after[run] <= (before[run] + growth) * (1 + 1e-9)), env_id
            limits += int(np.count_nonzero(info["limit"]))
    # (dissipative walls can keep the speeds down, and so can elastic ones that a penny rolling
    # without steering bounces off head-on, the torque then braking it)
    if vec.scene.law == "elastic" and (0 in c.controls or c.plane):
        assert limits >= 2, env_id  # constant torque reached a limit in every env
