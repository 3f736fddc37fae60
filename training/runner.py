"""Train one SB3 agent on one env id into a run folder, with the tooling users expect:

    RUN_DIR/config.json      what was trained (env_id, algo, seed, timesteps, num_envs, hyperparameters)
    RUN_DIR/progress.csv     SB3's CSV log (train/* and eval/* rows)
    RUN_DIR/events.out.tfevents.*  TensorBoard events (``tensorboard --logdir RUN_DIR``)
    RUN_DIR/curve.csv        evaluation during training: timesteps, success_rate, mean_return
    RUN_DIR/checkpoints/     model_<steps>_steps.zip every checkpoint_freq steps
    RUN_DIR/model.zip        the final model (``python -m training.evaluate RUN_DIR``)

Seeds: the model (torch, action sampling), the training envs (sub-env i: seed + i) and the
evaluation episodes (seeds from eval_seed(seed)) all derive from ``seed``; on CPU with one torch
thread a rerun gives the same model.
"""
from __future__ import annotations

import copy
import csv
import inspect
import json
from pathlib import Path

import numpy as np

ALGOS = ("ppo", "sac")
# set by the runner itself, not hyperparameters
_RESERVED = {"policy", "env", "seed", "verbose", "tensorboard_log", "device", "_init_setup_model"}


def algo_class(algo: str):
    if algo not in ALGOS:
        raise ValueError(f"unknown algorithm {algo!r}; known: {list(ALGOS)}")
    from stable_baselines3 import PPO, SAC
    return {"ppo": PPO, "sac": SAC}[algo]


def check_hyperparameters(algo: str, hyper: dict) -> None:
    """ValueError naming any key the algorithm's constructor does not take."""
    if not isinstance(hyper, dict):
        raise ValueError(f"hyperparameters of {algo} must be a mapping, got {type(hyper).__name__}")
    known = set(inspect.signature(algo_class(algo).__init__).parameters) - _RESERVED - {"self"}
    unknown = sorted(set(hyper) - known)
    if unknown:
        raise ValueError(f"unknown {algo} hyperparameter(s) {unknown}; known: {sorted(known)}")


def eval_seed(seed: int) -> int:
    """First seed of the evaluation episodes of a job seed (disjoint from training seeds)."""
    return 1_000_000 + 10_000 * int(seed)


def make_train_env(env_id: str, num_envs: int, seed: int):
    from stable_baselines3.common.vec_env import VecMonitor
    from penny_env.sb3 import PennySB3VecEnv
    from training.episodes import make_vector_env
    make_vector_env(env_id, 1).close()  # names an unknown id clearly
    venv = VecMonitor(PennySB3VecEnv(env_id, num_envs=num_envs))
    venv.seed(seed)
    return venv


def success_eval_callback(env_id: str, every: int, episodes: int, seed: int, out_csv: Path):
    """An SB3 callback: every `every` env steps, run `episodes` deterministic episodes (fixed
    seeds) and log eval/success_rate (from info["is_success"]) and eval/mean_return to SB3's
    logger (CSV, TensorBoard) and to out_csv."""
    from stable_baselines3.common.callbacks import BaseCallback
    from training.episodes import run_episodes

    class SuccessEval(BaseCallback):
        def __init__(self):
            super().__init__()
            self.next = 0
            self.rows = []

        def _evaluate(self):
            r = run_episodes(env_id, lambda o: self.model.predict(o, deterministic=True)[0], episodes, seed)
            row = (self.num_timesteps, float(np.mean(r["success"])), float(np.mean(r["return"])))
            self.rows.append(row)
            self.logger.record("eval/success_rate", row[1])
            self.logger.record("eval/mean_return", row[2])
            with open(out_csv, "w", newline="") as f:
                w = csv.writer(f)
                w.writerow(["timesteps", "success_rate", "mean_return"])
                w.writerows(self.rows)

        def _on_training_start(self):
            self._evaluate()
            self.next = every

        def _on_step(self):
            if self.num_timesteps >= self.next:
                self._evaluate()
                self.next += every
            return True

        def _on_training_end(self):
            # the final model, unless the last evaluation was just before (PPO ends on a rollout multiple)
            if not self.rows or self.num_timesteps - self.rows[-1][0] >= every / 2:
                self._evaluate()

    return SuccessEval()


def train_agent(run_dir, env_id: str, algo: str, seed: int, timesteps: int, num_envs: int = 8,
                hyperparameters: dict | None = None, eval_points: int = 10, eval_episodes: int = 32,
                checkpoints: int = 2):
    """Train, log, checkpoint and save; returns the model."""
    import torch
    from stable_baselines3.common.callbacks import CallbackList, CheckpointCallback
    from stable_baselines3.common.logger import configure

    hyper = copy.deepcopy(dict(hyperparameters or {}))  # SB3 writes into policy_kwargs (use_sde): not into the caller's job
    check_hyperparameters(algo, hyper)
    Algo = algo_class(algo)
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(1)
    venv = make_train_env(env_id, num_envs, seed)
    cfg = {"env_id": env_id, "algo": algo, "seed": seed, "timesteps": timesteps, "num_envs": num_envs,
           "hyperparameters": hyper}
    (run_dir / "config.json").write_text(json.dumps(cfg, indent=2))
    model = Algo("MlpPolicy", venv, seed=seed, verbose=0, device="cpu", **hyper)
    model.set_logger(configure(str(run_dir), ["csv", "tensorboard"]))
    every = max(1, timesteps // max(1, eval_points))
    ckpt_every = max(1, timesteps // max(1, checkpoints) // num_envs)
    callbacks = CallbackList([
        success_eval_callback(env_id, every, eval_episodes, eval_seed(seed) + 5_000, run_dir / "curve.csv"),
        CheckpointCallback(ckpt_every, str(run_dir / "checkpoints"), name_prefix="model"),
    ])
    model.learn(total_timesteps=timesteps, callback=callbacks)
    model.save(run_dir / "model.zip")
    venv.close()
    return model


def load_run(run_dir):
    """(config, model) of a run folder; ValueError naming a missing or incompatible file."""
    run_dir = Path(run_dir)
    cfg_path, model_path = run_dir / "config.json", run_dir / "model.zip"
    if not cfg_path.is_file():
        raise ValueError(f"{cfg_path}: missing (not a run folder of training.runner?)")
    if not model_path.is_file():
        raise ValueError(f"{model_path}: missing model file")
    try:
        cfg = json.loads(cfg_path.read_text())
        Algo = algo_class(cfg["algo"])
        env_id = cfg["env_id"]
    except (json.JSONDecodeError, KeyError, TypeError) as exc:
        raise ValueError(f"{cfg_path}: invalid run config ({exc!r})") from None
    from training.episodes import make_vector_env
    venv = make_vector_env(env_id, 1)
    try:
        model = Algo.load(model_path, device="cpu")
    except Exception as exc:  # zip errors, pickle errors, wrong algorithm class
        raise ValueError(f"{model_path}: cannot be loaded as a {cfg['algo']} model ({type(exc).__name__}: {exc})") from None
    if (model.observation_space.shape != venv.single_observation_space.shape
            or model.action_space.shape != venv.single_action_space.shape):
        raise ValueError(f"{model_path}: incompatible with {env_id}: model spaces {model.observation_space.shape} -> "
                         f"{model.action_space.shape}, env {venv.single_observation_space.shape} -> "
                         f"{venv.single_action_space.shape}")
    venv.close()
    return cfg, model
