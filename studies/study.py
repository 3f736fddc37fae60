"""The RL study "does controllability of the penny need impacts?".

    python -m studies.study [--config configs/study/default.yaml] [--runs runs/study] [--out docs/study.md]
                             [--workers N] [--ray] [--quick]

Jobs are keyed by (cell, agent, seed): a cell is a probe env id (docs/study_probes.md), an agent PPO or
SAC (SB3, trained then evaluated) or a reference (zero, random, feedback). Each job writes its files
under RUNS/<cell>/<agent>/seed<k>/ and, last, result.json; a rerun skips the jobs that have one made
with the same job config (a changed budget or hyperparameter runs the job again), so a crash or a stop
loses nothing. The jobs run in a process pool on all local cores (--workers) with a progress bar, or
with --ray as Ray tasks on the cluster named by RAY_ADDRESS (a local Ray instance when it is unset; a
cluster needs penny_env installed and --runs on a shared file system). The report
(studies/study_report.py) goes to --out, with its CSV and PNGs beside it. --quick runs
configs/study/quick.yaml (a few minutes on 2 cores, learns nothing) and never writes into docs/.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import yaml

from training.policies import REFERENCE_AGENTS
from training.runner import ALGOS
from studies.jobs import check_ray, finished, run_jobs
from studies.study_report import PROBES, job_dir, split_cell

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_CONFIG = ROOT / "configs" / "study" / "default.yaml"
QUICK_CONFIG = ROOT / "configs" / "study" / "quick.yaml"
AGENTS = ALGOS + REFERENCE_AGENTS
KEYS = {"cells", "agents", "seeds", "eval_episodes", "curve_points", "curve_episodes", "timesteps",
        "num_envs", "hyperparameters"}
OPTIONAL_KEYS = {"timesteps_per_probe"}  # {probe: {algo: steps}}: a longer budget where a probe learns slower


def probe_cells() -> list[str]:
    import penny_env  # noqa: F401
    from penny_env.envs import env_ids
    return [i for i in env_ids() if i.startswith("PennyProbe")]


def load_config(path) -> dict:
    """Read and check a study config: ValueError naming an unknown key, cell, agent or
    hyperparameter, or a bad value, before any job starts."""
    from penny_env.envs.yaml_io import read_text
    from penny_env.envs.yaml_io import safe_load as yaml_load  # (1e-2 read as a float, as in YAML 1.2)
    path = Path(path)
    text = read_text(path, "study config")  # (a folder, a missing file, bytes that are not UTF-8: named)
    try:
        cfg = yaml_load(text)
    except yaml.YAMLError as exc:
        raise ValueError(f"{path}: invalid YAML: {exc}") from None
    if not isinstance(cfg, dict):
        raise ValueError(f"{path}: a study config must be a mapping")
    unknown = sorted(set(cfg) - KEYS - OPTIONAL_KEYS)
    if unknown:
        raise ValueError(f"{path}: unknown config key(s) {unknown}; known: {sorted(KEYS | OPTIONAL_KEYS)}")
    missing = sorted(KEYS - set(cfg))
    if missing:
        raise ValueError(f"{path}: missing config key(s) {missing}")
    import penny_env  # noqa: F401
    from penny_env.envs import env_ids
    known = env_ids()
    if cfg["cells"] == "all":
        cfg["cells"] = probe_cells()
    if not isinstance(cfg["cells"], list) or not cfg["cells"]:
        raise ValueError(f"{path}: cells must be 'all' or a non-empty list of env ids")
    for c in cfg["cells"]:
        if c not in known:
            raise ValueError(f"{path}: unknown cell (env id) {c!r}; registered: {known}")
    if not isinstance(cfg["agents"], list) or not cfg["agents"]:
        raise ValueError(f"{path}: agents must be a non-empty list")
    for a in cfg["agents"]:
        if a not in AGENTS:
            raise ValueError(f"{path}: unknown agent/algorithm {a!r}; known: {list(AGENTS)}")
    seeds = cfg["seeds"]
    if not isinstance(seeds, list) or not seeds or any(isinstance(s, bool) or not isinstance(s, int) or s < 0 for s in seeds):
        raise ValueError(f"{path}: seeds must be a non-empty list of non-negative integers, got {seeds!r}")
    for k in ("eval_episodes", "curve_points", "curve_episodes"):
        v = cfg[k]
        if isinstance(v, bool) or not isinstance(v, int) or v < 1:
            raise ValueError(f"{path}: {k} must be a positive integer, got {v!r}")
    from training.runner import check_hyperparameters
    for algo in (a for a in cfg["agents"] if a in ALGOS):
        for k in ("timesteps", "num_envs"):
            v = (cfg[k] or {}).get(algo) if isinstance(cfg[k], dict) else None
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"{path}: {k}.{algo} must be a positive integer, got {v!r}")
        hyper = cfg["hyperparameters"] if isinstance(cfg["hyperparameters"], dict) else {}
        check_hyperparameters(algo, hyper.get(algo) or {})
    for k in ("timesteps", "num_envs", "hyperparameters"):
        extra = sorted(set(cfg[k] or {}) - set(ALGOS)) if isinstance(cfg[k], dict) else [cfg[k]]
        if extra:
            raise ValueError(f"{path}: {k}: unknown algorithm(s) {extra}; known: {list(ALGOS)}")
    cfg["timesteps_per_probe"] = _check_per_probe(path, cfg.get("timesteps_per_probe"))
    return cfg


def _check_per_probe(path, per_probe) -> dict:
    """timesteps_per_probe: {Steer|Drive|Both: {ppo|sac: positive int}}, overriding timesteps for that probe's cells."""
    if per_probe is None:
        return {}
    if not isinstance(per_probe, dict):
        raise ValueError(f"{path}: timesteps_per_probe must map a probe ({', '.join(PROBES)}) to "
                         f"{{algorithm: timesteps}}, got {per_probe!r}")
    for probe, budgets in per_probe.items():
        if probe not in PROBES:
            raise ValueError(f"{path}: timesteps_per_probe: unknown probe {probe!r}; known: {list(PROBES)}")
        if not isinstance(budgets, dict):
            raise ValueError(f"{path}: timesteps_per_probe.{probe} must map an algorithm to timesteps, got {budgets!r}")
        for algo, v in budgets.items():
            if algo not in ALGOS:
                raise ValueError(f"{path}: timesteps_per_probe.{probe}: unknown algorithm {algo!r}; known: {list(ALGOS)}")
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"{path}: timesteps_per_probe.{probe}.{algo} must be a positive integer, got {v!r}")
    return per_probe


