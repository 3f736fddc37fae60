"""RL Zoo native: configs/rl_zoo/{ppo,sac}.yml cover every registered id, match their generator,
and `python -m rl_zoo3.train ... -conf configs/rl_zoo/ppo.yml` trains with n_envs > 1 and
`python -m rl_zoo3.enjoy` replays it."""
import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from penny_env.envs import env_ids
from training import zoo_configs

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_every_id_has_zoo_hyperparameters(algo):
    conf = yaml.safe_load((ROOT / "configs" / "rl_zoo" / f"{algo}.yml").read_text())
    assert set(conf) == set(env_ids())
    for env_id, entry in conf.items():
        assert entry["n_envs"] > 1 and entry["n_timesteps"] > 0 and entry["policy"] == "MlpPolicy", env_id


def test_zoo_files_match_the_generator():
    assert zoo_configs.main(["--check"]) == 0


def test_zoo_hyperparameters_are_accepted_by_sb3():
    pytest.importorskip("stable_baselines3", reason="checks SB3 constructor arguments")
    from training.runner import check_hyperparameters
    for algo in ("ppo", "sac"):
        entry = zoo_configs.zoo_hyperparameters(algo)
        zoo_only = {"n_envs", "n_timesteps", "policy", "policy_kwargs"}
        check_hyperparameters(algo, {k: v for k, v in entry.items() if k not in zoo_only})


@pytest.mark.slow
def test_rl_zoo_train_and_enjoy(tmp_path):
    pytest.importorskip("rl_zoo3", reason="RL Zoo")
    pytest.importorskip("requests", reason="rl_zoo3.enjoy imports requests")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    common = ["--algo", "ppo", "--env", "PennyProbeBoth-Plane-v0", "--gym-packages", "penny_env", "-f", str(tmp_path)]
    train = subprocess.run([sys.executable, "-m", "rl_zoo3.train", *common, "-conf", str(ROOT / "configs/rl_zoo/ppo.yml"),
                            "-n", "4096", "--seed", "0", "--eval-freq", "-1", "--verbose", "1"],
                           cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert train.returncode == 0, train.stderr[-3000:]
    assert "Using 16 environments" in train.stdout
    run = tmp_path / "ppo" / "PennyProbeBoth-Plane-v0_1"
    assert (run / "PennyProbeBoth-Plane-v0.zip").is_file()
    enjoy = subprocess.run([sys.executable, "-m", "rl_zoo3.enjoy", *common, "--exp-id", "1", "-n", "450",
                            "--no-render"], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert enjoy.returncode == 0, enjoy.stderr[-3000:]
    assert "Episode Length" in enjoy.stdout or "Mean episode length" in enjoy.stdout
