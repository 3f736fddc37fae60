"""Issue 21.5-21.7: the single env's info batches (fixed-width impact arrays: TorchRL's GymEnv with
num_envs, gymnasium's Sync/AsyncVectorEnv); Gymnasium's conventions for make_vec's vector_kwargs and
goal envs; penny_env.make_env, a picklable factory that makes plain ids work in worker processes."""
import importlib.util
import multiprocessing
import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import penny_env
from penny_env import PennyGoalEnv

needs_sb3 = pytest.mark.skipif(importlib.util.find_spec("stable_baselines3") is None,
                               reason="Stable-Baselines3 (the penny-env[train] extra) is not installed")
needs_torchrl = pytest.mark.skipif(importlib.util.find_spec("torchrl") is None,
                                   reason="TorchRL (the penny-env[torchrl] extra) is not installed")


# -- 21.5: the single env's info has fixed shapes ------------------------------------------------
def test_single_env_info_batches_in_gymnasium_vector_envs():
    venv = gym.make_vec("PennyImpacts-Stadium-v0", 3, vectorization_mode="sync")
    _, info = venv.reset(seed=0)
    assert info["impact_times"].shape == (3, 8) and info["impact_times"].dtype == np.float64
    seen = 0
    for _ in range(300):
        _, _, _, _, info = venv.step(venv.action_space.sample())
        assert info["impact_times"].shape == (3, 8) and info["impact_ends"].shape == (3, 8)
        seen += int(info["impacts"].sum())
        k = np.minimum(info["impacts"], 8)
        assert (np.count_nonzero(info["impact_ends"], axis=1) == k).all()
    assert seen > 0
    venv.close()


def test_single_env_info_width_and_reset_keys():
    env = gym.make("PennyImpacts-Stadium-v0", max_impacts_in_info=3)
    _, reset_info = env.reset(seed=0)
    _, _, _, _, step_info = env.step(env.action_space.sample())
    assert reset_info.keys() == step_info.keys()  # every key on reset and step: batchable from the first step
    assert reset_info["impacts"] == 0 and not reset_info["is_success"] and step_info["impact_times"].shape == (3,)
    with pytest.raises(TypeError, match="max_impacts_in_info"):
        gym.make("PennyReach-Ellipse-v0", max_impacts_in_info=2.5)
    with pytest.raises(ValueError, match="max_impacts_in_info"):
        gym.make("PennyReach-Ellipse-v0", max_impacts_in_info=-1)


@needs_torchrl
@pytest.mark.slow
def test_torchrl_gymenv_with_num_envs():
    from torchrl.envs import GymEnv
    # gymnasium's AsyncVectorEnv of the single env; its workers may be spawned: the prefixed id imports penny_env
    env = GymEnv("penny_env:PennyImpacts-Stadium-v0", num_envs=2)
    td = env.rollout(20, break_when_any_done=False)
    env.close()
    assert td["next", "observation"].shape == (2, 20, 11) and td["next", "impact_times"].shape == (2, 20, 8)


@needs_torchrl
@pytest.mark.slow
def test_torchrl_parallel_env_with_make_env():
    from torchrl.envs import GymWrapper, ParallelEnv
    env = ParallelEnv(2, penny_env.make_env("PennyReach-Ellipse-v0", wrapper=GymWrapper))
    td = env.rollout(10, break_when_any_done=False)
    env.close()
    assert td["next", "observation"].shape == (2, 10, 10)


# -- 21.6: Gymnasium's conventions -------------------------------------------------------------
def test_make_vec_autoreset_mode_both_ways():
    native = gym.make_vec("PennyReach-Ellipse-v0", 2, autoreset_mode=AutoresetMode.SAME_STEP)
    assert native.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
    sync = gym.make_vec("PennyReach-Ellipse-v0", 2, vectorization_mode="sync",
                        vector_kwargs={"autoreset_mode": AutoresetMode.SAME_STEP})
    assert sync.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
    # gymnasium's own rule for vector entry points: arguments through kwargs only (docs/envs.md says so)
    with pytest.raises(gym.error.Error, match="only through kwargs"):
        gym.make_vec("PennyReach-Ellipse-v0", 2, vector_kwargs={"autoreset_mode": AutoresetMode.SAME_STEP})
    native.close(), sync.close()


