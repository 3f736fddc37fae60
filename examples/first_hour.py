# ---
# jupyter:
#   jupytext:
#     text_representation:
#       extension: .py
#       format_name: percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # Your first hour with penny_env
#
# From install to a trained agent and a plot. This file is a notebook in jupytext's percent format: open it in
# Jupyter (with jupytext installed, `pip install jupytext`, it opens as a notebook), in VS Code (each `# %%` is a
# cell), or run it whole as a script:
#
#     python examples/first_hour.py                        # about 200,000 env steps of PPO: minutes on a laptop
#     PENNY_ENV_QUICK=1 python examples/first_hour.py      # a check that every cell runs (what the tests run)
#
# **Install**, from the root of a clone of the repository (on a machine with an NVIDIA GPU take the CUDA build
# of torch instead, see the README):
#
#     python3 -m venv .venv && . .venv/bin/activate
#     pip install torch --index-url https://download.pytorch.org/whl/cpu
#     pip install -e ".[train,plot]"
#
# The first use of each table shape compiles the simulator with numba: about 10 to 30 s on a quiet machine,
# minutes on a busy or small one. A line says when it starts, every 30 s while it runs, and when it is done;
# later runs load the machine code from numba's cache in about a second.

# %%
import os
import sys
import tempfile
from pathlib import Path

import gymnasium as gym
import numpy as np

import penny_env as pe  # registers the environment ids (PennyReach-Ellipse-v0, ...)

QUICK = os.environ.get("PENNY_ENV_QUICK") == "1"  # a few thousand steps: checks the cells, learns nothing
ENV_ID = "PennyReach-Ellipse-v0"
REPO = Path(pe.__file__).resolve().parents[1]  # the clone (training/ and configs/ live there)
sys.path.insert(0, str(REPO))  # training/ is the clone's folder of commands, not an installed package
# every run gets a new folder (a training run refuses to write into another run's folder)
OUT = Path(os.environ.get("PENNY_ENV_OUT") or tempfile.mkdtemp(prefix="first_hour-"))
print("outputs go to", OUT)

# %% [markdown]
# ## 1. Make, reset, step
#
# An environment is a Gymnasium env: the penny (a vertical rolling disk) on the paper's elliptic table, two
# torques as the action (steering and rolling, each in [-1, 1]), and a target to reach with the contact point.

# %%
env = gym.make(ENV_ID)
obs, info = env.reset(seed=0)
print("observation:", obs.round(3))
total, done, steps = 0.0, False, 0
while not done:
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    total, steps, done = total + reward, steps + 1, terminated or truncated
print(f"a random episode: {steps} steps, return {total:.2f}, success {info['is_success']}")
env.close()

# %% [markdown]
# ## 2. The physics underneath
#
# `penny_env.simulate` runs the exact event-driven simulator: every impact of an end of the penny with the wall is
# found and resolved by the impact law. Here an elastic penny rolls and spins for two seconds.

# %%
traj = pe.simulate([0.0, 0.0, 0.0, 0.3, 10.0, 0.5], table=pe.Ellipse(0.15, 0.2), law="elastic", t_final=2.0)
print(f"{traj.n_impacts} impacts, the first at t = {traj.impact_times[0]:.4f} s; kinetic energy kept: "
      f"{np.ptp(traj.energies()) / traj.energies()[0]:.1e} relative spread")

# %% [markdown]
# ## 3. Train an agent
#
# `training.train` is the repository's training command (PPO from Stable-Baselines3 on the native vector env);
# here it runs in this process. From a shell the same run is
# `python -m training.train --config configs/train/ppo_reach_ellipse.yaml --set total_timesteps=200000`.

# %%
from training import train  # noqa: E402  (the clone's training/ folder)

args = ["--config", str(REPO / "configs" / "train" / "ppo_reach_ellipse.yaml"), "--out", str(OUT / "run"),
        "--progress-seconds", "15"]
args += ["--quick"] if QUICK else ["--set", "total_timesteps=200000", "--set", "eval_episodes=100"]
results = train.main(args)
print(f"trained: success {results['trained']['success_rate']:.2f}, random actions "
      f"{results['random']['success_rate']:.2f} on the same fresh episodes")

# %% [markdown]
# ## 4. Plot the learning curve and an episode
#
# The run folder holds the evaluations made during training (`curve.csv`), the final model (`model.zip`) and the
# best one (`best_model.zip`, chosen on fresh episodes against the final model: `best.json` says which).

# %%
import csv  # noqa: E402

import matplotlib.pyplot as plt  # noqa: E402
from stable_baselines3 import PPO  # noqa: E402

with open(OUT / "run" / "curve.csv") as f:
    curve = [(float(r["timesteps"]), float(r["success_rate"])) for r in csv.DictReader(f)]
model = PPO.load(OUT / "run" / "model.zip", device="cpu")

env = gym.make(ENV_ID)
obs, info = env.reset(seed=10_000)
path, done = [env.unwrapped.state[:2]], False
while not done:
    obs, _, terminated, truncated, info = env.step(model.predict(obs, deterministic=True)[0])
    path.append(env.unwrapped.state[:2])
    done = terminated or truncated
path = np.array(path)
wall = env.unwrapped.scene.make_table().boundary()
target, tolerance = env.unwrapped.target, env.unwrapped.task.tolerance
env.close()

fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4.2))
ax1.plot(*zip(*curve), "o-")
ax1.set(xlabel="env steps", ylabel="success rate (deterministic policy)", ylim=(-0.02, 1.02),
        title=f"Learning curve, {ENV_ID}")
ax2.plot(wall[:, 0], wall[:, 1], "k-", lw=1.5)
ax2.add_patch(plt.Circle(tuple(target), tolerance, color="tab:blue", alpha=0.4))
ax2.plot(path[:, 0], path[:, 1], "-", color="tab:orange")
ax2.plot(*path[0], "o", color="tab:orange")
ax2.set(aspect="equal", xlabel="x [m]", ylabel="y [m]",
        title=f"One episode: {'reached' if info['is_success'] else 'missed'} the target")
fig.tight_layout()
fig.savefig(OUT / "first_hour.png", dpi=110)
print("wrote", OUT / "first_hour.png")
if "inline" in plt.get_backend() or plt.get_backend().lower() != "agg":
    plt.show()  # (in a notebook, the figure below the cell)

# %% [markdown]
# ## Where next
#
# * `python -m training.evaluate RUN_FOLDER --best` scores the best and the final model with 95 % intervals;
# * `docs/extending.md` adds a table shape, an impact law or a task of your own;
# * `docs/envs.md` lists the environments, their observations and their limits.
