"""Train a Stable-Baselines3 baseline on a penny_env id, then evaluate it against random and
zero actions on fresh seeds.

    python -m training.train --config configs/train/ppo_reach_ellipse.yaml [--quick] [--out runs/NAME]
                             [--resume RUN_DIR_OR_CHECKPOINT] [--progress-seconds 30] [--keep-replay-buffers]

The config (YAML) names env_id, algo (ppo or sac), num_envs, total_timesteps, seed,
eval_episodes, algo_kwargs and policy_kwargs, and optionally checkpoint_freq (env steps between
checkpoints, default total_timesteps / 10), curve_points (evaluations during training, default 10)
and curve_episodes (episodes per evaluation, default 32); --set key=value overrides a field, and a dotted key one
hyperparameter (--set algo_kwargs.learning_rate=1e-3).

The run folder (--out; default runs/<config name>; --quick without --out: a new temporary
directory) has training.runner's layout, which training.evaluate reads: config.json, model.zip,
best_model.zip (the better of the best evaluation during training and the final model on eval_episodes fresh
episodes; best.json and results.md report both, training.best_choice), checkpoints/, curve.csv, progress.csv, TensorBoard
events (``tensorboard --logdir runs``), plus results.json and results.md: the trained policy
against zero and random actions on fresh seeds. The folder is printed at the start and the end.
On a terminal SB3's progress bar shows; elsewhere (nohup, a scheduler, CI) a line every
--progress-seconds gives steps, steps/s, the last evaluation's success and the time left.
--out must be empty or new unless --resume, and one run writes a folder at a time (a lock: training.run_folder).
--resume goes on from a checkpoint (a run folder: its newest intact one; SAC: with its replay buffer), with the
same num_envs, env_id, algo, seed and hyperparameters (only total_timesteps may change), appends to
progress.csv and reports the whole run's training time in results.md. Ctrl-C during training saves a
checkpoint and prints one line with the exact command that resumes the run. SAC checkpoints keep only the
newest replay buffer (each holds up to buffer_size transitions) unless --keep-replay-buffers.
"""
from __future__ import annotations

import argparse
import json
import shlex
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

ALGOS = ("ppo", "sac")
FIELDS = {"env_id", "algo", "num_envs", "total_timesteps", "seed", "eval_episodes", "algo_kwargs", "policy_kwargs",
          "checkpoint_freq", "curve_points", "curve_episodes"}


NESTED = ("algo_kwargs", "policy_kwargs")  # the fields that are mappings: --set algo_kwargs.learning_rate=1e-3


def parse_set(item: str) -> tuple[list[str], object]:
    """(key path, value) of one --set KEY=VALUE: the value read as YAML, a dotted key a path into a mapping field
    (algo_kwargs.learning_rate). ValueError naming the item otherwise."""
    from penny_env.envs.yaml_io import safe_load as yaml_load
    key, eq, value = item.partition("=")
    path = key.strip().split(".")
    if not eq or not all(path):
        raise ValueError(f"--set {item!r}: give KEY=VALUE, e.g. --set seed=1, or a dotted key into "
                         f"{' or '.join(NESTED)}: --set algo_kwargs.learning_rate=1e-3")
    try:
        return path, yaml_load(value)
    except yaml.YAMLError as exc:
        first = " ".join(str(exc).split())
        raise ValueError(f"--set {item!r}: the value {value!r} is not valid YAML ({first}); quote it in the shell, "
                         "e.g. --set 'policy_kwargs={net_arch: [64, 64]}'") from None


