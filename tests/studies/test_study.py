"""studies.study, training.runner, training.evaluate: bad input fails before any training,
the statistics, --quick end to end (process pool and Ray give the same rows)."""
import csv
import json
import sys

import pytest

pytest.importorskip("stable_baselines3", reason="the study trains SB3 agents")
pytest.importorskip("torch", reason="SB3 needs torch")

from studies import study  # noqa: E402
from studies import jobs as jobs_module  # noqa: E402
from studies.jobs import finished  # noqa: E402
from training.evaluate import wilson_interval  # noqa: E402

QUICK = study.QUICK_CONFIG.read_text()


def _cfg(tmp_path, text):
    p = tmp_path / "study.yaml"
    p.write_text(text)
    return str(p)


@pytest.mark.parametrize("old,new,match", [
    ("agents: [ppo,", "agents: [ppo, dqn,", "unknown agent/algorithm 'dqn'"),
    ("PennyProbeDrive-Plane-v0,", "PennyNoSuch-v0,", "unknown cell \\(env id\\) 'PennyNoSuch-v0'"),
    ("n_epochs: 2,", "n_epochz: 2,", "unknown ppo hyperparameter\\(s\\) \\['n_epochz'\\]"),
    ("seeds: [0, 1]", "seeds: [0, 1]\nbudget: 3", "unknown config key\\(s\\) \\['budget'\\]"),
    ("seeds: [0, 1]", "seeds: [0, -1]", "seeds must be"),
    ("timesteps: {ppo: 1024, sac: 256}", "timesteps: {ppo: 1024, sac: 256, a2c: 5}", "timesteps: unknown algorithm"),
    ("seeds: [0, 1]", "seeds: [0, 1]\ntimesteps_per_probe: {Park: {ppo: 5}}", "timesteps_per_probe: unknown probe 'Park'"),
    ("seeds: [0, 1]", "seeds: [0, 1]\ntimesteps_per_probe: {Both: {td3: 5}}", "timesteps_per_probe.Both: unknown algorithm"),
    ("seeds: [0, 1]", "seeds: [0, 1]\ntimesteps_per_probe: {Both: {ppo: 0}}", "timesteps_per_probe.Both.ppo must be"),
    ("seeds: [0, 1]", "seeds: [0, 1]\ntimesteps_per_probe: [Both]", "timesteps_per_probe must map"),
])
def test_bad_config_named_before_training(tmp_path, capsys, old, new, match):
    assert old in QUICK
    path = _cfg(tmp_path, QUICK.replace(old, new))
    with pytest.raises(ValueError, match=match):
        study.load_config(path)
    with pytest.raises(SystemExit):
        study.main(["--config", path, "--runs", str(tmp_path / "runs"), "--out", str(tmp_path / "r.md")])
    assert "error:" in capsys.readouterr().err
    assert not (tmp_path / "runs").exists()  # nothing started


def test_per_probe_budget_overrides_only_that_probe(tmp_path):
    path = _cfg(tmp_path, QUICK + "timesteps_per_probe: {Both: {sac: 512}}\n")
    jobs = study.make_jobs(study.load_config(path))
    budget = {(j["cell"], j["agent"]): j.get("timesteps") for j in jobs}
    assert budget[("PennyProbeBoth-Plane-v0", "sac")] == 512
    assert budget[("PennyProbeBoth-Plane-v0", "ppo")] == 1024
    assert budget[("PennyProbeDrive-Plane-v0", "sac")] == 256
    default = study.make_jobs(study.load_config(study.QUICK_CONFIG))
    assert [j for j in default if j["cell"] != "PennyProbeBoth-Plane-v0" or j["agent"] != "sac"] == \
        [j for j in jobs if j["cell"] != "PennyProbeBoth-Plane-v0" or j["agent"] != "sac"]  # the others are not rerun


