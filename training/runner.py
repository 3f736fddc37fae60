"""Train one SB3 agent on one env id into a run folder, with the tooling users expect:

    RUN_DIR/config.json      what was trained (env_id, algo, seed, timesteps, num_envs, hyperparameters)
    RUN_DIR/progress.csv     SB3's CSV log (train/* and eval/* rows)
    RUN_DIR/events.out.tfevents.*  TensorBoard events (``tensorboard --logdir RUN_DIR``)
    RUN_DIR/curve.csv        evaluation during training: timesteps, success_rate, mean_return
    RUN_DIR/checkpoints/     model_<steps>_steps.zip every checkpoint_freq steps and when training is
                             interrupted (Ctrl-C), model_<steps>_steps.json the training time up to it
                             (SAC, when asked: model_replay_buffer_<steps>_steps.pkl, for --resume; only
                             the newest unless all are kept)
    RUN_DIR/train_time.json  the whole run's training time, over its resumed parts
    RUN_DIR/best_model.zip   the model of the best evaluation so far (success rate, then mean return),
                             RUN_DIR/best.json its timesteps and scores
    RUN_DIR/model.zip        the final model (``python -m training.evaluate RUN_DIR``)

training.train and training.evaluate use this layout. Ctrl-C during training saves a
checkpoint of the step it reached and raises TrainingInterrupted (a KeyboardInterrupt) naming it; a resumed
run appends to progress.csv (its rows up to the checkpoint kept) and adds the time of the part before the
checkpoint to its own.

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


class TrainingInterrupted(KeyboardInterrupt):
    """Ctrl-C during train_agent: the checkpoint saved at the step training reached."""

    def __init__(self, checkpoint: Path, timesteps: int):
        super().__init__(f"training interrupted at {timesteps} steps; checkpoint {checkpoint}")
        self.checkpoint, self.timesteps = Path(checkpoint), timesteps


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


def success_eval_callback(env_id: str, every: int, episodes: int, seed: int, out_csv: Path,
                          best_model: Path | None = None, confirm_episodes: int | None = None,
                          confirm_seed: int | None = None, load=None):
    """An SB3 callback: every `every` env steps, run `episodes` deterministic episodes (fixed
    seeds) and log eval/success_rate (from info["is_success"]) and eval/mean_return to SB3's
    logger (CSV, TensorBoard) and to out_csv. With best_model, the model of the best evaluation
    (success rate, ties broken by mean return) is saved there and its scores next to it (best.json).
    A resumed run (a model with timesteps already) keeps the rows of out_csv and the best so far.

    With confirm_episodes, the choice is confirmed when training ends (training.best_choice): the best candidate
    and the final model each play the same confirm_episodes fresh episodes (seeds from confirm_seed), and
    best_model.zip keeps the one that does better there (the final model on a tie). Picked from evaluations of
    `episodes` episodes alone, it was noise: a checkpoint that scored 1.0 on 32 episodes scored 0.65 on more, the
    final model 0.95. best.json then records both, with their 95 % Wilson intervals. load(path): the model class's
    load (to play the saved candidate)."""
    from stable_baselines3.common.callbacks import BaseCallback
    from training.best_choice import confirm_best
    from training.episodes import run_episodes

    best_json = None if best_model is None else Path(best_model).with_name("best.json")

    class SuccessEval(BaseCallback):
        def __init__(self):
            super().__init__()
            self.next = 0
            self.rows = []
            self.best = None  # (success_rate, mean_return)

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
            if best_model is not None and (self.best is None or row[1:] > self.best):
                self.best = row[1:]
                self.model.save(best_model)
                best_json.write_text(json.dumps({"timesteps": row[0], "success_rate": row[1], "mean_return": row[2]}))

        def _on_training_start(self):
            if self.num_timesteps > 0:  # resumed: keep what the run logged up to its checkpoint
                self._resume()
                return
            self._evaluate()
            self.next = every

        def _resume(self):
            if Path(out_csv).is_file():
                with open(out_csv) as f:
                    self.rows = [(int(float(r["timesteps"])), float(r["success_rate"]), float(r["mean_return"]))
                                 for r in csv.DictReader(f) if float(r["timesteps"]) <= self.num_timesteps]
            if best_json is not None and best_json.is_file():
                b = json.loads(best_json.read_text())
                if b["timesteps"] <= self.num_timesteps:
                    self.best = (b["success_rate"], b["mean_return"])
            self.next = (self.num_timesteps // every + 1) * every

        def _on_step(self):
            if self.num_timesteps >= self.next:
                self._evaluate()
                self.next += every
            return True

        def _on_training_end(self):
            # the final model, unless the last evaluation was just before (PPO ends on a rollout multiple)
            if not self.rows or self.num_timesteps - self.rows[-1][0] >= every / 2:
                self._evaluate()
            if best_model is not None and confirm_episodes and best_json.is_file() and load is not None:
                final_row = (self.num_timesteps, *self.rows[-1][1:])
                confirm_best(env_id, self.model, best_model, best_json, load, final_row,
                             confirm_episodes, confirm_seed if confirm_seed is not None else seed + 100_000,
                             episodes)

    return SuccessEval()


def progress_lines_callback(total: int, every_seconds: float, curve=None, print_fn=print):
    """An SB3 callback that prints one line every `every_seconds` of wall time (and at the end):
    steps done of `total`, env steps per second, the last evaluation's success rate (from the
    SuccessEval callback `curve`, if given) and the estimated time left. For runs off a terminal
    (nohup, a scheduler, CI), where a progress bar draws nothing."""
    import sys
    import time
    from stable_baselines3.common.callbacks import BaseCallback

    class ProgressLines(BaseCallback):
        def _on_training_start(self):
            self.t0 = self.last = time.perf_counter()
            self.start_steps = self.num_timesteps

        def _line(self):
            elapsed = time.perf_counter() - self.t0
            done = self.num_timesteps - self.start_steps
            fps = done / elapsed if elapsed > 0 else 0.0
            left = max(0, total - self.num_timesteps)
            eta = f"{left / fps:.0f} s" if fps > 0 else "?"
            succ = ""
            if curve is not None and curve.rows:
                succ = f", eval success {curve.rows[-1][1]:.2f} at {curve.rows[-1][0]:,} steps"
            print_fn(f"[train] {self.num_timesteps:,}/{total:,} steps ({100 * self.num_timesteps / total:.0f} %), "
                     f"{fps:,.0f} steps/s{succ}, elapsed {elapsed:.0f} s, ETA {eta}")
            sys.stdout.flush()

        def _on_step(self):
            now = time.perf_counter()
            if now - self.last >= every_seconds:
                self.last = now
                self._line()
            return True

        def _on_training_end(self):
            self._line()

    return ProgressLines()


def stop_on_ctrl_c_callback():
    """An SB3 callback that turns Ctrl-C into a stop at the next env step. While learn runs (main thread, Python's own
    SIGINT handler in place), a SIGINT sets a flag instead of raising KeyboardInterrupt wherever Python happens to be:
    raised inside a finalizer (llvmlite's, numba's) Python ignores it ("Exception ignored in ...") and training went
    on; raised inside an update it could leave the model half written. ``_on_step`` then returns False and SB3's learn
    returns; the runner saves the checkpoint. A second Ctrl-C raises KeyboardInterrupt at once. penny_env's compiles
    hold a SIGINT and hand it to this handler when they are done (backends/interrupts.compiling). A handler of the
    user's own is left in place. ``restore()`` puts the previous handler back (also called at the training's end)."""
    import signal
    import threading

    from stable_baselines3.common.callbacks import BaseCallback

    class StopOnCtrlC(BaseCallback):
        requested = False
        _previous = None

        def _on_training_start(self):
            if threading.current_thread() is threading.main_thread() and \
                    signal.getsignal(signal.SIGINT) is signal.default_int_handler:
                self._previous = signal.signal(signal.SIGINT, self._on_sigint)

        def _on_sigint(self, signum, frame):
            if self.requested:
                raise KeyboardInterrupt
            self.requested = True

        def _on_step(self):
            return not self.requested

        def _on_training_end(self):
            self.restore()

        def restore(self):
            if self._previous is not None:
                signal.signal(signal.SIGINT, self._previous)
                self._previous = None

    return StopOnCtrlC()


def _checkpoint_steps(path: Path) -> int:
    from training.run_folder import checkpoint_steps
    return checkpoint_steps(path)


def checkpoint_callback(save_freq: int, folder: Path, save_replay_buffer: bool, keep_replay_buffers: bool,
                        seconds_before: float, t_start: float):
    """SB3's CheckpointCallback that also records the run's training time at each checkpoint
    (model_<steps>_steps.json: the time before this process plus this process's time since t_start),
    keeps only the newest replay buffer unless keep_replay_buffers, and saves one more checkpoint on
    demand (save_now: Ctrl-C)."""
    import time
    from stable_baselines3.common.callbacks import CheckpointCallback

    class TimedCheckpoints(CheckpointCallback):
        def _on_step(self) -> bool:
            if self.n_calls % self.save_freq == 0:
                self.save_now()
            return True

        def save_now(self) -> Path:
            path = Path(self._checkpoint_path(extension="zip"))
            self.model.save(path)
            has_buffer = getattr(self.model, "replay_buffer", None) is not None
            if self.save_replay_buffer and has_buffer:
                buffer = Path(self._checkpoint_path("replay_buffer_", extension="pkl"))
                self.model.save_replay_buffer(buffer)
                if not keep_replay_buffers:  # a buffer holds up to buffer_size transitions: tens of MB each
                    for old in Path(self.save_path).glob("model_replay_buffer_*_steps.pkl"):
                        if old != buffer:
                            old.unlink()
            path.with_suffix(".json").write_text(json.dumps(
                {"timesteps": int(self.num_timesteps), "train_seconds": seconds_before + time.perf_counter() - t_start}))
            return path

    return TimedCheckpoints(save_freq, str(folder), name_prefix="model", save_replay_buffer=save_replay_buffer)


def seconds_before(checkpoint: Path) -> float | None:
    """The run's training time up to `checkpoint` (its .json), or None (a checkpoint without the record)."""
    record = Path(checkpoint).with_suffix(".json")
    if not record.is_file():
        return None
    try:
        return float(json.loads(record.read_text())["train_seconds"])
    except (ValueError, KeyError, TypeError):
        return None


def progress_csv(path: Path, keep_until: int | None):
    """SB3's CSV output (progress.csv). A resumed run (keep_until: the checkpoint's steps) keeps the earlier
    rows up to that step and their columns, and appends; SB3's own CSV output truncates the file."""
    from stable_baselines3.common.logger import CSVOutputFormat

    keys, rows = [], []
    if keep_until is not None and path.is_file():
        with open(path, newline="") as f:
            reader = csv.DictReader(f)
            keys = list(reader.fieldnames or [])
            for row in reader:
                steps = row.get("time/total_timesteps") or ""
                try:
                    if steps and float(steps) > keep_until:  # logged after the checkpoint: done again now
                        continue
                except ValueError:
                    pass
                rows.append(row)
    out = CSVOutputFormat(str(path))
    if keys:
        out.keys = keys
        writer = csv.writer(out.file, lineterminator="\n")  # SB3 rewrites the file line by line on new columns
        writer.writerow(keys)
        writer.writerows([[row.get(k) or "" for k in keys] for row in rows])
        out.file.flush()
    return out


def latest_checkpoint(path, say=print) -> Path:
    """The model zip to resume from: PATH itself (a .zip), or the newest intact checkpoint of a run folder
    (PATH/checkpoints/model_<steps>_steps.zip, by steps; a truncated newer one is skipped, and said:
    training.run_folder.intact_checkpoint). ValueError (run_folder.RunFolderError) if there is none."""
    from training.run_folder import intact_checkpoint
    return intact_checkpoint(path, say)


def train_agent(run_dir, *args, **kwargs):
    """:func:`train_one` with RUN_DIR's lock held (training.run_folder.run_lock): a second run into the same folder
    is refused at once (run_folder.RunFolderError) instead of interleaving its files with this one's."""
    from training.run_folder import run_lock
    with run_lock(run_dir):
        return train_one(run_dir, *args, **kwargs)


def train_one(run_dir, env_id: str, algo: str, seed: int, timesteps: int, num_envs: int = 8,
              hyperparameters: dict | None = None, eval_points: int = 10, eval_episodes: int = 32,
              checkpoints: int = 2, *, checkpoint_freq: int | None = None, save_replay_buffer: bool = False,
              keep_replay_buffers: bool = False, resume=None, progress: str | None = None,
              progress_seconds: float = 30.0, extra_callbacks=(), confirm_episodes: int | None = 100):
    """Train, log, checkpoint and save; returns the model.

    checkpoint_freq: env steps between checkpoints (default: timesteps / checkpoints);
    save_replay_buffer: SAC checkpoints also save the replay buffer (what --resume needs to go on
    exactly where it stopped), only the newest one unless keep_replay_buffers; resume: a checkpoint .zip
    or a run folder (its newest checkpoint): the model (and the replay buffer saved with it) is loaded
    and trained on up to `timesteps` in all, progress.csv continued; progress: None (silent), "bar"
    (SB3's progress bar, for a terminal) or "lines" (a line every progress_seconds). Ctrl-C during
    training saves a checkpoint and raises TrainingInterrupted. RUN_DIR/train_time.json gets the run's
    training time: this call's wall time plus, when resumed, the time recorded with the checkpoint.
    A resume that would change num_envs, env_id, algo, seed or the hyperparameters is refused
    (run_folder.check_resume). confirm_episodes: the best model is confirmed on that many fresh episodes when
    training ends (success_eval_callback; None: the best evaluation during training is kept as it is)."""
    import time

    import torch
    from stable_baselines3.common.callbacks import CallbackList
    from stable_baselines3.common.logger import Logger, make_output_format

    hyper = copy.deepcopy(dict(hyperparameters or {}))  # SB3 writes into policy_kwargs (use_sde): not into the caller's job
    check_hyperparameters(algo, hyper)
    if progress not in (None, "bar", "lines"):
        raise ValueError(f"progress must be None, 'bar' or 'lines', got {progress!r}")
    Algo = algo_class(algo)
    t_start = time.perf_counter()
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(1)
    venv = make_train_env(env_id, num_envs, seed)
    cfg = {"env_id": env_id, "algo": algo, "seed": seed, "timesteps": timesteps, "num_envs": num_envs,
           "hyperparameters": hyper}
    ckpt = None
    if resume is not None:  # (checked before this run writes anything)
        from training.run_folder import check_resume
        ckpt = latest_checkpoint(resume)
        check_resume(ckpt, cfg)
    (run_dir / "config.json").write_text(json.dumps(cfg, indent=2))
    before = 0.0
    if resume is None:
        model = Algo("MlpPolicy", venv, seed=seed, verbose=0, device="cpu", **hyper)
    else:
        model = Algo.load(ckpt, env=venv, device="cpu")
        buffer = ckpt.with_name(ckpt.name.replace("model_", "model_replay_buffer_").replace(".zip", ".pkl"))
        if hasattr(model, "load_replay_buffer") and buffer.is_file():
            model.load_replay_buffer(buffer)
        elif hasattr(model, "load_replay_buffer"):
            print(f"[train] {buffer.name}: no replay buffer saved with this checkpoint (only the newest is kept "
                  "unless all are asked for): SAC goes on with an empty buffer", flush=True)
        before = seconds_before(ckpt)
    resumed_at = None if resume is None else int(model.num_timesteps)
    formats = [progress_csv(run_dir / "progress.csv", resumed_at)]
    if _tensorboard_installed():
        formats.append(make_output_format("tensorboard", str(run_dir)))
    model.set_logger(Logger(str(run_dir), formats))
    every = max(1, timesteps // max(1, eval_points))
    ckpt_steps = checkpoint_freq or max(1, timesteps // max(1, checkpoints))
    curve = success_eval_callback(env_id, every, eval_episodes, eval_seed(seed) + 5_000, run_dir / "curve.csv",
                                  run_dir / "best_model.zip", confirm_episodes, eval_seed(seed) + 7_000,
                                  lambda path: Algo.load(path, device="cpu"))
    saver = checkpoint_callback(max(1, ckpt_steps // num_envs), run_dir / "checkpoints", save_replay_buffer,
                                keep_replay_buffers, before or 0.0, t_start)
    callbacks = [curve, saver]
    if progress == "lines":
        callbacks.append(progress_lines_callback(timesteps, progress_seconds, curve))
    callbacks.extend(extra_callbacks)
    ctrl_c = stop_on_ctrl_c_callback()
    callbacks.append(ctrl_c)
    remaining = timesteps - model.num_timesteps
    if remaining > 0:
        try:
            try:
                model.learn(total_timesteps=remaining, callback=CallbackList(callbacks),
                            reset_num_timesteps=resume is None, progress_bar=progress == "bar")
            finally:
                ctrl_c.restore()
            if ctrl_c.requested:
                raise KeyboardInterrupt
        except KeyboardInterrupt:
            saver.init_callback(model)  # (set when learn started; again in case Ctrl-C came before)
            checkpoint = saver.save_now()
            model.logger.close()
            venv.close()
            raise TrainingInterrupted(checkpoint, int(model.num_timesteps)) from None
    model.save(run_dir / "model.zip")
    model.logger.close()
    venv.close()
    this_run = time.perf_counter() - t_start
    (run_dir / "train_time.json").write_text(json.dumps({
        "train_seconds": None if before is None else before + this_run, "this_process_seconds": this_run,
        "resumed_at": resumed_at, "seconds_before": before, "timesteps": int(model.num_timesteps)}, indent=2))
    return model


def _tensorboard_installed() -> bool:
    """SB3's TensorBoard output needs the tensorboard package (the [train] extra)."""
    import importlib.util
    return importlib.util.find_spec("tensorboard") is not None


def load_run(run_dir, model_file: str = "model.zip"):
    """(config, model) of a run folder (model_file: model.zip, best_model.zip or a checkpoint under
    it); ValueError naming a missing or incompatible file."""
    run_dir = Path(run_dir)
    cfg_path, model_path = run_dir / "config.json", run_dir / model_file
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
