"""Resumable jobs of a study: each job writes its folder and, last, result.json (atomically); a rerun skips the jobs
whose result.json was made by the same job config. They run in a process pool on the local cores or as Ray tasks
(RAY_ADDRESS, or a local Ray instance). Used by studies/ladder.py."""
from __future__ import annotations

import json
import os
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


class DamagedResult(ValueError):
    """A result.json that is not a job's result (truncated, not JSON, not an object with its job), named."""


def read_result(path) -> dict:
    """The result in ``path``; DamagedResult naming the file and the remedy when it is not a job's result."""
    path = Path(path)
    try:
        result = json.loads(path.read_bytes().decode("utf-8"))
    except (ValueError, OSError) as exc:  # (UnicodeDecodeError and JSONDecodeError are ValueErrors)
        raise DamagedResult(f"{path} is damaged ({type(exc).__name__}: {exc}); delete it and the study reruns its "
                            "job") from None
    if not isinstance(result, dict) or not isinstance(result.get("job"), dict):
        raise DamagedResult(f"{path} is damaged (it holds {type(result).__name__} {str(result)[:60]!r}, not a job's "
                            "result with its job); delete it and the study reruns its job")
    return result


def result_of(runs, job, job_dir) -> dict | None:
    """The job's result when it was made by this very job (cell, agent, seed, budgets, hyperparameters, episodes),
    else None: a result of a job whose config has changed since is stale. DamagedResult for a damaged file."""
    path = job_dir(runs, job) / "result.json"
    if not path.is_file():
        return None
    result = read_result(path)
    return result if result["job"] == job else None


def finished(runs, job, job_dir) -> bool:
    """The job has a result made by this very job (result_of); a damaged or stale one runs again."""
    try:
        return result_of(runs, job, job_dir) is not None
    except DamagedResult:
        return False


def _finish(runs, result, job_dir):
    path = job_dir(runs, result["job"]) / "result.json"
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(result))
    tmp.replace(path)  # atomic: result.json exists only for a finished job


def run_jobs(run_job, todo, runs, workers: int, job_dir, ray: bool = False) -> None:
    """``run_job(job, runs) -> result`` for every job of ``todo``, in a process pool of ``workers`` or as Ray tasks;
    each result is written to its job's folder (``job_dir(runs, job)``) as it comes. RuntimeError naming the jobs
    that failed once the others are done (a rerun retries them)."""
    (_ray if ray else _pool)(run_job, todo, runs, workers, job_dir)


def _pool(run_job, todo, runs, workers, job_dir):
    from concurrent.futures import ProcessPoolExecutor, as_completed
    import multiprocessing as mp
    from tqdm import tqdm
    with ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn")) as ex:
        futures = [ex.submit(run_job, job, str(runs)) for job in todo]
        failed = []
        for fut in tqdm(as_completed(futures), total=len(futures), desc="jobs", unit="job"):
            try:
                _finish(runs, fut.result(), job_dir)
            except Exception as exc:  # keep the other jobs going; a rerun retries this one
                failed.append(f"{futures.index(fut)}: {type(exc).__name__}: {exc}")
    _raise_failed(failed, todo)


def _raise_failed(failed, todo):
    if failed:
        lines = [f"  {todo[int(f.split(':')[0])].get('cell')} {todo[int(f.split(':')[0])].get('agent')} "
                 f"seed {todo[int(f.split(':')[0])].get('seed')}: {f.split(': ', 1)[1]}" for f in failed]
        raise RuntimeError(f"{len(failed)} job(s) failed (the others are saved; rerun to retry):\n" + "\n".join(lines))


def check_ray():
    try:
        import ray  # noqa: F401
    except ImportError:
        raise ValueError('--ray needs Ray, which is not installed: '
                         'the ray extra (pip install -e ".[ray]" in the clone)') from None


def _ray(run_job, todo, runs, workers, job_dir):
    import ray
    from tqdm import tqdm
    address = os.environ.get("RAY_ADDRESS") or None
    env = {"env_vars": {"PYTHONPATH": os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH", "")) if p)}}
    if address is None:
        ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False, runtime_env=env)
    else:
        ray.init(address=address, log_to_driver=False)
    try:
        task = ray.remote(num_cpus=1)(run_job)
        refs = [task.remote(job, str(runs)) for job in todo]
        index = {r: i for i, r in enumerate(refs)}
        pending, failed = list(refs), []
        with tqdm(total=len(pending), desc="jobs (ray)", unit="job") as bar:
            while pending:
                done, pending = ray.wait(pending, num_returns=1)
                try:
                    _finish(runs, ray.get(done[0]), job_dir)
                except Exception as exc:  # a RayTaskError wraps the job's exception
                    failed.append(f"{index[done[0]]}: {type(exc).__name__}: {exc}")
                bar.update(1)
    finally:
        ray.shutdown()
    _raise_failed(failed, todo)


