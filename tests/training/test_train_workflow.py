"""The researcher's workflow around training (issue 21): training.train writes a run folder that
training.evaluate reads (one layout for train, the study and evaluate), logs off a terminal,
checkpoints, keeps the best model and resumes."""
import csv
import importlib.util
import io
import json
import os
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(importlib.util.find_spec("stable_baselines3") is None,
                                reason="Stable-Baselines3 (the penny-env[train] extra) is not installed")

REPO = Path(__file__).parents[2]
PPO_CONFIG = str(REPO / "configs" / "train" / "ppo_reach_ellipse.yaml")
SAC_CONFIG = str(REPO / "configs" / "train" / "sac_park_circle.yaml")
# a hang detector, not a measure: 10 times a training start on a busy small machine (the first compile of the
# vector env took about 170 s there, issue 40)
HANG_SECONDS = 1800


def test_train_quick_then_evaluate_its_output(reports_untouched, capsys, monkeypatch):
    from training import evaluate, train
    train.main(["--config", PPO_CONFIG, "--quick", "--out", "run"])
    out = capsys.readouterr().out
    run = reports_untouched / "run"
    assert out.count(f"output folder: {run}") == 2, "the output folder is printed at start and end"
    for f in ("config.json", "model.zip", "best_model.zip", "best.json", "curve.csv", "progress.csv",
              "results.json", "results.md"):
        assert (run / f).is_file(), f
    assert list((run / "checkpoints").glob("model_*_steps.zip"))
    if importlib.util.find_spec("tensorboard") is not None:
        assert list(run.glob("events.out.tfevents.*"))
    res = evaluate.main([str(run), "--episodes", "4", "--no-video"])
    assert res["env_id"] == "PennyReach-Ellipse-v0" and res["algo"] == "ppo" and res["episodes"] == 4
    assert "success" in capsys.readouterr().out
    best = evaluate.main([str(run), "--episodes", "4", "--no-video", "--best"])
    assert best["model"].endswith("best_model.zip")
    assert (run / "evaluation_best.json").is_file()
    # the final model beside it, on the same episodes, and how best_model.zip was chosen (issue 40, item 15)
    assert best["final"]["episodes"] == 4 and best["final"]["model"].endswith("model.zip")
    printed = capsys.readouterr().out
    assert "the final model (model.zip) on the same episodes: success" in printed
    assert "best_model.zip is the " in printed and "on the same 8 episodes" in printed
    assert "best_model.zip is the " in (run / "results.md").read_text()
    # without MoviePy (the main job's install): the default evaluation still prints its numbers, then one
    # line on how to get the videos (it crashed after the episodes)
    capsys.readouterr()
    monkeypatch.setitem(__import__("sys").modules, "moviepy", None)  # find_spec("moviepy") -> None
    res = evaluate.main([str(run), "--episodes", "4"])
    lines = capsys.readouterr().out.strip().splitlines()
    assert "success" in lines[0] and "Wilson" in lines[0] and "videos" not in res
    assert lines[1:] == [evaluate.VIDEO_HINT] and 'pip install -e ".[video]"' in lines[1]
    assert not (run / "videos").exists() and (run / "evaluation.json").is_file()


def test_progress_lines_off_a_terminal(reports_untouched, capsys):
    from training import train
    assert train.progress_mode(io.StringIO()) == "lines"  # a pipe or a file: no bar
    train.main(["--config", PPO_CONFIG, "--quick", "--out", "run", "--progress-seconds", "0.001"])
    lines = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("[train]")]
    assert len(lines) >= 2
    assert "/2,048 steps" in lines[-1] and "steps/s" in lines[-1] and "ETA" in lines[-1]
    assert "2,048/2,048 steps (100 %)" in lines[-1] and "eval success" in lines[-1]


