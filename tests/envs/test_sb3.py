"""Stable-Baselines3 on the native vector env (short runs)."""
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
import torch  # noqa: E402
from stable_baselines3 import PPO, SAC  # noqa: E402
from stable_baselines3.common.vec_env import VecMonitor  # noqa: E402

from gymnasium.vector import AutoresetMode  # noqa: E402

from penny_env import PennyVectorEnv  # noqa: E402
from penny_env.sb3 import PennySB3VecEnv  # noqa: E402

torch.set_num_threads(1)


def test_adapter_semantics():
    venv = VecMonitor(PennySB3VecEnv("PennyReach-Ellipse-v0", num_envs=4, max_episode_steps=5))
    venv.seed(3)
    obs = venv.reset()
    assert obs.shape == (4, 10) and obs.dtype == np.float32
    for t in range(5):
        obs, rew, dones, infos = venv.step(np.zeros((4, 2), np.float32))
    assert dones.all()
    for info in infos:
        assert info["TimeLimit.truncated"] and not info["is_success"]
        assert info["terminal_observation"].shape == (10,)
        assert info["episode"]["l"] == 5
    assert not np.array_equal(obs[0], infos[0]["terminal_observation"])


def test_ppo_and_sac_train():
    venv = VecMonitor(PennySB3VecEnv("PennyImpacts-Stadium-v0", num_envs=8, max_episode_steps=32))
    model = PPO("MlpPolicy", venv, n_steps=32, batch_size=64, n_epochs=1, seed=0, device="cpu")
    model.learn(total_timesteps=512)
    assert len(model.ep_info_buffer) >= 8
    sac = SAC("MlpPolicy", PennySB3VecEnv("PennySteer-Plane-v0", num_envs=2, max_episode_steps=20),
              learning_starts=50, batch_size=32, seed=0, device="cpu", train_freq=1, gradient_steps=1)
    sac.learn(total_timesteps=120)


def test_sub_env_access_follows_the_vecenv_contract():
    from gymnasium.wrappers.vector import RecordEpisodeStatistics
    from stable_baselines3.common.monitor import Monitor

    venv = PennySB3VecEnv("PennyReach-Ellipse-v0", num_envs=3)
    venv.seed(0)
    venv.reset()
    assert venv.get_attr("action_space", indices=[1]) == [venv.action_space]
    rows = venv.get_attr("states", indices=[2, 0])
    assert len(rows) == 2 and np.array_equal(rows[0], venv.venv.states[2]) and np.array_equal(rows[1], venv.venv.states[0])
    assert venv.get_attr("num_envs", indices=[0, 1]) == [3, 3]
    with pytest.raises(ValueError, match="every index"):  # the sub-envs share it: no partial set
        venv.set_attr("render_mode", "rgb_array", indices=[1])
    with pytest.raises(ValueError, match="every index"):
        venv.env_method("reset", indices=[0])
    assert len(venv.env_method("reset")) == 3
    assert venv.env_is_wrapped(Monitor) == [False, False, False]
    wrapped = PennySB3VecEnv(venv=RecordEpisodeStatistics(PennyVectorEnv(2, autoreset_mode=AutoresetMode.SAME_STEP)))
    assert wrapped.env_is_wrapped(RecordEpisodeStatistics, indices=[1]) == [True]


def test_goal_env_and_her():
    from stable_baselines3 import HerReplayBuffer

    venv = PennySB3VecEnv("PennyReach-Ellipse-v0", num_envs=2, goal_env=True, max_episode_steps=25)
    venv.seed(0)
    obs = venv.reset()
    assert set(obs) == {"observation", "achieved_goal", "desired_goal"} and obs["desired_goal"].shape == (2, 2)
    assert venv.observation_space.contains({k: v[0] for k, v in obs.items()})
    target = venv.venv.targets[0] / venv.venv._core.L
    assert np.allclose(obs["desired_goal"][0], target, atol=1e-6)
    # compute_reward is vectorised, 0 at the goal and -1 away from it, and the step's reward uses it
    g = np.zeros((5, 2), np.float32)
    far = g + np.float32(0.5)
    assert venv.env_method("compute_reward", g, g, [{}] * 5, indices=[0])[0].tolist() == [0.0] * 5
    assert venv.compute_reward(g, far, None).tolist() == [-1.0] * 5
    o, r, d, infos = venv.step(np.zeros((2, 2), np.float32))
    assert np.array_equal(r, venv.compute_reward(o["achieved_goal"], o["desired_goal"], infos))
    model = SAC("MultiInputPolicy", venv, replay_buffer_class=HerReplayBuffer,
                replay_buffer_kwargs=dict(n_sampled_goal=4, goal_selection_strategy="future"),
                learning_starts=100, batch_size=32, seed=0, device="cpu", train_freq=1, gradient_steps=1)
    model.learn(total_timesteps=300)
    assert model.replay_buffer.size() > 0
    with pytest.raises(ValueError, match="reach"):
        PennySB3VecEnv("PennyImpacts-Stadium-v0", num_envs=2, goal_env=True)
