"""The researcher's workflow around training (issue 21): training.train writes a run folder that
training.evaluate reads (one layout for train, the study and evaluate), logs off a terminal,
checkpoints, keeps the best model and resumes."""
import csv
import importlib.util
import io
import json
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(importlib.util.find_spec("stable_baselines3") is None,
                                reason="Stable-Baselines3 (the penny-env[train] extra) is not installed")

REPO = Path(__file__).parent.parent
PPO_CONFIG = str(REPO / "configs" / "train" / "ppo_reach_ellipse.yaml")
SAC_CONFIG = str(REPO / "configs" / "train" / "sac_park_circle.yaml")


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
    train.main(["--config", SAC_CONFIG, "--quick", "--out", "first"])
    first = reports_untouched / "first"
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
    assert (best["success_rate"], best["mean_return"]) == top[:2]
    assert best["timesteps"] == min(r[2] for r in rows if r[:2] == top[:2])