def test_resume_sac_from_a_checkpoint(reports_untouched, capsys):
    """SAC checkpoints carry the replay buffer; --resume loads model, buffer and step counter and
    trains on to the run's total, keeping the learning curve logged so far."""
    from training import train
    from training.runner import latest_checkpoint
    train.main(["--config", SAC_CONFIG, "--quick", "--out", "first", "--keep-replay-buffers"])
    first = reports_untouched / "first"
    assert len(list((first / "checkpoints").glob("model_replay_buffer_*_steps.pkl"))) == 2  # asked to keep all
    assert int(latest_checkpoint(first).stem.split("_")[-2]) == 2048  # a run folder: its newest checkpoint
    ckpt = min((first / "checkpoints").glob("model_*_steps.zip"), key=lambda p: int(p.stem.split("_")[-2]))
    steps = int(ckpt.stem.split("_")[-2])
    assert 0 < steps < 2048
    assert ckpt.with_name(f"model_replay_buffer_{steps}_steps.pkl").is_file()
    # resume into a new folder from the first checkpoint (as after a crash at that point)
    capsys.readouterr()
    res = train.main(["--config", SAC_CONFIG, "--quick", "--out", "second", "--resume", str(ckpt)])
    from stable_baselines3 import SAC
    model = SAC.load(reports_untouched / "second" / "model.zip")
    assert model.num_timesteps == 2048 and res["timesteps"] == 2048
    with open(reports_untouched / "second" / "curve.csv") as f:
        rows = [int(float(r["timesteps"])) for r in csv.DictReader(f)]
    assert rows and min(rows) > steps  # evaluations after the checkpoint only: it went on from there
    with pytest.raises(SystemExit):
        train.main(["--config", SAC_CONFIG, "--quick", "--resume", str(reports_untouched / "nothing")])
    assert "resume" in capsys.readouterr().err


def test_best_model_follows_evaluation_success(tmp_path):
    from training.runner import train_agent
    run = tmp_path / "run"
    train_agent(run, "PennyProbeDrive-Plane-v0", "ppo", 0, 128, 2, {"n_steps": 32, "batch_size": 64, "n_epochs": 1},
                eval_points=2, eval_episodes=2, checkpoints=1)
    with open(run / "curve.csv") as f:
        rows = [(float(r["success_rate"]), float(r["mean_return"]), int(float(r["timesteps"]))) for r in csv.DictReader(f)]
    best = json.loads((run / "best.json").read_text())
    top = max(rows, key=lambda r: r[:2])
    candidate = best["confirmed"]["checkpoint"]["during_training"]  # the best evaluation during training...
    assert (candidate["success_rate"], candidate["mean_return"]) == top[:2]
    assert candidate["timesteps"] == min(r[2] for r in rows if r[:2] == top[:2])
    # ...confirmed against the final model on 100 fresh episodes (issue 40, item 15): best_model.zip is the better
    confirmed = best["confirmed"]
    assert confirmed["episodes"] == 100 and confirmed["final"]["timesteps"] == 128
    ck, fi = confirmed["checkpoint"], confirmed["final"]
    assert best["chosen"] == ("checkpoint" if (ck["success_rate"], ck["mean_return"]) > (fi["success_rate"],
                                                                                          fi["mean_return"]) else "final")


def test_sac_keeps_only_the_newest_replay_buffer(reports_untouched):
    """A replay buffer holds up to buffer_size transitions (a SAC run folder grew to 201 MB of them): by
    default each checkpoint's buffer replaces the one before."""
    from training import train
    from training.runner import latest_checkpoint
    train.main(["--config", SAC_CONFIG, "--quick", "--out", "run"])
    ckpts = sorted((reports_untouched / "run" / "checkpoints").glob("model_*_steps.zip"))
    buffers = list((reports_untouched / "run" / "checkpoints").glob("model_replay_buffer_*_steps.pkl"))
    newest = latest_checkpoint(reports_untouched / "run")
    assert len(ckpts) == 2 and [b.name for b in buffers] == [newest.name.replace("model_", "model_replay_buffer_")
                                                                .replace(".zip", ".pkl")]


def _steps_column(path):
    with open(path, newline="") as f:
        return [int(float(r["time/total_timesteps"])) for r in csv.DictReader(f) if r.get("time/total_timesteps")]