def timesteps_of(cfg, cell: str, algo: str) -> int:
    """The training budget of one cell: the probe's own (timesteps_per_probe) if it has one, else timesteps."""
    per_probe = cfg.get("timesteps_per_probe") or {}
    return per_probe.get(split_cell(cell)[0], {}).get(algo, cfg["timesteps"][algo])


def make_jobs(cfg) -> list[dict]:
    """The (cell, agent, seed) jobs; the feedback controller only where both controls act."""
    from penny_env.envs import resolve
    from penny_env.envs.scene import env_presets
    presets = env_presets()
    jobs = []
    for cell in cfg["cells"]:
        both = resolve(**presets[cell])[0].actuation == "both"
        for agent in cfg["agents"]:
            if agent == "feedback" and not both:
                continue
            for seed in cfg["seeds"]:
                job = {"cell": cell, "agent": agent, "seed": seed, "eval_episodes": cfg["eval_episodes"]}
                if agent in ALGOS:
                    job.update(timesteps=timesteps_of(cfg, cell, agent), num_envs=cfg["num_envs"][agent],
                               hyperparameters=(cfg["hyperparameters"] or {}).get(agent) or {},
                               curve_points=cfg["curve_points"], curve_episodes=cfg["curve_episodes"])
                jobs.append(job)
    return jobs


