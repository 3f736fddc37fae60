"""Stable-Baselines3 on the native vector env (short runs)."""
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
import torch  # noqa: E402
from stable_baselines3 import PPO, SAC  # noqa: E402
from stable_baselines3.common.vec_env import VecMonitor  # noqa: E402

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