def test_goal_env_on_gym_make_passes_the_checkers():
    from gymnasium.utils.env_checker import check_env
    env = gym.make("PennyReach-Ellipse-v0", goal_env=True)
    assert isinstance(env.unwrapped, PennyGoalEnv)
    assert set(env.observation_space.spaces) == {"observation", "achieved_goal", "desired_goal"}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warnings.filterwarnings("ignore", message='render_mode="human": no display')  # (as tests/envs/test_env.py)
        check_env(gym.make("PennyReach-Ellipse-v0", goal_env=True, render_mode="rgb_array").unwrapped,
                  skip_render_check=importlib.util.find_spec("pygame") is None)
    obs, _ = env.reset(seed=0)
    obs, r, term, trunc, info = env.step(env.action_space.sample())
    assert r == env.unwrapped.compute_reward(obs["achieved_goal"], obs["desired_goal"], info) == -1.0
    batch = env.unwrapped.compute_reward(np.zeros((5, 2)), np.zeros((5, 2)), [{}] * 5)
    assert batch.shape == (5,) and (batch == 0).all()
    assert pickle.loads(pickle.dumps(env.unwrapped)).observation_space == env.unwrapped.observation_space
    with pytest.raises(ValueError, match="reach task on a table"):
        gym.make("PennyImpacts-Stadium-v0", goal_env=True)
    with pytest.raises(ValueError, match="reach task on a table"):
        gym.make("PennyReach-Plane-v0", goal_env=True)
    with pytest.raises(TypeError, match="goal_env"):
        gym.make("PennyReach-Ellipse-v0", goal_env="yes")


@needs_sb3
def test_goal_env_with_sb3_her():
    from stable_baselines3 import SAC, HerReplayBuffer
    from stable_baselines3.common.env_checker import check_env
    from stable_baselines3.common.env_util import make_vec_env
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(gym.make("PennyReach-Ellipse-v0", goal_env=True).unwrapped)
    venv = make_vec_env(penny_env.make_env("PennyReach-Ellipse-v0", goal_env=True, max_episode_steps=20), n_envs=2)
    model = SAC("MultiInputPolicy", venv, replay_buffer_class=HerReplayBuffer, learning_starts=64, batch_size=32,
                replay_buffer_kwargs={"n_sampled_goal": 2}, policy_kwargs={"net_arch": [8]}, device="cpu")
    model.learn(200)
    assert model.num_timesteps >= 200


# -- 21.7: plain ids in worker processes -------------------------------------------------------
def test_make_env_pickles_and_checks_the_id():
    factory = penny_env.make_env("PennyReach-Ellipse-v0", max_episode_steps=7)
    again = pickle.loads(pickle.dumps(factory))
    env = again()
    assert env.spec.max_episode_steps == 7
    env.close()
    assert penny_env.make_env("penny_env:PennyReach-Ellipse-v0")().spec.id == "PennyReach-Ellipse-v0"
    with pytest.raises(ValueError, match="not registered"):
        penny_env.make_env("PennyReach-Elipse-v0")
    with pytest.raises(TypeError, match="env_id"):
        penny_env.make_env(3)


@needs_sb3
@pytest.mark.slow
@pytest.mark.parametrize("method", ["spawn", "forkserver"])
def test_sb3_subprocvecenv_with_plain_ids(method):
    if method not in multiprocessing.get_all_start_methods():
        pytest.skip(f"start method {method} is not available here")
    from stable_baselines3.common.vec_env import SubprocVecEnv
    venv = SubprocVecEnv([penny_env.make_env("PennyReach-Ellipse-v0") for _ in range(2)], start_method=method)
    venv.seed(0)
    obs = venv.reset()
    obs, rew, done, infos = venv.step(np.zeros((2, 2), np.float32))
    venv.close()
    assert obs.shape == (2, 10) and infos[0]["impact_times"].shape == (8,)


def test_goal_env_takes_any_task_registered_as_a_goal_task():
    """goal_env=True reads the task record's goal flag, not the task's name: a user's reach-like task registered with
    goal=True is a goal env with no edit of the package; the same task registered without it is refused."""
    import dataclasses

    import tests.step.example_task  # noqa: F401  (registers "hurry": reach in a hurry, its clock as entry 10)
    from penny_env import register_task
    from penny_env.sb3 import PennySB3VecEnv
    from penny_env.step.tasks import TASKS
    assert TASKS["reach"].goal and not TASKS["park"].goal and not TASKS["hurry"].goal
    register_task(dataclasses.replace(TASKS["hurry"], name="hurry_goal", goal=True))
    task = {"kind": "hurry_goal", "max_episode_steps": 50}
    env = gym.make("PennyReach-Ellipse-v0", goal_env=True, task=task, backend="python")
    obs, _ = env.reset(seed=0)
    assert obs["observation"].shape == (11,)
    assert np.array_equal(obs["desired_goal"], obs["observation"][0:2] + obs["observation"][8:10])
    assert isinstance(PennySB3VecEnv("PennyReach-Ellipse-v0", num_envs=2, goal_env=True, task=task,
                                     backend="python").observation_space, gym.spaces.Dict)
    with pytest.raises(ValueError, match="registered with goal=True"):
        gym.make("PennyReach-Ellipse-v0", goal_env=True, task={"kind": "hurry", "max_episode_steps": 50},
                 backend="python")
