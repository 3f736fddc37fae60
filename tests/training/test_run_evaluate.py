"""training.runner and training.evaluate on a run folder: bad input named, a run's files, an incompatible model
refused, the evaluation's interval, its video and its GIF of the first success."""
import json

import pytest

pytest.importorskip("stable_baselines3", reason="training.runner trains SB3 agents (the penny-env[train] extra)")
pytest.importorskip("torch", reason="SB3 needs torch")

from training.evaluate import wilson_interval  # noqa: E402
from training.runner import load_run, train_agent  # noqa: E402

ENV = "PennyProbeDrive-Ellipse-Elastic-v0"


@pytest.fixture(scope="module")
def ppo_run(tmp_path_factory):
    """A tiny PPO run folder (seconds): what training.evaluate reads."""
    run = tmp_path_factory.mktemp("run") / "ppo"
    train_agent(run, ENV, "ppo", 0, 128, 2, {"n_steps": 64, "batch_size": 64, "n_epochs": 1}, 1, 2)
    return run


def test_missing_and_incompatible_model(tmp_path):
    from training.evaluate import evaluate_run
    with pytest.raises(ValueError, match="config.json"):
        evaluate_run(tmp_path)
    run = tmp_path / "run"
    train_agent(run, "PennyProbeDrive-Plane-v0", "ppo", 0, 64, 2, {"n_steps": 32, "batch_size": 64, "n_epochs": 1},
                eval_points=1, eval_episodes=2, checkpoints=1)
    for f in ("config.json", "model.zip", "progress.csv", "curve.csv"):
        assert (run / f).is_file(), f
    assert list(run.glob("events.out.tfevents.*")) and list((run / "checkpoints").glob("*.zip"))
    cfg = json.loads((run / "config.json").read_text())
    (run / "config.json").write_text(json.dumps(dict(cfg, env_id="PennyProbeBoth-Plane-v0")))  # 2 actions, model has 1
    with pytest.raises(ValueError, match="incompatible with PennyProbeBoth-Plane-v0"):
        load_run(run)
    (run / "config.json").write_text(json.dumps(dict(cfg, algo="sac")))
    with pytest.raises(ValueError, match="cannot be loaded as a sac model"):
        load_run(run)
    (run / "config.json").write_text(json.dumps(cfg))
    (run / "model.zip").write_bytes(b"not a zip")
    with pytest.raises(ValueError, match="model.zip"):
        load_run(run)
    (run / "model.zip").unlink()
    with pytest.raises(ValueError, match="missing model file"):
        load_run(run)


def test_wilson_interval():
    assert wilson_interval(0, 10)[0] == 0.0 and wilson_interval(0, 10)[1] == pytest.approx(0.2775, abs=1e-4)
    lo, hi = wilson_interval(50, 100)
    assert lo == pytest.approx(1 - hi) and lo < 0.5 < hi


@pytest.mark.slow
def test_evaluate_run_dir_with_video(ppo_run, tmp_path):
    pytest.importorskip("moviepy", reason="RecordVideo writes mp4 with moviepy")
    pytest.importorskip("pygame", reason="rgb_array rendering")
    from training.evaluate import main
    res = main([str(ppo_run), "--episodes", "8", "--video-episodes", "1", "--gif", str(tmp_path / "a.gif")])
    lo, hi = res["ci95_wilson"]
    assert lo <= res["success_rate"] <= hi and res["episodes"] == 8
    assert len(res["videos"]) == 1 and (ppo_run / "evaluation.json").is_file()
    from PIL import Image
    with Image.open(tmp_path / "a.gif") as im:
        assert im.n_frames > 10
    assert res["gif_seed"] == res["seed"]


@pytest.mark.slow
def test_gif_success_shows_the_first_successful_episode(ppo_run, tmp_path, monkeypatch):
    pytest.importorskip("pygame", reason="rgb_array rendering")
    import training.episodes
    import training.evaluate as ev
    real = training.episodes.run_episodes

    def third_succeeds(env_id, policy, episodes, seed):
        r = real(env_id, policy, episodes, seed)
        r["success"] = [j == 2 for j in range(episodes)]
        return r
    monkeypatch.setattr(training.episodes, "run_episodes", third_succeeds)
    res = ev.evaluate_run(ppo_run, episodes=4, video_episodes=0, gif=str(tmp_path / "b.gif"), gif_success=True)
    assert res["gif_seed"] == res["seed"] + 2 and res["gif_success"] and (tmp_path / "b.gif").is_file()


def test_training_leaves_the_job_config_as_it_was(tmp_path):
    """SB3 adds keys to policy_kwargs (SAC: use_sde); the caller's dict (a ladder or study job records it and compares
    it on a rerun) must not change."""
    hyper = {"learning_starts": 16, "buffer_size": 1000, "batch_size": 16, "policy_kwargs": {"net_arch": [8]}}
    before = json.loads(json.dumps(hyper))
    train_agent(tmp_path / "run", "PennyProbeDrive-Plane-v0", "sac", 0, 64, 2, hyper, 1, 2)
    assert hyper == before
