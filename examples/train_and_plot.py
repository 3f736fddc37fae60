"""From install to a trained agent and a plot: PPO learns to roll the penny to a target on the paper's
elliptic table (PennyReach-Ellipse-v0), then one figure shows its learning curve beside one of its episodes.

Install, from the root of a clone of the repository (penny_env is not on a package index yet; on a machine
with an NVIDIA GPU take the CUDA build of torch instead, see the README):

    python3 -m venv .venv && . .venv/bin/activate
    pip install torch --index-url https://download.pytorch.org/whl/cpu
    pip install -e ".[train,plot]"

Run:

    python examples/train_and_plot.py            # 200,000 env steps (25 s on one core of a shared AMD EPYC, 2026-11-26)
    python examples/train_and_plot.py --quick    # a check that it runs: 8,192 steps, learns nothing

It prints the success rate of the trained policy and of uniformly random actions on the same fresh
episodes, and writes train_and_plot.png into --out (default runs/example/ under the working directory;
--quick: a new temporary folder). The PPO settings are those of configs/train/ppo_reach_ellipse.yaml.
"""
from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import gymnasium as gym
import numpy as np

import penny_env  # noqa: F401  (registers the ids)

ENV_ID = "PennyReach-Ellipse-v0"
EVAL_SEED = 10_000  # evaluation episodes use seeds EVAL_SEED, EVAL_SEED + 1, ...: none of the training seeds


def run_episode(env, policy, seed: int):
    """One episode: (success, the contact point's path as an (n, 2) array, the points where it hit the wall)."""
    obs, info = env.reset(seed=seed)
    path, hits, done = [env.unwrapped.state[:2]], [], False
    while not done:
        obs, _, terminated, truncated, info = env.step(policy(obs))
        path.append(env.unwrapped.state[:2])
        if info["impacts"]:
            hits.append(path[-1])
        done = terminated or truncated
    return bool(info["is_success"]), np.array(path), np.array(hits).reshape(-1, 2)


def success_rate(policy, episodes: int) -> float:
    env = gym.make(ENV_ID)
    rate = np.mean([run_episode(env, policy, EVAL_SEED + i)[0] for i in range(episodes)])
    env.close()
    return float(rate)


def train(total_steps: int, points: int, episodes: int):
    """PPO on the native vector env, evaluated `points` times along the way; returns (model, curve)."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecMonitor
    from penny_env.sb3 import PennySB3VecEnv

    torch.set_num_threads(1)  # small networks: one thread is the fastest
    venv = VecMonitor(PennySB3VecEnv(ENV_ID, num_envs=32))
    venv.seed(0)
    model = PPO("MlpPolicy", venv, n_steps=128, batch_size=1024, n_epochs=10, learning_rate=3e-4, seed=0,
                policy_kwargs={"net_arch": [64, 64]}, device="cpu")
    policy = lambda obs: model.predict(obs, deterministic=True)[0]  # noqa: E731
    curve = [(0, success_rate(policy, episodes))]
    for k in range(1, points + 1):
        if total_steps * k // points <= model.num_timesteps:  # a rollout (32 x 128 steps) may overshoot a point
            continue
        model.learn(total_steps * k // points - model.num_timesteps, reset_num_timesteps=False)
        curve.append((model.num_timesteps, success_rate(policy, episodes)))
        print(f"{model.num_timesteps:>9,} steps: success {curve[-1][1]:.2f} over {episodes} fresh episodes", flush=True)
    venv.close()
    return model, curve


def plot(curve, random_rate: float, episode, path: Path):
    import matplotlib
    import matplotlib.ticker
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    env = gym.make(ENV_ID)
    env.reset(seed=EVAL_SEED)
    table = env.unwrapped.scene.make_table().boundary()
    target, tolerance = env.unwrapped.target, env.unwrapped.task.tolerance
    success, track, hits = episode
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4.2))
    steps, rates = zip(*curve)
    ax1.plot(steps, rates, "o-", label="PPO (deterministic policy)")
    ax1.axhline(random_rate, color="grey", ls="--", label="uniformly random actions")
    ax1.xaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda v, _: f"{v / 1000:g}k"))
    ax1.set(xlabel="env steps", ylabel="success rate", ylim=(-0.02, 1.02), title=f"Learning curve, {ENV_ID}")
    ax1.legend(loc="upper left")
    ax2.plot(table[:, 0], table[:, 1], "k-", lw=1.5)
    ax2.add_patch(plt.Circle(tuple(target), tolerance, color="tab:blue", alpha=0.4))
    ax2.plot(track[:, 0], track[:, 1], "-", color="tab:orange", lw=1)
    ax2.plot(*track[0], "o", color="tab:orange")
    if len(hits):
        ax2.plot(hits[:, 0], hits[:, 1], "o", mfc="none", color="gold", ms=9, label="end of a step with an impact")
        ax2.legend(loc="lower right")
    ax2.set(aspect="equal", xlabel="x [m] (contact point, once per control period)", ylabel="y [m]",
            title=f"Episode seed {EVAL_SEED}: {'reached the target' if success else 'missed the target'}")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    env.close()


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--steps", type=int, default=200_000, help="env steps of training (default 200,000)")
    ap.add_argument("--episodes", type=int, default=50, help="fresh episodes per evaluation (default 50)")
    ap.add_argument("--out", default=None, help="output folder (default runs/example; --quick: a temporary folder)")
    ap.add_argument("--quick", action="store_true", help="8,192 steps and 4 episodes per evaluation: checks it runs")
    args = ap.parse_args(argv)
    steps, episodes = (8_192, 4) if args.quick else (args.steps, args.episodes)
    if steps < 1 or episodes < 1:
        ap.error("--steps and --episodes must be positive")
    if args.out:
        out = Path(args.out)
    elif args.quick:
        out = Path(tempfile.mkdtemp(prefix="penny_env-example-"))
    else:
        out = Path("runs") / "example"
    out.mkdir(parents=True, exist_ok=True)

    model, curve = train(steps, 2 if args.quick else 5, episodes)
    rng = np.random.default_rng(0)
    random_rate = success_rate(lambda obs: rng.uniform(-1, 1, 2).astype(np.float32), episodes)
    print(f"trained PPO: success {curve[-1][1]:.2f}; uniformly random actions: {random_rate:.2f} "
          f"(the same {episodes} fresh episodes)")
    env = gym.make(ENV_ID)
    episode = run_episode(env, lambda obs: model.predict(obs, deterministic=True)[0], EVAL_SEED)
    env.close()
    figure = out / "train_and_plot.png"
    plot(curve, random_rate, episode, figure)
    print(f"wrote {figure}")
    return {"curve": curve, "random": random_rate, "figure": figure}


if __name__ == "__main__":
    main()
