"""The environments as RL tools use them: time limits and is_success (SB3's EvalCallback counting),
wrong types and values of actions and reset options, unknown keywords, ids in spawned workers."""
import functools

import gymnasium as gym
import numpy as np
import pytest

import penny_env  # noqa: F401  (registers the ids)
from penny_env import PennyEnv, PennyVectorEnv
from penny_env.envs.scene import ConfigError, UnknownFieldError


def _episode_lengths(env, n_episodes, seed=0):
    """(lengths, is_success at each end) with zero actions."""
    lengths, success = [], []
    env.reset(seed=seed)
    steps = 0
    while len(lengths) < n_episodes:
        obs, r, term, trunc, info = env.step(np.zeros(env.action_space.shape, np.float32))
        steps += 1
        if term or trunc:
            assert "is_success" in info  # every episode end carries it
            lengths.append(steps)
            success.append(info["is_success"])
            steps = 0
            env.reset()
    return lengths, success


@pytest.mark.parametrize("n", [3, 650])
def test_make_honours_max_episode_steps_both_ways(n):
    env = gym.make("PennyReach-Ellipse-v0", max_episode_steps=n)  # the task's own limit is 400
    lengths, success = _episode_lengths(env, 2)
    assert lengths == [n, n] and success == [False, False]
    venv = gym.make_vec("PennyReach-Ellipse-v0", num_envs=2, max_episode_steps=n)
    venv.reset(seed=0)
    for t in range(n):
        obs, r, term, trunc, info = venv.step(np.zeros((2, 2), np.float32))
        assert trunc.all() == (t == n - 1) and "is_success" in info
    assert not info["is_success"].any()


def test_registered_env_without_time_limit_never_truncates_itself():
    env = gym.make("PennyReach-Ellipse-v0", max_episode_steps=-1)  # gymnasium: no TimeLimit
    env.reset(seed=0)
    for _ in range(450):
        *_, trunc, info = env.step(np.zeros(2, np.float32))
        assert not trunc
    assert PennyEnv(max_episode_steps=4).task.max_episode_steps == 4  # direct construction: its own limit


def test_sb3_success_rate_counts_truncated_episodes_as_failures():
    sb3 = pytest.importorskip("stable_baselines3", reason="SB3 is an optional extra")
    from stable_baselines3.common.evaluation import evaluate_policy

    class Still:  # a policy that does nothing: most episodes end by the time limit
        def predict(self, obs, state=None, episode_start=None, deterministic=True):
            return np.zeros((len(obs), 2), np.float32), None

    successes = []

    def log_success(locals_, globals_):  # EvalCallback's _log_success_callback
        if locals_["done"]:
            maybe = locals_["info"].get("is_success")
            if maybe is not None:
                successes.append((maybe, locals_["info"].get("TimeLimit.truncated", False)))

    env = sb3.common.env_util.make_vec_env("PennyReach-Ellipse-v0", n_envs=1,
                                           env_kwargs={"max_episode_steps": 5})
    evaluate_policy(Still(), env, n_eval_episodes=6, callback=log_success)
    assert len(successes) == 6 and sum(cut for _, cut in successes) >= 4  # (a drifting penny may arrive)
    assert all(ok != cut for ok, cut in successes)  # time-limit ends are failures, the others successes


def test_unknown_keywords_are_type_errors_and_config_errors():
    for make in (lambda: PennyEnv(frameskip=1), lambda: PennyVectorEnv(2, frameskip=1),
                 lambda: gym.make("PennyReach-Ellipse-v0", frameskip=1)):
        with pytest.raises(TypeError, match="unexpected keyword argument 'frameskip'") as err:
            make()
        assert isinstance(err.value, ConfigError) and isinstance(err.value, UnknownFieldError)
    with pytest.raises(TypeError, match="spawn_radius"):
        PennyEnv(init={"spawn_radius": 0.1})
    with pytest.raises(ValueError, match="control_dt"):  # a bad value stays a ValueError
        PennyEnv(control_dt=-1.0)


@pytest.mark.parametrize("bad", ["left", None, [True, False], np.array([1 + 1j, 0]), [None, 0.0], b"ab", [True, 0.0],
                                 ["0.5", 0.0]])
def test_wrong_action_types_are_type_errors(bad):
    env = PennyEnv()
    env.reset(seed=0)
    s0 = env.state
    with pytest.raises(TypeError, match="action"):
        env.step(bad)
    venv = PennyVectorEnv(2)
    venv.reset(seed=0)
    S0 = venv.states
    with pytest.raises(TypeError, match="action"):
        venv.step(bad if bad is None or isinstance(bad, (str, bytes)) else [bad, bad])
    assert np.array_equal(s0, env.state) and np.array_equal(S0, venv.states)


def test_reset_options_are_checked_like_scene_fields():
    env = PennyEnv("ellipse", "reach")
    obs, _ = env.reset(seed=0, options={"target": (0.05, -0.1)})
    assert env.observation_space.contains(obs) and np.array_equal(env.target, [0.05, -0.1])
    for bad, err in (((5, 5), ValueError), ((0.0, np.nan), ValueError), ((0.1,), ValueError),
                     ("far", TypeError), ((True, False), TypeError)):
        with pytest.raises(err, match=r"options\['target'\]"):
            env.reset(options={"target": bad})
    with pytest.raises(ValueError, match="reach"):  # a point no heading fits at (ends outside)
        env.reset(options={"target": (0.1499, 0.0)})  # inside the wall, 0.1 mm from it
    with pytest.raises(ValueError, match="impacts"):
        PennyEnv("stadium", "impacts").reset(options={"target": (0.0, 0.0)})
    plane = PennyEnv("plane", "reach")  # the open plane: any finite target (its observation is squashed)
    assert plane.observation_space.contains(plane.reset(options={"target": (5.0, 5.0)})[0])
    venv = PennyVectorEnv(3, "ellipse", "reach")
    with pytest.raises(ValueError, match=r"options\['target'\]\[1\]"):
        venv.reset(options={"target": [(0.0, 0.0), (5.0, 5.0), (0.0, 0.0)]})
    with pytest.raises(ValueError, match="outside"):
        venv.reset(options={"state": [0.2, 0.0, 0.0, 0.0, 1.0, 0.0]})
    venv.reset(seed=0)
    before = venv.states
    state = [0.01, 0.02, 0.0, 0.5, 3.0, 0.0]
    obs, _ = venv.reset(options={"state": state, "target": (0.0, 0.1), "reset_mask": np.array([False, True, False])})
    assert np.array_equal(venv.states[1], state) and np.array_equal(venv.targets[1], [0.0, 0.1])
    assert np.array_equal(before[[0, 2]], venv.states[[0, 2]]) and venv.observation_space.contains(obs)
    single = PennyEnv("ellipse", "reach")
    assert np.array_equal(single.reset(options={"state": state, "target": (0.0, 0.1)})[0], obs[1])


def test_prefixed_ids_work_in_spawned_workers():
    # gymnasium 1.x loads no plugins: a spawned worker knows an id once penny_env is imported there,
    # which the "penny_env:" prefix does
    env = gym.vector.AsyncVectorEnv([functools.partial(gym.make, "penny_env:PennyReach-Ellipse-v0")] * 2,
                                    context="spawn")
    try:
        obs, _ = env.reset(seed=1)
        assert np.array_equal(obs[1], PennyEnv().reset(seed=2)[0])
        env.step(np.zeros((2, 2), np.float32))
    finally:
        env.close()