def test_large_config_reruns_only_the_both_controls_sac_jobs():
    """configs/study/large.yaml is the default with a longer SAC budget on the both-controls probe: after a
    default run it reruns only those jobs (the stale check keys on the whole job config)."""
    default = study.make_jobs(study.load_config(study.DEFAULT_CONFIG))
    large = study.make_jobs(study.load_config(study.ROOT / "configs" / "study" / "large.yaml"))
    changed = [(a["cell"], a["agent"]) for a, b in zip(default, large, strict=True) if a != b]
    assert changed and all(c.startswith("PennyProbeBoth-") and a == "sac" for c, a in changed)
    assert len(changed) == 7 * 5


def test_ray_missing_is_named(tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    with pytest.raises(SystemExit):
        study.main(["--quick", "--ray", "--runs", str(tmp_path / "runs")])
    assert "--ray needs Ray" in capsys.readouterr().err
    assert not (tmp_path / "runs").exists()


def test_quick_never_writes_docs(tmp_path, capsys):
    with pytest.raises(SystemExit):
        study.main(["--quick", "--runs", str(tmp_path / "runs"), "--out", str(study.ROOT / "docs" / "study.md")])
    assert "never writes into docs/" in capsys.readouterr().err


def test_missing_and_incompatible_model(tmp_path):
    from training.runner import load_run, train_agent
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


def _row(table, agent, s, lo, hi):
    return {"table": table, "agent": agent, "success": s, "ci_low": lo, "ci_high": hi}


def test_last_quarter_change_interpolates():
    from studies.study_report import last_quarter_change
    curve = [[0, 0.0], [100, 0.2], [200, 0.4], [300, 0.6], [400, 1.0]]
    assert last_quarter_change(curve) == pytest.approx(1.0 - 0.6)
    assert last_quarter_change([[0, 0.1], [350, 0.5], [700, 0.5], [1000, 0.9]]) == pytest.approx(0.9 - 0.5 - 0.4 * 50 / 300)


def test_flattening_counts_only_solved_cells_and_rising_curves():
    from studies.study_report import FLAT, flattening

    def row(table, agent, low, change, last=0.5):
        return dict(_row(table, agent, low + 0.05, low, low + 0.1), cell=f"PennyProbeBoth-{table}-v0",
                    curve_last_change=change, curve_last=last)
    rows = [row("Plane", "ppo", 0.5, FLAT + 0.01), row("Plane", "sac", 0.2, FLAT - 0.01),
            row("Ellipse-Elastic", "ppo", 0.0, 0.3), row("Ellipse-Elastic", "sac", 0.0, 0.2),  # unsolved
            row("Stadium-E05", "ppo", 0.4, -0.1), row("Stadium-E05", "zero", 0.9, "", ""),
            row("Stadium-E05", "sac", 0.9, FLAT + 0.01, 1 - FLAT / 2)]  # at the ceiling: no room to rise
    solved, rising = flattening(rows)
    assert solved == ["PennyProbeBoth-Plane-v0", "PennyProbeBoth-Stadium-E05-v0"]
    assert [(r["table"], r["agent"]) for r in rising] == [("Plane", "ppo")]


@pytest.fixture(scope="module")
def quick_pool(tmp_path_factory):
    runs = tmp_path_factory.mktemp("quick_pool")
    out = study.main(["--quick", "--runs", str(runs), "--workers", "2"])
    return runs, out


@pytest.mark.slow
def test_quick_end_to_end(quick_pool, capsys):
    runs, out = quick_pool
    assert out == runs / "study.md"
    text = out.read_text()
    cfg = study.load_config(study.QUICK_CONFIG)
    jobs = study.make_jobs(cfg)
    assert len(jobs) == 3 * 4 * 2 + 2  # feedback only on the both-controls cell
    with open(out.with_suffix(".csv")) as f:
        rows = list(csv.DictReader(f))
    assert {(r["cell"], r["agent"]) for r in rows} == {(j["cell"], j["agent"]) for j in jobs}
    assert all(int(r["seeds"]) == 2 and int(r["episodes"]) == 32 for r in rows)
    # the plane's invariant: drive only never reaches a target off the heading line
    assert all(float(r["success"]) == 0.0 for r in rows if r["cell"] == "PennyProbeDrive-Plane-v0")
    fb = [r for r in rows if r["agent"] == "feedback"]
    assert fb and float(fb[0]["success"]) > 0.8
    assert "| Drive | " in text and "| Both | " in text and "## Proven" in text and "witnesses.md" in text
    assert (runs / "study_curves_drive.png").is_file() and (runs / "study_curves_both.png").is_file()
    # a rerun skips the finished jobs
    capsys.readouterr()
    study.main(["--quick", "--runs", str(runs), "--workers", "2"])
    assert f"{len(jobs)} jobs, {len(jobs)} already finished" in capsys.readouterr().out


@pytest.mark.slow
def test_quick_ray_same_rows_as_pool(quick_pool, tmp_path, capsys):
    # the pool's finished jobs are copied and one job of each trained agent and of the feedback agent is taken out:
    # those run again as Ray tasks (the others are skipped as finished) and the report's rows are the pool's, to the
    # letter (rerunning every quick job under Ray cost 4 minutes of the suite and tests nothing more)
    pytest.importorskip("ray", reason="--ray needs ray")
    import shutil

    from studies.study_report import job_dir
    runs, out = quick_pool
    copy = tmp_path / "runs"
    shutil.copytree(runs, copy)
    jobs = study.make_jobs(study.load_config(study.QUICK_CONFIG))
    rerun = [next(j for j in jobs if j["agent"] == agent) for agent in ("ppo", "sac", "feedback")]
    for j in rerun:
        (job_dir(copy, j) / "result.json").unlink()
    capsys.readouterr()
    ray_out = study.main(["--quick", "--ray", "--runs", str(copy), "--workers", "2"])
    assert f"{len(jobs)} jobs, {len(jobs) - len(rerun)} already finished" in capsys.readouterr().out
    assert all(finished(copy, j, job_dir) for j in rerun)
    assert ray_out.with_suffix(".csv").read_text() == out.with_suffix(".csv").read_text()


@pytest.mark.slow
def test_evaluate_run_dir_with_video(quick_pool, tmp_path):
    pytest.importorskip("moviepy", reason="RecordVideo writes mp4 with moviepy")
    pytest.importorskip("pygame", reason="rgb_array rendering")
    from training.evaluate import main
    runs, _ = quick_pool
    run = runs / "PennyProbeDrive-Ellipse-Elastic-v0" / "ppo" / "seed0"
    res = main([str(run), "--episodes", "8", "--video-episodes", "1", "--gif", str(tmp_path / "a.gif")])
    lo, hi = res["ci95_wilson"]
    assert lo <= res["success_rate"] <= hi and res["episodes"] == 8
    assert len(res["videos"]) == 1 and (run / "evaluation.json").is_file()
    from PIL import Image
    with Image.open(tmp_path / "a.gif") as im:
        assert im.n_frames > 10
    assert res["gif_seed"] == res["seed"]


@pytest.mark.slow
def test_gif_success_shows_the_first_successful_episode(quick_pool, tmp_path, monkeypatch):
    pytest.importorskip("pygame", reason="rgb_array rendering")
    import training.episodes
    import training.evaluate as ev
    runs, _ = quick_pool
    run = runs / "PennyProbeDrive-Ellipse-Elastic-v0" / "ppo" / "seed0"
    real = training.episodes.run_episodes

    def third_succeeds(env_id, policy, episodes, seed):
        r = real(env_id, policy, episodes, seed)
        r["success"] = [j == 2 for j in range(episodes)]
        return r
    monkeypatch.setattr(training.episodes, "run_episodes", third_succeeds)
    res = ev.evaluate_run(run, episodes=4, video_episodes=0, gif=str(tmp_path / "b.gif"), gif_success=True)
    assert res["gif_seed"] == res["seed"] + 2 and res["gif_success"] and (tmp_path / "b.gif").is_file()


def test_failed_jobs_are_named():
    jobs = [{"cell": "PennyProbeDrive-Plane-v0", "agent": "ppo", "seed": 3}]
    with pytest.raises(RuntimeError, match="PennyProbeDrive-Plane-v0 ppo seed 3: ValueError: boom"):
        jobs_module._raise_failed(["0: ValueError: boom"], jobs)
    jobs_module._raise_failed([], jobs)  # nothing failed: no error


def test_readme_says_what_the_report_computes_of_the_curves():
    """The README claims flattened curves only if the committed report's rows say so."""
    from studies.study_report import _num, flattening
    with open(study.ROOT / "docs" / "study.csv") as f:
        rows = [{k: _num(v) for k, v in r.items()} for r in csv.DictReader(f)]
    solved, rising = flattening(rows)
    claim = "the learning curves of every solved cell have flattened" in (study.ROOT / "README.md").read_text()
    assert solved and claim == (not rising), [(r["cell"], r["agent"], r["curve_last_change"]) for r in rising]


def test_paired_times_pair_the_same_draws():
    from studies.study_report import paired_times
    def res(cell, agent, seed, success, time):
        return {"job": {"cell": cell, "agent": agent, "seed": seed},
                "episodes": {"success": success, "time": time}}
    plane, table = "PennyProbeBoth-Plane-v0", "PennyProbeBoth-Stadium-Elastic-v0"
    groups = {(plane, "ppo"): [res(plane, "ppo", 0, [True, True, False, True], [3.0, 2.0, 9.0, 4.0])],
              (table, "ppo"): [res(table, "ppo", 0, [True, False, True, True], [1.0, 9.0, 1.0, 5.0])],
              (table, "sac"): [res(table, "sac", 0, [True] * 4, [1.0] * 4)]}  # no plane sac: not paired
    rows = paired_times(groups, "Both")
    assert len(rows) == 1 and rows[0]["agent"] == "ppo" and rows[0]["pairs"] == 2  # episodes 0 and 3
    assert rows[0]["mean_diff_s"] == pytest.approx(((1 - 3) + (5 - 4)) / 2)
    assert rows[0]["table_faster"] == 0.5 and rows[0]["ci_low"] <= rows[0]["mean_diff_s"] <= rows[0]["ci_high"]


def test_a_result_of_another_config_is_stale(tmp_path):
    """A rerun skips a job only if its result.json was made by the same job; a changed budget runs it again."""
    job = {"cell": "PennyProbeDrive-Plane-v0", "agent": "ppo", "seed": 0, "eval_episodes": 4, "timesteps": 1024,
           "num_envs": 8, "hyperparameters": {"n_steps": 64, "policy_kwargs": {"net_arch": [32, 32]}},
           "curve_points": 2, "curve_episodes": 8}
    assert not finished(tmp_path, job, study.job_dir)
    study.job_dir(tmp_path, job).mkdir(parents=True)
    jobs_module._finish(tmp_path, {"job": job, "episodes": {}, "curve": [], "seconds": 0.0}, study.job_dir)
    assert finished(tmp_path, job, study.job_dir)  # the JSON round trip keeps it equal
    assert not finished(tmp_path, dict(job, timesteps=2048), study.job_dir)
    assert not finished(tmp_path, dict(job, hyperparameters={"n_steps": 128}), study.job_dir)
    (study.job_dir(tmp_path, job) / "result.json").write_text("{not json")
    assert not finished(tmp_path, job, study.job_dir)


def test_training_leaves_the_job_config_as_it_was(tmp_path):
    """SB3 adds keys to policy_kwargs (SAC: use_sde); the job's own dict, which result.json records and the rerun
    check compares, must not change, or every finished SAC job would look stale."""
    pytest.importorskip("stable_baselines3")
    from training.runner import train_agent
    hyper = {"learning_starts": 16, "buffer_size": 1000, "batch_size": 16, "policy_kwargs": {"net_arch": [8]}}
    before = json.loads(json.dumps(hyper))
    train_agent(tmp_path / "run", "PennyProbeDrive-Plane-v0", "sac", 0, 64, 2, hyper, 1, 2)
    assert hyper == before