def test_an_interrupted_sac_run_saves_model_and_buffer_and_resumes_with_its_time(tmp_path):
    """Ctrl-C (a KeyboardInterrupt inside SB3's loop) saves a checkpoint of the step reached, with the newest
    replay buffer and the training time so far; the resumed run appends to progress.csv and counts that time."""
    from stable_baselines3.common.callbacks import BaseCallback
    from training.runner import TrainingInterrupted, latest_checkpoint, train_agent

    class CtrlC(BaseCallback):
        def _on_step(self):
            if self.num_timesteps >= 1200:
                raise KeyboardInterrupt
            return True

    run = tmp_path / "run"
    hyper = {"learning_starts": 64, "buffer_size": 5_000, "batch_size": 64, "policy_kwargs": {"net_arch": [16]}}
    # 200-step episodes on 4 envs: SAC logs a progress.csv row every 4 episodes, at 800, 1600 and 2400 steps
    args = (run, "PennyReach-Plane-v0", "sac", 0, 2400, 4, hyper, 1, 2)
    with pytest.raises(TrainingInterrupted) as info:
        train_agent(*args, checkpoint_freq=512, save_replay_buffer=True, extra_callbacks=[CtrlC()])
    steps = info.value.timesteps
    assert info.value.checkpoint == latest_checkpoint(run) and steps == 1200
    assert [p.name for p in (run / "checkpoints").glob("*.pkl")] == [f"model_replay_buffer_{steps}_steps.pkl"]
    before = json.loads(info.value.checkpoint.with_suffix(".json").read_text())
    assert before["timesteps"] == steps and before["train_seconds"] > 0
    rows_before = _steps_column(run / "progress.csv")
    assert rows_before == [800]
    model = train_agent(*args, checkpoint_freq=512, save_replay_buffer=True, resume=run)
    # the buffer saved at the interruption was loaded: more rows than the resumed part alone adds (4 envs a row)
    assert model.num_timesteps == 2400 and model.replay_buffer.size() > (2400 - steps) // 4
    rows = _steps_column(run / "progress.csv")
    assert rows[:len(rows_before)] == [r for r in rows_before if r <= steps] and rows[-1] > steps
    timing = json.loads((run / "train_time.json").read_text())
    assert timing["resumed_at"] == steps and timing["seconds_before"] == pytest.approx(before["train_seconds"])
    assert timing["train_seconds"] == pytest.approx(before["train_seconds"] + timing["this_process_seconds"])


@pytest.mark.slow
def test_ctrl_c_prints_the_resume_command_which_appends_and_reports_the_whole_time(tmp_path, python_sigint_handler):
    """SIGINT to `python -m training.train`: no traceback, one line with the exact resume command, exit 130;
    that command goes on from the checkpoint, appends to progress.csv and reports the whole run's time."""
    from training.runner import latest_checkpoint
    run = tmp_path / "run"
    cmd = [sys.executable, "-m", "training.train", "--config", PPO_CONFIG, "--out", str(run),
           "--set", "total_timesteps=400000", "--set", "num_envs=8",
           "--set", "algo_kwargs={n_steps: 32, batch_size: 256, n_epochs: 1}", "--set", "eval_episodes=4",
           "--set", "curve_points=1", "--set", "curve_episodes=2", "--set", "checkpoint_freq=200000",
           "--progress-seconds", "1"]
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.Popen(cmd, cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + HANG_SECONDS
    while not ((run / "progress.csv").is_file() and len(_steps_column(run / "progress.csv")) >= 3):
        assert proc.poll() is None, proc.communicate()[1][-3000:]
        if time.monotonic() > deadline:  # (a hang detector, not a measure)
            proc.kill()
            pytest.fail(f"no progress rows after {HANG_SECONDS} s: {proc.communicate()[1][-3000:]}")
        time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=HANG_SECONDS)
    assert proc.returncode == 130 and "Traceback" not in err, err[-3000:]
    lines = [ln for ln in err.splitlines() if ln.startswith("[train] interrupted")]
    assert len(lines) == 1 and "checkpoint saved" in lines[0], err[-3000:]
    steps = int(latest_checkpoint(run).stem.split("_")[-2])
    assert 0 < steps < 400_000
    rows_before = _steps_column(run / "progress.csv")
    resume = shlex.split(lines[0].split("resume with: ", 1)[1])
    assert resume[:3] == ["python", "-m", "training.train"] and resume[-4:] == ["--out", str(run), "--resume", str(run)]
    # the printed command, with the total cut to two more rollouts (a later --set wins)
    done = subprocess.run([sys.executable, *resume[1:], "--set", f"total_timesteps={steps + 512}"], cwd=tmp_path,
                          env=env, capture_output=True, text=True, timeout=HANG_SECONDS)
    assert done.returncode == 0, done.stderr[-3000:]
    rows = _steps_column(run / "progress.csv")
    assert rows[:len(rows_before)] == [r for r in rows_before if r <= steps] and rows[-1] == steps + 512
    results = (run / "results.md").read_text()
    assert f"resumed at {steps} steps" in results and "of training in all" in results
    timing = json.loads((run / "train_time.json").read_text())
    assert timing["train_seconds"] > timing["this_process_seconds"] > 0 and timing["seconds_before"] > 0
