"""Train a Stable-Baselines3 baseline on a penny_env id, then evaluate it against random and
zero actions on fresh seeds.

    python -m training.train --config configs/train/ppo_reach_ellipse.yaml [--quick] [--out runs/NAME]

The config (YAML) names env_id, algo (ppo or sac), num_envs, total_timesteps, seed,
eval_episodes, algo_kwargs and policy_kwargs; --set key=value overrides a top-level field.
The run writes model.zip, results.json and results.md to --out (default runs/<config name>;
--quick without --out: a new temporary directory).
"""
from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

ALGOS = ("ppo", "sac")
FIELDS = {"env_id", "algo", "num_envs", "total_timesteps", "seed", "eval_episodes", "algo_kwargs", "policy_kwargs"}


def load_config(path, overrides=()):
    """Read and check a training config; unknown or invalid fields raise ValueError naming them."""
    try:
        cfg = yaml.safe_load(Path(path).read_text())
    except yaml.YAMLError as exc:
        raise ValueError(f"{path}: invalid YAML: {exc}") from None
    if not isinstance(cfg, dict):
        raise ValueError(f"{path}: a training config must be a mapping of fields")
    for item in overrides:
        key, _, value = item.partition("=")
        cfg[key] = yaml.safe_load(value)
    unknown = set(cfg) - FIELDS
    if unknown:
        raise ValueError(f"{path}: unknown field(s) {sorted(unknown)}; known: {sorted(FIELDS)}")
    import gymnasium as gym
    import penny_env  # noqa: F401  (registers the ids)
    if cfg.get("env_id") not in gym.registry:
        raise ValueError(f"{path}: env_id {cfg.get('env_id')!r} is not a registered id")
    if cfg.get("algo") not in ALGOS:
        raise ValueError(f"{path}: algo must be one of {ALGOS}, got {cfg.get('algo')!r}")
    for key, default in (("num_envs", 8), ("total_timesteps", 100_000), ("seed", 0), ("eval_episodes", 100)):
        value = cfg.setdefault(key, default)
        if isinstance(value, bool) or not isinstance(value, int) or value < (0 if key == "seed" else 1):
            raise ValueError(f"{path}: {key} must be a {'non-negative' if key == 'seed' else 'positive'} integer, got {value!r}")
    cfg.setdefault("algo_kwargs", {})
    cfg.setdefault("policy_kwargs", {})
    return cfg


def evaluate(env_id, policy, episodes, seed, num_envs=16):
    """Mean return, success rate and mean length of `policy(obs) -> actions` over full episodes."""
    from penny_env.sb3 import PennySB3VecEnv
    venv = PennySB3VecEnv(env_id, num_envs=num_envs)
    venv.seed(seed)
    obs = venv.reset()
    returns, successes, lengths = [], [], []
    ep_ret = np.zeros(num_envs)
    ep_len = np.zeros(num_envs, dtype=int)
    while len(returns) < episodes:
        obs, rew, done, infos = venv.step(policy(obs))
        ep_ret += rew
        ep_len += 1
        for i in np.flatnonzero(done):
            returns.append(ep_ret[i])
            lengths.append(ep_len[i])
            successes.append(bool(infos[i].get("is_success", False)))
            ep_ret[i] = 0.0
            ep_len[i] = 0
    venv.close()
    k = episodes
    return {"mean_return": float(np.mean(returns[:k])), "success_rate": float(np.mean(successes[:k])),
            "mean_length": float(np.mean(lengths[:k])), "episodes": k}


def _progress_bar_installed() -> bool:
    """SB3's progress bar needs tqdm and rich (the [train] extra); without them training runs without it."""
    import importlib.util
    return all(importlib.util.find_spec(m) is not None for m in ("tqdm", "rich"))


def train(cfg, out: Path, quick: bool = False):
    import torch
    from stable_baselines3 import PPO, SAC
    from stable_baselines3.common.vec_env import VecMonitor
    from penny_env.sb3 import PennySB3VecEnv

    torch.set_num_threads(1)
    total = 2_048 if quick else cfg["total_timesteps"]
    n_eval = 8 if quick else cfg["eval_episodes"]
    venv = VecMonitor(PennySB3VecEnv(cfg["env_id"], num_envs=cfg["num_envs"]))
    venv.seed(cfg["seed"])
    algo_kwargs = dict(cfg["algo_kwargs"])
    if quick and cfg["algo"] == "ppo":
        algo_kwargs.update(n_steps=32, batch_size=256, n_epochs=2)
    if quick and cfg["algo"] == "sac":
        algo_kwargs.update(learning_starts=256, buffer_size=10_000)
    Algo = PPO if cfg["algo"] == "ppo" else SAC
    model = Algo("MlpPolicy", venv, seed=cfg["seed"], policy_kwargs=cfg["policy_kwargs"], verbose=0, **algo_kwargs)
    t0 = time.perf_counter()
    model.learn(total_timesteps=total, progress_bar=not quick and _progress_bar_installed())
    seconds = time.perf_counter() - t0
    out.mkdir(parents=True, exist_ok=True)
    model.save(out / "model.zip")

    act_space = venv.action_space
    rng = np.random.default_rng(cfg["seed"] + 1)
    eval_seed = 10_000 + cfg["seed"]
    results = {
        "config": cfg, "quick": quick, "timesteps": total, "train_seconds": seconds,
        "trained": evaluate(cfg["env_id"], lambda o: model.predict(o, deterministic=True)[0], n_eval, eval_seed),
        "random": evaluate(cfg["env_id"], lambda o: rng.uniform(-1, 1, (len(o),) + act_space.shape).astype(np.float32),
                           n_eval, eval_seed),
        "zero": evaluate(cfg["env_id"], lambda o: np.zeros((len(o),) + act_space.shape, np.float32), n_eval, eval_seed),
    }
    (out / "results.json").write_text(json.dumps(results, indent=2))
    rows = [f"| {name} | {r['mean_return']:.3f} | {r['success_rate']:.3f} | {r['mean_length']:.1f} |"
            for name, r in ((k, results[k]) for k in ("trained", "random", "zero"))]
    md = [f"# {cfg['algo'].upper()} on {cfg['env_id']}", "",
          f"{total} timesteps on {cfg['num_envs']} vectorized envs in {seconds:.0f} s (seed {cfg['seed']}); "
          f"evaluation on {n_eval} episodes with seeds from {eval_seed}.", "",
          "| policy | mean return | success rate | mean length |", "|---|---|---|---|", *rows, ""]
    (out / "results.md").write_text("\n".join(md))
    print("\n".join(md))
    venv.close()
    return results


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", required=True, help="training config (YAML), e.g. configs/train/ppo_reach_ellipse.yaml")
    ap.add_argument("--out", default=None, help="output folder (default: runs/<config name> under the working "
                                                "directory; --quick: a new temporary directory)")
    ap.add_argument("--quick", action="store_true", help="a few thousand steps: checks the pipeline, learns nothing")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a config field")
    args = ap.parse_args(argv)
    cfg = load_config(args.config, args.set)
    if args.out:
        out = Path(args.out).resolve()
    elif args.quick:  # a quick run checks the pipeline: it never writes over a real run
        out = Path(tempfile.mkdtemp(prefix="penny_env-quick-")) / Path(args.config).stem
    else:
        out = (Path("runs") / Path(args.config).stem).resolve()
    return train(cfg, out, quick=args.quick)


if __name__ == "__main__":
    main()
