"""RL Zoo's hyperparameter optimisation (`-optimize`) runs on a penny id and writes its trials table
(it needs pandas, carried by the zoo extra: without it rl_zoo3 runs every trial and then fails)."""
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def test_zoo_extra_carries_what_optimize_needs():
    tomllib = pytest.importorskip("tomllib", reason="Python >= 3.11 (tomllib)")
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    assert any(dep.startswith("pandas") for dep in extras["zoo"]), "rl_zoo3 -optimize writes its table with pandas"


@pytest.mark.slow
def test_rl_zoo_optimize_writes_the_trials_table(tmp_path):
    pytest.importorskip("rl_zoo3", reason="RL Zoo (the penny-env[zoo] extra)")
    pytest.importorskip("optuna", reason="RL Zoo's -optimize")
    pytest.importorskip("pandas", reason="RL Zoo's -optimize trials table (the penny-env[zoo] extra)")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    # a tiny budget: 2 random trials of 256 steps on one env, one evaluation each, no plots (they open a browser)
    run = subprocess.run([sys.executable, "-m", "rl_zoo3.train", "--algo", "ppo", "--env", "PennyProbeBoth-Plane-v0",
                          "--gym-packages", "penny_env", "-conf", str(ROOT / "configs/rl_zoo/ppo.yml"), "-f", "logs",
                          "-optimize", "--n-trials", "2", "-n", "256", "--n-evaluations", "1", "--n-jobs", "1",
                          "--sampler", "random", "--pruner", "none", "--no-optim-plots", "--seed", "0",
                          "--hyperparams", "n_envs:1"],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    tables = list((tmp_path / "logs" / "ppo").glob("report_PennyProbeBoth-Plane-v0_2-trials-256-*.csv"))
    assert len(tables) == 1
    rows = tables[0].read_text().strip().splitlines()
    assert len(rows) == 3 and "params_learning_rate" in rows[0]  # header + one row per trial