def run_job(job: dict, runs: str) -> dict:
    """Train (RL agents) and evaluate one job; returns its result (the caller writes result.json)."""
    import csv
    from training.episodes import make_vector_env, run_episodes
    from training.runner import eval_seed, train_agent
    import numba
    numba.set_num_threads(1)  # one job per core (pool or Ray task): the vector env's prange would oversubscribe
    out = job_dir(runs, job)
    out.mkdir(parents=True, exist_ok=True)
    t0, c0 = time.perf_counter(), time.process_time()
    curve = []
    if job["agent"] in ALGOS:
        model = train_agent(out, job["cell"], job["agent"], job["seed"], job["timesteps"], job["num_envs"],
                            job["hyperparameters"], job["curve_points"], job["curve_episodes"])
        policy = lambda o: model.predict(o, deterministic=True)[0]  # noqa: E731
        with open(out / "curve.csv") as f:
            curve = [[float(r["timesteps"]), float(r["success_rate"])] for r in csv.DictReader(f)]
    else:
        from training.policies import reference_policy
        venv = make_vector_env(job["cell"], 1)
        policy = reference_policy(job["agent"], venv._core, job["seed"])
        venv.close()
    episodes = run_episodes(job["cell"], policy, job["eval_episodes"], eval_seed(job["seed"]))
    return {"job": job, "episodes": episodes, "curve": curve, "seconds": time.perf_counter() - t0,
            "cpu_seconds": time.process_time() - c0}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", default=None, help=f"study config (default {DEFAULT_CONFIG.relative_to(ROOT)})")
    ap.add_argument("--runs", default=None, help="job results folder (default runs/study, --quick: runs/study_quick)")
    ap.add_argument("--out", default=None, help="report (markdown; CSV and PNGs beside it). Default docs/study.md, "
                    "--quick: RUNS/study.md")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="parallel jobs (default: all cores)")
    ap.add_argument("--ray", action="store_true", help="run the jobs as Ray tasks (RAY_ADDRESS or a local instance)")
    ap.add_argument("--quick", action="store_true", help="configs/study/quick.yaml; never writes into docs/")
    args = ap.parse_args(argv)
    try:
        if args.workers < 1:
            raise ValueError(f"--workers must be >= 1, got {args.workers}")
        if args.ray:
            check_ray()
        cfg_path = Path(args.config) if args.config else (QUICK_CONFIG if args.quick else DEFAULT_CONFIG)
        cfg = load_config(cfg_path)
        runs = Path(args.runs or ("runs/study_quick" if args.quick else "runs/study"))
        out = Path(args.out) if args.out else (runs / "study.md" if args.quick else ROOT / "docs" / "study.md")
        if args.quick and (ROOT / "docs").resolve() in out.resolve().parents:
            raise ValueError(f"--quick never writes into docs/: --out {out}")
        if out.suffix != ".md":
            raise ValueError(f"--out must name a markdown file (.md), got {out}")
    except ValueError as exc:
        ap.error(str(exc))
    jobs = make_jobs(cfg)
    todo = [j for j in jobs if not finished(runs, j, job_dir)]
    stale = sum((job_dir(runs, j) / "result.json").is_file() for j in todo)
    print(f"{len(jobs)} jobs, {len(jobs) - len(todo)} already finished in {runs}"
          + (f"; {stale} with a result of another config (budgets, hyperparameters...) run again" if stale else ""),
          flush=True)
    t0 = time.perf_counter()
    if todo:
        run_jobs(run_job, todo, runs, args.workers, job_dir, ray=args.ray)
    from studies.study_report import write_report
    write_report(cfg, jobs, runs, out, argv=argv if argv is not None else sys.argv[1:],
                 seconds=time.perf_counter() - t0)
    print(f"report: {out}")
    if out.resolve() == (ROOT / "docs" / "study.md").resolve():
        print("the README's answer (learnability beside the verdicts) follows docs/study.csv: "
              "rerun python -m studies.witness_study --report-only to update it")
    return out


if __name__ == "__main__":
    main()
