"""PennyEnv: spaces, rewards, errors, determinism, registration, checkers."""
import pickle
import subprocess
import sys
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.error import ResetNeeded

import penny_env
from penny_env import PennyEnv
from penny_env.envs import ConfigError, env_ids, resolve
from penny_env.envs.registration import env_presets

IDS = env_ids()


@pytest.mark.fast
def test_ids_cover_tasks_scenes_laws_actuations():
    # the study's probe ids (PennyProbe*, tests/step/test_study_probes.py) are a grid apart
    assert 8 <= len([i for i in IDS if not i.startswith("PennyProbe")]) <= 12
    presets = env_presets()
    scenes, tasks, laws, acts = set(), set(), set(), set()
    for kw in presets.values():
        sc, tk = resolve(**kw)
        scenes.add(sc.table["kind"])
        tasks.add(tk.kind)
        acts.add(sc.actuation)
        laws.add(sc.law if isinstance(sc.law, str) else "restitution")
    assert scenes == {"ellipse", "circle", "stadium", "rounded_rectangle", "none"}
    assert tasks == {"reach", "park", "impacts"}
    assert laws == {"elastic", "plastic", "restitution"}
    assert acts == {"both", "steer", "drive"}


def test_import_is_light():
    # numba is imported only by the compiled backend, which backend="python" declines
    code = ("import sys, penny_env, gymnasium as gym; gym.make('PennyReach-Ellipse-v0', backend='python');"
            "print([m for m in ('torch', 'matplotlib', 'pygame', 'scipy', 'stable_baselines3', 'numba') if m in sys.modules])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_make_without_import():
    code = ("import gymnasium as gym; e = gym.make('penny_env:PennyPark-Circle-v0'); e.reset(seed=0); "
            "print(type(e.unwrapped).__name__)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "PennyEnv"


@pytest.mark.parametrize("env_id", IDS)
def test_checkers_without_warnings(env_id):
    import importlib.util
    from gymnasium.utils.env_checker import check_env
    # the checker also opens render_mode="human", which needs pygame-ce (the [render] extra)
    no_pygame = importlib.util.find_spec("pygame") is None
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        # the tests run without a display (SDL_VIDEODRIVER=dummy): human mode says so once, rightly
        warnings.filterwarnings("ignore", message='render_mode="human": no display')
        check_env(gym.make(env_id, render_mode="rgb_array").unwrapped, skip_render_check=no_pygame)


@pytest.mark.parametrize("env_id", IDS)
def test_sb3_checker_without_warnings(env_id):
    pytest.importorskip("stable_baselines3", reason="Stable-Baselines3 (the penny-env[train] extra) is not installed")
    from stable_baselines3.common.env_checker import check_env as sb3_check_env
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sb3_check_env(gym.make(env_id).unwrapped)


@pytest.mark.parametrize("env_id", IDS)
def test_rollout_spaces_info_and_truncation(env_id):
    env = gym.make(env_id, max_episode_steps=None)
    u = env.unwrapped
    n_act = 2 if u.scene.actuation == "both" else 1
    assert env.action_space.shape == (n_act,) and env.action_space.dtype == np.float32
    assert env.observation_space.dtype == np.float32
    obs, info = env.reset(seed=3)
    assert env.observation_space.contains(obs)
    env.action_space.seed(0)
    steps = 0
    for _ in range(u.task.max_episode_steps):
        obs, r, term, trunc, info = env.step(env.action_space.sample())
        steps += 1
        assert env.observation_space.contains(obs) and np.isfinite(r)
        k = min(info["impacts"], 8)  # fixed-width arrays (max_impacts_in_info = 8), padded
        assert info["impact_times"].shape == info["impact_ends"].shape == (8,)
        assert np.count_nonzero(info["impact_ends"]) == k and not info["impact_times"][k:].any()
        assert info["time"] == pytest.approx(steps * u.scene.control_dt)
        assert info["kinetic_energy"] >= 0
        if term or trunc:
            assert "is_success" in info and info["is_success"] == term
            break
    if not term:
        assert trunc and steps == u.task.max_episode_steps


def test_impacts_happen_with_random_actions():
    for env_id in ("PennyImpacts-Stadium-v0", "PennyReach-Ellipse-v0", "PennyDrive-Circle-v0"):
        env = gym.make(env_id)
        env.reset(seed=0)
        env.action_space.seed(0)
        total = 0
        for _ in range(2000):  # pennies start near rest; random torques take a while to reach a wall
            _, _, term, trunc, info = env.step(env.action_space.sample())
            total += info["impacts"]
            times = info["impact_times"][:min(info["impacts"], 8)]
            assert np.all((times >= 0) & (times <= 0.05 + 1e-12))
            assert set(info["impact_ends"][:len(times)]) <= {1, -1}
            if term or trunc:
                env.reset()
        assert total >= 5, env_id


def test_open_plane_never_searches(monkeypatch):
    # the open plane is one flow per step: the step never calls the certificate or the event loop
    from penny_env.physics import scalar
    calls = []
    record = lambda *a, **k: calls.append(1)  # noqa: E731
    for name in ("period_is_free", "advance_into", "advance_through_into"):  # run_interval's callees
        monkeypatch.setattr(scalar, name, record)
    env = gym.make("PennyReach-Plane-v0", backend="python")
    env.reset(seed=0)
    for _ in range(50):  # (unseeded random actions may reach the target: start the next episode)
        if any(env.step(env.action_space.sample())[2:4]):
            env.reset()
    venv = penny_env.PennyVectorEnv(4, "plane", "reach", backend="python")
    venv.reset(seed=0)
    for _ in range(20):
        venv.step(venv.action_space.sample())
    assert not calls
    env = gym.make("PennyReach-Ellipse-v0", backend="python")  # (the patch does reach the step)
    env.reset(seed=0)
    with pytest.raises(TypeError):
        for _ in range(50):
            env.step(env.action_space.sample())


def test_determinism_bitwise_and_pickle():
    env = gym.make("PennyImpacts-Stadium-v0")
    acts = np.random.default_rng(0).uniform(-1, 1, (300, 2)).astype(np.float32)

    def run(e):
        out = [e.reset(seed=7)[0]]
        for a in acts:
            o, r, te, tr, info = e.step(a)
            out += [o, np.array([r, te, tr, info["impacts"]]), np.array(info["impact_times"])]
            if te or tr:
                out.append(e.reset()[0])
        return out

    a, b = run(env), run(env)
    assert all(np.array_equal(x, y) for x, y in zip(a, b))
    clone = pickle.loads(pickle.dumps(env.unwrapped))
    c = run(clone)
    assert all(np.array_equal(x, y) for x, y in zip(a, c))
    # different seeds differ; unseeded resets continue the seed's episode sequence
    assert not np.array_equal(env.reset(seed=7)[0], env.reset(seed=8)[0])
    o1 = [env.reset(seed=5)[0], env.reset()[0], env.reset()[0]]
    o2 = [env.reset(seed=5)[0], env.reset()[0], env.reset()[0]]
    assert all(np.array_equal(x, y) for x, y in zip(o1, o2)) and not np.array_equal(o1[0], o1[1])


def test_bad_input_errors_and_recovery():
    env = PennyEnv("ellipse", "reach")
    with pytest.raises(ResetNeeded):
        env.step(np.zeros(2, np.float32))
    env.reset(seed=0)
    for bad in (np.array([np.nan, 0.0]), np.array([0.0, np.inf])):
        with pytest.raises(ValueError, match="non-finite"):
            env.step(bad)
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(3, np.float32))
    with pytest.raises(TypeError, match="action"):  # a wrong type (issue 12.5's rule for the envs)
        env.step("left")
    s0 = env.state
    # out of range actions are clipped: the same as +-1
    e2 = PennyEnv("ellipse", "reach")
    e2.reset(seed=0)
    o_big = env.step(np.array([5.0, -7.0], np.float32))
    o_one = e2.step(np.array([1.0, -1.0], np.float32))
    assert np.array_equal(o_big[0], o_one[0]) and o_big[1] == o_one[1]
    assert not np.array_equal(s0, env.state)
    env2 = PennyEnv("ellipse", "reach", max_episode_steps=3)
    env2.reset(seed=0)
    for _ in range(3):
        *_, trunc, info = env2.step(np.zeros(2, np.float32))
    assert trunc and "is_success" in info
    with pytest.raises(ResetNeeded):
        env2.step(np.zeros(2, np.float32))
    env2.reset()
    env2.step(np.zeros(2, np.float32))  # usable again


@pytest.mark.fast
def test_config_errors_name_the_field(tmp_path):
    with pytest.raises(ConfigError, match="control_dt"):
        PennyEnv(control_dt=-1.0)
    with pytest.raises(ConfigError, match="bogus"):
        PennyEnv(bogus=3)
    with pytest.raises(ConfigError, match=r"init: unknown field\(s\) \['speed'\]"):
        PennyEnv(init={"speed": 3})
    with pytest.raises(ConfigError, match="actuation"):
        PennyEnv(actuation="fly")
    with pytest.raises(ConfigError, match="law"):
        PennyEnv(law=1.5)
    with pytest.raises(ConfigError, match="table"):
        PennyEnv(table={"kind": "ellipse", "a": -1, "b": 0.2})
    with pytest.raises(ConfigError, match="spawn_fraction"):
        PennyEnv(init={"spawn_fraction": 0.99})
    with pytest.raises(ConfigError, match="max_episode_steps"):
        PennyEnv(max_episode_steps=0)
    with pytest.raises(ConfigError, match="impacts"):
        PennyEnv("plane", "impacts")
    with pytest.raises(ConfigError, match="unknown scene preset"):
        PennyEnv("hexagon")
    bad = tmp_path / "bad.yaml"
    bad.write_text("table: {kind: circle, radius: [\n")
    with pytest.raises(ConfigError, match="invalid YAML"):
        PennyEnv(scene=str(bad))
    unknown = tmp_path / "unknown.yaml"
    unknown.write_text("table: {kind: circle, radius: 0.1}\nfriction: 0.3\n")
    with pytest.raises(ConfigError, match="friction"):
        PennyEnv(scene=str(unknown))
    good = tmp_path / "good.yaml"
    good.write_text("table: {kind: circle, radius: 0.1}\nlaw: 0.7\nactuation: drive\n")
    env = PennyEnv(scene=str(good), task="park", tolerance=0.05)
    assert env.action_space.shape == (1,) and env.task.tolerance == 0.05 and env.scene.law == 0.7
    env.reset(seed=0)
    env.step(np.ones(1, np.float32))


def test_rewards_match_documented_formulas():
    env = PennyEnv("circle", "reach", ctrl_cost=0.5, progress_weight=3.0)
    env.reset(seed=1, options={"state": [0.0, 0.0, 0.0, 0.0, 10.0, 0.0], "target": [0.05, 0.0]})
    L = env.unwrapped._core.L
    d0 = 0.05
    _, r, term, _, info = env.step(np.array([0.0, 0.5], np.float32))
    d = info["distance"]
    assert d == pytest.approx(np.hypot(*(env.target - env.state[:2])))
    assert r == pytest.approx(3.0 * (d0 - d) / L - 0.5 * (0.25 / 2) + (10.0 if d < 0.02 else 0.0))
    # drive straight to the target: success terminates with the bonus
    env.reset(seed=1, options={"state": [0.0, 0.0, 0.0, 0.0, 10.0, 0.0], "target": [0.04, 0.0]})
    for _ in range(20):
        _, r, term, trunc, info = env.step(np.array([0.0, 0.0], np.float32))
        if term:
            break
    assert term and info["is_success"] and r > 10.0 - 1e-9
    # park: rolling through the target is no success; stopping there is
    env = PennyEnv("circle", "park", speed_tolerance=0.01)
    env.reset(seed=1, options={"state": [0.0, 0.0, 0.0, 0.0, 10.0, 0.0], "target": [0.01, 0.0]})
    _, _, term, _, info = env.step(np.zeros(2, np.float32))
    assert not term and info["distance"] < 0.02
    env.reset(seed=1, options={"state": [0.0, 0.0, 0.0, 0.0, 0.0, 0.0], "target": [0.01, 0.0]})
    _, r, term, _, info = env.step(np.zeros(2, np.float32))
    assert term and info["is_success"]


def test_impacts_task_counts_arc_hits():
    # rolling straight at the wall point in the arc's direction: elastic bounces back and forth
    env = PennyEnv("circle", "impacts", impacts_goal=3, arc_half_width=np.pi)
    env.reset(seed=0, options={"state": [0.0, 0.0, 0.0, 0.0, 20.0, 0.0]})
    total, rew = 0, 0.0
    for _ in range(200):
        obs, r, term, trunc, info = env.step(np.zeros(2, np.float32))
        total += info["impacts"]
        rew += r
        assert obs[10] == pytest.approx(min(info["arc_impacts"] / 3, 1.0))
        if term:
            break
    assert term and info["is_success"] and total == 3 and info["arc_impacts"] == 3
    assert rew == pytest.approx(3 * 1.0 + 10.0)


def test_options_state_validated():
    env = PennyEnv("circle", "reach")
    with pytest.raises(ValueError, match="outside"):
        env.reset(options={"state": [0.2, 0.0, 0.0, 0.0, 1.0, 0.0]})
    with pytest.raises(ValueError, match="phi"):
        env.reset(options={"state": [0.0, 0.0, 0.0, np.nan, 1.0, 0.0]})
    with pytest.raises(ValueError, match="unknown"):
        env.reset(options={"velocity": 1})
    env.reset(seed=0)


@pytest.mark.fast
@pytest.mark.parametrize("kwargs,field", [
    ({"tolerance": "0.5"}, "task.tolerance"), ({"max_episode_steps": 10.5}, "task.max_episode_steps"),
    ({"kind": 3}, "task.kind"), ({"actuation": ["both"]}, "scene.actuation"), ({"params": [1, 2]}, "scene.params"),
    ({"table": 0.2}, "scene.table"), ({"table": {"kind": "ellipse", "a": "0.1", "b": 0.2}}, "scene.table"),
    ({"init": {"theta_dot": "fast"}}, "scene.init.theta_dot"), ({"spin_tolerance": True}, "task.spin_tolerance"),
])
def test_config_wrong_type_is_a_type_error_naming_the_field(kwargs, field):
    # a wrong type is a TypeError (ConfigTypeError: also a ConfigError, so a ValueError); a bad value stays a plain
    # ConfigError (ValueError, not TypeError)
    from penny_env.envs import ConfigTypeError
    with pytest.raises(ConfigTypeError, match=field.replace(".", r"\.")) as info:
        PennyEnv("ellipse", "park", **kwargs)
    assert isinstance(info.value, TypeError) and isinstance(info.value, ConfigError)
    with pytest.raises(ConfigError) as info:
        PennyEnv("ellipse", "park", tolerance=-1.0)
    assert not isinstance(info.value, TypeError)
    with pytest.raises(ConfigError) as info:
        PennyEnv("ellipse", "park", max_episode_steps=0)
    assert not isinstance(info.value, TypeError)
