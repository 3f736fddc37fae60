"""lab.jobs: a job's result is its own (a changed config or a damaged file runs it again), failures are named."""
import pytest

from lab import jobs as jobs_module
from lab.jobs import finished


def job_dir(runs, job):
    return runs / job["cell"] / job["agent"] / f"seed{job['seed']}"


def test_failed_jobs_are_named():
    jobs = [{"cell": "PennyProbeDrive-Plane-v0", "agent": "ppo", "seed": 3}]
    with pytest.raises(RuntimeError, match="PennyProbeDrive-Plane-v0 ppo seed 3: ValueError: boom"):
        jobs_module._raise_failed(["0: ValueError: boom"], jobs)
    jobs_module._raise_failed([], jobs)  # nothing failed: no error


def test_a_result_of_another_config_is_stale(tmp_path):
    """A rerun skips a job only if its result.json was made by the same job; a changed budget runs it again."""
    job = {"cell": "PennyProbeDrive-Plane-v0", "agent": "ppo", "seed": 0, "eval_episodes": 4, "timesteps": 1024,
           "num_envs": 8, "hyperparameters": {"n_steps": 64, "policy_kwargs": {"net_arch": [32, 32]}},
           "curve_points": 2, "curve_episodes": 8}
    assert not finished(tmp_path, job, job_dir)
    job_dir(tmp_path, job).mkdir(parents=True)
    jobs_module._finish(tmp_path, {"job": job, "episodes": {}, "curve": [], "seconds": 0.0}, job_dir)
    assert finished(tmp_path, job, job_dir)  # the JSON round trip keeps it equal
    assert not finished(tmp_path, dict(job, timesteps=2048), job_dir)
    assert not finished(tmp_path, dict(job, hyperparameters={"n_steps": 128}), job_dir)
    (job_dir(tmp_path, job) / "result.json").write_text("{not json")
    assert not finished(tmp_path, job, job_dir)