def apply_set(cfg: dict, path: list[str], value, item: str) -> None:
    """cfg[path[0]][path[1]]... = value, making the mappings on the way (a dotted key into algo_kwargs or
    policy_kwargs); ValueError for an unknown field or a path through a value that is not a mapping."""
    if path[0] not in FIELDS:
        raise ValueError(f"--set {item!r}: unknown field {path[0]!r}; known: {sorted(FIELDS)} (one hyperparameter: "
                         "--set algo_kwargs.learning_rate=1e-3)")
    if len(path) > 1 and path[0] not in NESTED:
        raise ValueError(f"--set {item!r}: {path[0]} is not a mapping; dotted keys go into {' or '.join(NESTED)}")
    node = cfg
    for depth, key in enumerate(path[:-1]):
        child = node.get(key)
        if child is None:
            child = node[key] = {}
        if not isinstance(child, dict):
            raise ValueError(f"--set {item!r}: {'.'.join(path[:depth + 1])} is {child!r}, not a mapping")
        node = child
    node[path[-1]] = value


def load_config(path, overrides=()):
    """Read and check a training config; a missing, unreadable or invalid file, unknown or invalid fields and
    malformed --set items raise ValueError naming them. overrides: KEY=VALUE strings (--set), KEY a field or a
    dotted path into algo_kwargs / policy_kwargs."""
    from penny_env.envs.yaml_io import read_text
    from penny_env.envs.yaml_io import safe_load as yaml_load  # (1e-2 read as a float, as in YAML 1.2)
    text = read_text(path, "training config")
    try:
        cfg = yaml_load(text)
    except yaml.YAMLError as exc:
        raise ValueError(f"{path}: invalid YAML: {exc}") from None
    if not isinstance(cfg, dict):
        raise ValueError(f"{path}: a training config must be a mapping of fields")
    unknown = set(map(str, cfg)) - FIELDS
    if unknown:
        raise ValueError(f"{path}: unknown field(s) {sorted(unknown)}; known: {sorted(FIELDS)}")
    for item in overrides:
        apply_set(cfg, *parse_set(item), item)
    for key in ("env_id", "algo"):
        if not isinstance(cfg.get(key), str):
            raise ValueError(f"{path}: {key} must be a string, got {type(cfg.get(key)).__name__} {cfg.get(key)!r}")
    import gymnasium as gym
    import penny_env  # noqa: F401  (registers the ids)
    if cfg["env_id"] not in gym.registry:
        raise ValueError(f"{path}: env_id {cfg['env_id']!r} is not a registered id")
    if cfg["algo"] not in ALGOS:
        raise ValueError(f"{path}: algo must be one of {ALGOS}, got {cfg['algo']!r}")
    for key, default in (("num_envs", 8), ("total_timesteps", 100_000), ("seed", 0), ("eval_episodes", 100),
                         ("checkpoint_freq", None), ("curve_points", 10), ("curve_episodes", 32)):
        if default is None:  # checkpoint_freq: ten checkpoints per run unless the config says
            default = max(1, cfg["total_timesteps"] // 10)
        value = cfg.setdefault(key, default)
        if isinstance(value, bool) or not isinstance(value, int) or value < (0 if key == "seed" else 1):
            raise ValueError(f"{path}: {key} must be a {'non-negative' if key == 'seed' else 'positive'} integer, got {value!r}")
    for key in NESTED:
        if cfg.setdefault(key, {}) is None:
            cfg[key] = {}
        if not isinstance(cfg[key], dict):
            raise ValueError(f"{path}: {key} must be a mapping of hyperparameters, got {type(cfg[key]).__name__}")
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


def progress_mode(stream=None) -> str:
    """'bar' on a terminal (with tqdm and rich), else 'lines': a bar draws nothing under nohup or CI."""
    import sys
    stream = sys.stdout if stream is None else stream
    isatty = getattr(stream, "isatty", None)
    return "bar" if isatty is not None and isatty() and _progress_bar_installed() else "lines"


def train(cfg, out: Path, quick: bool = False, resume=None, progress: str | None = None,
          progress_seconds: float = 30.0, keep_replay_buffers: bool = False):
    """Train into the run folder `out` (training.runner's layout), then compare the trained policy
    with zero and random actions; returns the results (also results.json, results.md). Ctrl-C during
    training raises training.runner.TrainingInterrupted after saving a checkpoint."""
    from training.run_folder import check_new_folder, run_lock

    out = Path(out)
    with run_lock(out):  # (one run writes a folder at a time: training.run_folder)
        if resume is None:
            check_new_folder(out)
        return _train(cfg, out, quick, resume, progress, progress_seconds, keep_replay_buffers)


def _train(cfg, out: Path, quick, resume, progress, progress_seconds, keep_replay_buffers):
    from training.best_choice import describe
    from training.runner import train_agent

    print(f"output folder: {out}", flush=True)
    total = 2_048 if quick else cfg["total_timesteps"]
    n_eval = 8 if quick else cfg["eval_episodes"]
    algo_kwargs = dict(cfg["algo_kwargs"])
    if quick and cfg["algo"] == "ppo":
        algo_kwargs.update(n_steps=32, batch_size=256, n_epochs=2)
    if quick and cfg["algo"] == "sac":
        algo_kwargs.update(learning_starts=256, buffer_size=10_000)
    hyper = {**algo_kwargs, "policy_kwargs": dict(cfg["policy_kwargs"])}
    t0 = time.perf_counter()
    model = train_agent(out, cfg["env_id"], cfg["algo"], cfg["seed"], total, cfg["num_envs"], hyper,
                        eval_points=2 if quick else cfg["curve_points"],
                        eval_episodes=8 if quick else cfg["curve_episodes"],
                        checkpoint_freq=total // 2 if quick else cfg["checkpoint_freq"],
                        save_replay_buffer=cfg["algo"] == "sac", keep_replay_buffers=keep_replay_buffers,
                        resume=resume, progress=progress_mode() if progress is None else progress,
                        progress_seconds=progress_seconds, confirm_episodes=n_eval)
    this_process = time.perf_counter() - t0
    timing = json.loads((out / "train_time.json").read_text())
    seconds = timing["train_seconds"]  # the whole run, resumed parts included (None: the earlier part's time unknown)
    from gymnasium.spaces import Box
    act_space = Box(-1.0, 1.0, model.action_space.shape, np.float32)
    rng = np.random.default_rng(cfg["seed"] + 1)
    eval_seed = 10_000 + cfg["seed"]
    results = {
        "config": cfg, "quick": quick, "timesteps": total, "train_seconds": seconds,
        "this_process_seconds": this_process, "resumed_at": timing["resumed_at"],
        "trained": evaluate(cfg["env_id"], lambda o: model.predict(o, deterministic=True)[0], n_eval, eval_seed),
        "random": evaluate(cfg["env_id"], lambda o: rng.uniform(-1, 1, (len(o),) + act_space.shape).astype(np.float32),
                           n_eval, eval_seed),
        "zero": evaluate(cfg["env_id"], lambda o: np.zeros((len(o),) + act_space.shape, np.float32), n_eval, eval_seed),
    }
    best = json.loads((out / "best.json").read_text()) if (out / "best.json").is_file() else {}
    results["best"] = best
    (out / "results.json").write_text(json.dumps(results, indent=2))
    rows = [f"| {name} | {r['mean_return']:.3f} | {r['success_rate']:.3f} | {r['mean_length']:.1f} |"
            for name, r in ((k, results[k]) for k in ("trained", "random", "zero"))]
    if timing["resumed_at"] is None:
        took = f"in {seconds:.0f} s"
    elif seconds is None:
        took = (f"resumed at {timing['resumed_at']} steps from a checkpoint without a time record: "
                f"{this_process:.0f} s in this process, the earlier part's time unknown")
    else:
        took = (f"in {seconds:.0f} s of training in all (resumed at {timing['resumed_at']} steps: "
                f"{timing['seconds_before']:.0f} s before, {this_process:.0f} s in this process)")
    md = [f"# {cfg['algo'].upper()} on {cfg['env_id']}", "",
          f"{total} timesteps on {cfg['num_envs']} vectorized envs {took} (seed {cfg['seed']}); "
          f"evaluation on {n_eval} episodes with seeds from {eval_seed}.", "",
          "| policy | mean return | success rate | mean length |", "|---|---|---|---|", *rows, ""]
    if describe(best):
        md += [describe(best) + ".", ""]
    (out / "results.md").write_text("\n".join(md))
    print("\n".join(md))
    print(f"output folder: {out} (python -m training.evaluate {out}; tensorboard --logdir {out})", flush=True)
    return results


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", required=True, help="training config (YAML), e.g. configs/train/ppo_reach_ellipse.yaml")
    ap.add_argument("--out", default=None, help="output folder (default: runs/<config name> under the working "
                                                "directory; --quick: a new temporary directory)")
    ap.add_argument("--quick", action="store_true", help="a few thousand steps: checks the pipeline, learns nothing")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="override a config field (value read as YAML); a dotted key sets one hyperparameter: "
                         "--set algo_kwargs.learning_rate=1e-3")
    ap.add_argument("--resume", default=None, metavar="PATH",
                    help="go on from a checkpoint: a model_<steps>_steps.zip or a run folder (its newest intact "
                         "checkpoint), with the same settings (only total_timesteps may change)")
    ap.add_argument("--progress-seconds", type=float, default=30.0,
                    help="off a terminal: seconds between progress lines (default 30)")
    ap.add_argument("--keep-replay-buffers", action="store_true",
                    help="SAC: keep the replay buffer of every checkpoint (default: only the newest)")
    args = ap.parse_args(argv)
    try:
        cfg = load_config(args.config, args.set)
        if args.resume is not None:
            from training.runner import latest_checkpoint
            latest_checkpoint(args.resume)
        if not args.progress_seconds > 0:
            raise ValueError(f"--progress-seconds must be positive, got {args.progress_seconds}")
    except ValueError as exc:
        ap.error(str(exc))
    if args.out:
        out = Path(args.out).resolve()
    elif args.quick:  # a quick run checks the pipeline: it never writes over a real run
        out = Path(tempfile.mkdtemp(prefix="penny_env-quick-")) / Path(args.config).stem
    else:
        out = (Path("runs") / Path(args.config).stem).resolve()
    from training.run_folder import RunFolderError
    from training.runner import TrainingInterrupted, latest_checkpoint
    try:
        return train(cfg, out, quick=args.quick, resume=args.resume, progress_seconds=args.progress_seconds,
                     keep_replay_buffers=args.keep_replay_buffers)
    except RunFolderError as exc:  # another run's folder, a resume that changes the run: usage errors
        ap.error(str(exc))
    except KeyboardInterrupt as exc:  # Ctrl-C: one line, no traceback
        if isinstance(exc, TrainingInterrupted):
            where = f"interrupted at {exc.timesteps:,} steps, checkpoint saved: {exc.checkpoint}"
        elif (out / "model.zip").is_file() and not (out / "results.md").is_file():
            where = f"interrupted after training, during the final evaluation: the model is {out / 'model.zip'}"
        else:
            where = "interrupted"
        try:
            latest_checkpoint(out)
        except ValueError:
            print(f"[train] {where}; no checkpoint yet: nothing to resume", file=sys.stderr, flush=True)
        else:
            print(f"[train] {where}; resume with: {resume_command(args, out)}", file=sys.stderr, flush=True)
        sys.exit(130)


def resume_command(args, out: Path) -> str:
    """The command line that goes on with this run from its newest checkpoint."""
    argv = ["python", "-m", "training.train", "--config", args.config]
    for item in args.set:
        argv += ["--set", item]
    if args.quick:
        argv.append("--quick")
    if args.progress_seconds != 30.0:
        argv += ["--progress-seconds", f"{args.progress_seconds:g}"]
    if args.keep_replay_buffers:
        argv.append("--keep-replay-buffers")
    return shlex.join(argv + ["--out", str(out), "--resume", str(out)])


if __name__ == "__main__":
    main()
