"""A run folder is written by one run at a time and resumed from an intact checkpoint of the same run; the best model
is chosen on enough episodes (issue 40, items 7, 8 and 15; training/run_folder.py, training/best_choice.py)."""
import importlib.util
import json
import zipfile
from pathlib import Path

import pytest

from training import best_choice, train
from training.run_folder import RunFolderError, check_resume, intact_checkpoint, run_lock
from training.runner import latest_checkpoint

REPO = Path(__file__).parents[2]
PPO_CONFIG = str(REPO / "configs" / "train" / "ppo_reach_ellipse.yaml")
needs_filelock = pytest.mark.skipif(importlib.util.find_spec("filelock") is None,
                                    reason="filelock (the penny-env[train] extra) is not installed")
needs_sb3 = pytest.mark.skipif(importlib.util.find_spec("stable_baselines3") is None,
                               reason="Stable-Baselines3 (the penny-env[train] extra) is not installed")


def _checkpoint(folder: Path, steps: int, n_envs: int = 8) -> Path:
    """A checkpoint zip as SB3 writes one (its "data" member holds n_envs), big enough to be cut."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"model_{steps}_steps.zip"
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("data", json.dumps({"n_envs": n_envs, "num_timesteps": steps}))
        z.writestr("policy.pth", bytes(range(256)) * 64)
    return path


@needs_filelock
def test_a_second_run_into_a_locked_folder_is_refused(tmp_path, capsys):
    # repro_two_runs_same_out.sh: both runs exited 0, progress.csv interleaved, results.json named one seed
    from filelock import FileLock
    out = tmp_path / "run"
    out.mkdir()
    other = FileLock(str(out / ".lock"))  # another process's lock (flock: another open file, refused alike)
    other.acquire()
    try:
        with pytest.raises(RunFolderError, match=r"another training run is writing into .*run"):
            with run_lock(out):
                pass
        with pytest.raises(SystemExit) as exit_:
            train.main(["--config", PPO_CONFIG, "--quick", "--out", str(out)])
        assert exit_.value.code == 2 and "another training run is writing into" in capsys.readouterr().err
    finally:
        other.release()
    with run_lock(out), run_lock(out):  # free again, and re-entrant within one run
        pass


@needs_filelock
def test_a_non_empty_out_needs_resume(tmp_path, capsys):
    out = tmp_path / "run"
    out.mkdir()
    (out / "progress.csv").write_text("time/total_timesteps\n512\n")
    with pytest.raises(SystemExit) as exit_:
        train.main(["--config", PPO_CONFIG, "--quick", "--out", str(out)])
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and f"--out {out} is not empty (progress.csv)" in err and f"--resume {out}" in err
    assert (out / "progress.csv").read_text() == "time/total_timesteps\n512\n"  # untouched


def test_a_truncated_newest_checkpoint_falls_back_to_the_one_before(tmp_path, capsys):
    folder = tmp_path / "run" / "checkpoints"
    good = _checkpoint(folder, 1024)
    cut = _checkpoint(folder, 2048)
    cut.write_bytes(cut.read_bytes()[:-300])  # a run killed while saving it
    assert latest_checkpoint(tmp_path / "run") == good
    out = capsys.readouterr().out
    assert "checkpoint model_2048_steps.zip is damaged" in out and "falling back to the one before" in out
    with pytest.raises(RunFolderError, match="cannot be loaded"):
        intact_checkpoint(cut)
    good.write_bytes(b"not a zip")
    with pytest.raises(RunFolderError, match="every checkpoint under .* is damaged"):
        latest_checkpoint(tmp_path / "run")


def test_a_resume_that_changes_the_run_is_refused_naming_what_changes(tmp_path):
    run = tmp_path / "run"
    ckpt = _checkpoint(run / "checkpoints", 1024, n_envs=8)
    config = {"env_id": "PennyReach-Ellipse-v0", "algo": "ppo", "seed": 0, "timesteps": 4096, "num_envs": 8,
              "hyperparameters": {"n_steps": 32, "policy_kwargs": {"net_arch": [64, 64]}}}
    (run / "config.json").write_text(json.dumps(config))
    check_resume(ckpt, {**config, "timesteps": 8192})  # only the total may change
    with pytest.raises(RunFolderError, match=r"num_envs: the checkpoint was trained with 8 envs, this run asks for "
                                             r"4 .*Resume with the same settings"):
        check_resume(ckpt, {**config, "num_envs": 4})
    with pytest.raises(RunFolderError, match=r"seed: 0 in .*config.json, 3 now.*hyperparameters"):
        check_resume(ckpt, {**config, "seed": 3, "hyperparameters": {"n_steps": 64}})


@needs_sb3
def test_resume_with_another_num_envs_is_refused_before_training(tmp_path):
    from training.runner import train_agent
    run = tmp_path / "run"
    hyper = {"n_steps": 32, "batch_size": 64, "n_epochs": 1}
    train_agent(run, "PennyProbeDrive-Plane-v0", "ppo", 0, 128, 2, hyper, eval_points=1, eval_episodes=2,
                checkpoints=1, confirm_episodes=None)
    progress = (run / "progress.csv").read_text()
    with pytest.raises(RunFolderError, match="num_envs: the checkpoint was trained with 2 envs, this run asks for 4"):
        train_agent(run, "PennyProbeDrive-Plane-v0", "ppo", 0, 256, 4, hyper, eval_points=1, eval_episodes=2,
                    checkpoints=1, resume=run)
    assert (run / "progress.csv").read_text() == progress and json.loads((run / "config.json").read_text())["num_envs"] == 2


class _Model:
    def __init__(self, name):
        self.name, self.saved = name, []

    def predict(self, obs, deterministic=True):
        return self.name, None

    def save(self, path):
        self.saved.append(Path(path))
        Path(path).write_text(self.name)


def test_the_best_model_is_chosen_on_the_same_fresh_episodes(tmp_path, monkeypatch):
    # the run: the best checkpoint scored 1.0 on 32 episodes during training, then 0.65, the final model 0.95
    from training import episodes
    rates = {"candidate": 0.65, "final": 0.95}

    def run_episodes(env_id, policy, n, seed):
        rate = rates[policy(None)]
        k = round(rate * n)
        return {"success": [True] * k + [False] * (n - k), "return": [rate] * n}
    monkeypatch.setattr(episodes, "run_episodes", run_episodes)
    best, record = tmp_path / "best_model.zip", tmp_path / "best.json"
    best.write_text("candidate")
    record.write_text(json.dumps({"timesteps": 20_000, "success_rate": 1.0, "mean_return": 3.0}))
    final = _Model("final")
    out = best_choice.confirm_best("PennyReach-Ellipse-v0", final, best, record, lambda p: _Model(Path(p).read_text()),
                                   (100_000, 0.9, 2.0), 200, 7, 32)
    assert out["chosen"] == "final" and best.read_text() == "final" and final.saved == [best]
    c = out["confirmed"]
    assert (c["checkpoint"]["success_rate"], c["final"]["success_rate"], c["episodes"]) == (0.65, 0.95, 200)
    assert c["checkpoint"]["during_training"] == {"timesteps": 20_000, "success_rate": 1.0, "mean_return": 3.0,
                                                  "episodes": 32}
    assert c["final"]["ci95_wilson"][0] > c["checkpoint"]["ci95_wilson"][1] and not c["intervals_overlap"]
    assert json.loads(record.read_text()) == out and (out["timesteps"], out["success_rate"]) == (100_000, 0.9)
    text = best_choice.describe(out)
    assert "best_model.zip is the final model" in text and "0.650 [" in text and "0.950 [" in text
    # a checkpoint that stays better on the same episodes is kept
    rates.update(candidate=0.9, final=0.6)
    best.write_text("candidate")
    record.write_text(json.dumps({"timesteps": 20_000, "success_rate": 1.0, "mean_return": 3.0}))
    out = best_choice.confirm_best("PennyReach-Ellipse-v0", _Model("final"), best, record,
                                   lambda p: _Model(Path(p).read_text()), (100_000, 0.9, 2.0), 200, 7, 32)
    assert out["chosen"] == "checkpoint" and best.read_text() == "candidate" and out["timesteps"] == 20_000


@needs_filelock
def test_ppo_torch_refuses_another_runs_folder_too(tmp_path, capsys):
    # the same defect in the other training command: a non-empty --out, or a folder another run holds
    pytest.importorskip("torch", reason="torch (the penny-env[train] extra) is not installed")
    from filelock import FileLock

    from training import ppo_torch
    out = tmp_path / "run"
    out.mkdir()
    (out / "progress.csv").write_text("global_step\n128\n")
    with pytest.raises(SystemExit) as exit_:
        ppo_torch.main(["--quick", "--out", str(out), "--device", "cpu"])
    assert exit_.value.code == 2 and "is not empty (progress.csv)" in capsys.readouterr().err
    held = tmp_path / "held"
    held.mkdir()
    other = FileLock(str(held / ".lock"))
    other.acquire()
    try:
        with pytest.raises(RunFolderError, match="another training run is writing into"):
            ppo_torch.train(ppo_torch.Args(out=str(held), quick=True, device="cpu"))
    finally:
        other.release()
