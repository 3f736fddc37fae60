"""The agent ladder: baseline agents on the single-input cells, from scale to hindsight to curricula, each
measured by one deterministic evaluation on the witness study's pair seeds, beside the certified witnesses.

    python -m studies.ladder [--config configs/ladder/cpu.yaml] [--runs runs/ladder] [--out docs/ladder.md]
                             [--workers N] [--ray] [--quick] [--report-only]

Jobs are keyed by (agent, cell, seed). A cell is (probe, table, law), named as in docs/witnesses.csv and made by
studies/cells.cell_spec (the probe id, or its field overrides); every agent trains on the env with the fair reward
(the success bonus only: progress_weight, speed_cost and ctrl_cost 0; an agent may shape its own reward from what
it observes, and its docstring says so). An agent is one file in training/ following training/protocol.py: at
log-spaced env-step budgets (half decades from ``first_checkpoint`` to its budget) its deterministic policy plays
one episode per pair seed (training.protocol.evaluate: seeds 0..eval_seeds-1, the witness study's), and the job
records the successes and the impacts of each successful episode. Privileged agents (start-state curricula and
Go-Explore: they reset their training envs to chosen states, and learn from certified witness episodes of
training seeds, never of the pair seeds) are labelled so in every table and figure.

Each job writes RUNS/<agent>/<cell>/seed<k>/ and, last, result.json; a rerun skips the jobs that have one made by the
same job config (studies/jobs.py), so an interruption costs at most the job under way (each is under an hour on
one core at the committed budgets). --ray runs the jobs as Ray tasks (RAY_ADDRESS or a local instance).
Demonstrations for the privileged agents are made first, once per cell (RUNS/demos/<cell>.npz).

The report (--out; default docs/ladder.md, with docs/ladder.csv and the figures docs/ladder_<cell>.png beside it):
per cell, every agent's success at its budget with a 95 % interval clustered by seed (honest at 0 and 1:
studies/stats.seed_clustered_ci) beside the witnessed rate of the same pair seeds (docs/witnesses_pairs.csv), the
impacts per successful episode and a check that every single-input success had at least one impact (the theorems
say it must: a success without one stops the report as a bug), the rise of the success rate over the last decade
of samples, and the issue's goals checked from the table. One CSV row per (agent, privileged, probe, table, law,
seed, env_steps). The README's ladder block (one sentence per actuation) is written from the table.
--quick runs configs/ladder/quick.yaml in a new temporary folder (under a minute on the CPU) and never writes into
docs/ or the README.
"""
from __future__ import annotations

import argparse
import csv
import dataclasses
import importlib
import inspect
import json
import math
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from studies.cells import PROBE_TASKS, TABLE_NAMES, cell_spec
from studies.jobs import check_ray, finished, result_of, run_jobs

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
DEFAULT_CONFIG = ROOT / "configs" / "ladder" / "cpu.yaml"
QUICK_CONFIG = ROOT / "configs" / "ladder" / "quick.yaml"
KEYS = {"eval_seeds", "seeds", "first_checkpoint", "cells", "agents", "demos"}
AGENT_KEYS = {"module", "privileged", "probes", "budget", "args", "label", "seeds", "cells"}
DEMO_SEED = 100_000      # demonstrations: witness episodes of seeds DEMO_SEED + j
README_BEGIN = "<!-- ladder-answer: written by python -m studies.ladder (studies/ladder.py) -->"
README_END = "<!-- /ladder-answer -->"
CSV_FIELDS = ["agent", "label", "privileged", "probe", "table", "law", "seed", "env_steps", "successes", "episodes",
              "impacts_per_success", "successes_without_impact"]


# -- the config ------------------------------------------------------------------------------------------------
def load_config(path) -> dict:
    """Read and check a ladder config; ValueError naming the key, the agent or the cell, before any job runs."""
    from penny_env.envs.yaml_io import read_text, safe_load
    path = Path(path)
    cfg = safe_load(read_text(path, "ladder config"))
    if not isinstance(cfg, dict):
        raise ValueError(f"{path}: a ladder config must be a mapping")
    unknown, missing = sorted(set(cfg) - KEYS), sorted(KEYS - set(cfg))
    if unknown or missing:
        raise ValueError(f"{path}: unknown key(s) {unknown}, missing key(s) {missing}; keys: {sorted(KEYS)}")
    for key in ("eval_seeds", "first_checkpoint"):
        if isinstance(cfg[key], bool) or not isinstance(cfg[key], int) or cfg[key] < 1:
            raise ValueError(f"{path}: {key} must be a positive integer, got {cfg[key]!r}")
    seeds = cfg["seeds"]
    if not isinstance(seeds, list) or not seeds or any(isinstance(s, bool) or not isinstance(s, int) or s < 0
                                                       for s in seeds):
        raise ValueError(f"{path}: seeds must be a non-empty list of non-negative integers, got {seeds!r}")
    cells = []
    for c in cfg["cells"]:
        if not (isinstance(c, list) and len(c) == 3 and c[0] in PROBE_TASKS and c[1] in TABLE_NAMES):
            raise ValueError(f"{path}: a cell is [probe, table, law] with probe in {list(PROBE_TASKS)} and table in "
                             f"{list(TABLE_NAMES)}, got {c!r}")
        probe, table, law = c[0], c[1], "-" if c[1] == "plane" else str(c[2])
        cell_spec(probe, table, law)  # (an unknown law raises here)
        cells.append((probe, table, law))
    cfg["cells"] = cells
    if not isinstance(cfg["agents"], dict) or not cfg["agents"]:
        raise ValueError(f"{path}: agents must map a name to its settings")
    for name, a in cfg["agents"].items():
        if not isinstance(a, dict) or set(a) - AGENT_KEYS or not {"module", "privileged", "probes", "budget"} <= set(a):
            raise ValueError(f"{path}: agents.{name} must have module, privileged, probes, budget (and may have args, "
                             f"label), got {sorted(a) if isinstance(a, dict) else a!r}")
        if "seeds" in a and not _seed_list(a["seeds"]):
            raise ValueError(f"{path}: agents.{name}.seeds must be a list of distinct non-negative integers (the "
                             f"agent's own seeds, instead of the config's), got {a['seeds']!r}")
        if "cells" in a:  # the agent's own cells: a subset of the config's
            own = [(c[0], c[1], "-" if c[1] == "plane" else str(c[2])) for c in a["cells"]
                   if isinstance(c, list) and len(c) == 3]
            if len(own) != len(a["cells"]) or not set(own) <= set(cells):
                raise ValueError(f"{path}: agents.{name}.cells must be [probe, table, law] cells of the config's cells, "
                                 f"got {a['cells']!r}")
            a["cells"] = own
        if not isinstance(a["privileged"], bool):
            raise ValueError(f"{path}: agents.{name}.privileged must be true or false")
        if not set(a["probes"]) <= set(PROBE_TASKS):
            raise ValueError(f"{path}: agents.{name}.probes must be among {list(PROBE_TASKS)}, got {a['probes']!r}")
        if not isinstance(a["budget"], dict):
            raise ValueError(f"{path}: agents.{name}.budget must map a probe (or probe/table/law) to env steps")
        for key, b in a["budget"].items():
            if isinstance(b, bool) or not isinstance(b, (int, float)) or b < 1:
                raise ValueError(f"{path}: agents.{name}.budget.{key} must be a positive number of env steps, got {b!r}")
        for probe in a["probes"]:
            if probe not in a["budget"]:
                raise ValueError(f"{path}: agents.{name}.budget has no budget for probe {probe}")
        module = importlib.import_module(a["module"])
        if not hasattr(module, "Args") or not hasattr(module, "train"):
            raise ValueError(f"{path}: agents.{name}.module {a['module']} does not follow training/protocol.py "
                             "(Args and train)")
        names = {f.name for f in dataclasses.fields(module.Args)}
        bad = sorted(set(a.get("args") or {}) - names)
        if bad:
            raise ValueError(f"{path}: agents.{name}.args: {bad} are not fields of {a['module']}.Args")
    d = cfg["demos"]
    if not isinstance(d, dict) or set(d) != {"pairs"} or isinstance(d["pairs"], bool) or not isinstance(d["pairs"], int):
        raise ValueError(f"{path}: demos must be {{pairs: N}} (witness episodes per cell for the privileged agents)")
    return cfg


def _seeds_words(cfg) -> str:
    own = {n: a["seeds"] for n, a in cfg["agents"].items() if "seeds" in a}
    return ", ".join([f"{cfg['seeds']}"] + [f"{n} {s}" for n, s in own.items()])


def _seed_list(seeds) -> bool:
    return (isinstance(seeds, list) and bool(seeds) and len(set(seeds)) == len(seeds)
            and all(isinstance(x, int) and not isinstance(x, bool) and x >= 0 for x in seeds))


def checkpoints(first: int, budget: int) -> list[int]:
    """Log-spaced evaluation budgets: half decades from ``first`` up to ``budget``, and the budget itself."""
    out, k = [], 0
    while True:
        c = int(round(first * 10 ** (k / 2)))
        if c >= budget:
            break
        out.append(c)
        k += 1
    return out + [int(budget)]


def cell_name(cell) -> str:
    probe, table, law = cell
    return f"{probe}-{table}-{law}".replace(".", "")


def make_jobs(cfg) -> list[dict]:
    jobs = []
    for name, a in cfg["agents"].items():
        for cell in cfg["cells"]:
            if cell[0] not in a["probes"] or ("cells" in a and cell not in a["cells"]):
                continue
            budget = int(a["budget"].get("/".join(cell), a["budget"][cell[0]]))  # (a cell's own, else its probe's)
            for seed in a.get("seeds", cfg["seeds"]):
                jobs.append({"agent": name, "module": a["module"], "privileged": a["privileged"], "cell": list(cell),
                             "seed": seed, "budget": budget, "checkpoints": checkpoints(cfg["first_checkpoint"], budget),
                             "args": dict(a.get("args") or {}), "eval_seeds": cfg["eval_seeds"]})
    return jobs


def job_dir(runs, job) -> Path:
    return Path(runs) / job["agent"] / cell_name(job["cell"]) / f"seed{job['seed']}"


# -- demonstrations (privileged agents) -----------------------------------------------------------------------------
def demos_path(runs, cell) -> Path:
    return Path(runs) / "demos" / f"{cell_name(cell)}.npz"


def make_demos(runs, cell, pairs: int) -> Path:
    """Certified witness episodes of training seeds DEMO_SEED + j (never pair seeds) of ``cell``, replayed in the env
    with their states recorded (studies/witness_demos.py, training.protocol.save_demos). Made once per cell; a cell
    with no witness (the plane: theorems T2.3 and T3.2) gets an empty file, and the privileged agents start from the
    task's own draws there."""
    from studies.witness_demos import witness_demos
    from training.protocol import save_demos
    path = demos_path(runs, cell)
    if path.is_file():
        return path
    env_id, overrides = cell_spec(*cell)
    episodes = witness_demos(env_id, overrides, range(DEMO_SEED, DEMO_SEED + pairs))
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.stem + ".tmp.npz")
    save_demos(tmp, episodes)
    tmp.replace(path)
    return path


# -- one job ------------------------------------------------------------------------------------------------------
def run_job(job: dict, runs: str) -> dict:
    """Train the job's agent on its cell and evaluate it at its checkpoints (training.protocol.evaluate on the pair
    seeds); its result (the caller writes result.json)."""
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")  # one job per core: the vector env's prange would oversubscribe
    import numba
    import torch
    numba.set_num_threads(1)
    torch.set_num_threads(1)
    from training.protocol import evaluate, fair_reward_kwargs
    out = job_dir(runs, job)
    out.mkdir(parents=True, exist_ok=True)
    module = importlib.import_module(job["module"])
    env_id, overrides = cell_spec(*job["cell"])
    extra = dict(job["args"])
    if job["privileged"] and "demos" in {f.name for f in dataclasses.fields(module.Args)}:
        extra["demos"] = str(demos_path(runs, job["cell"]))  # (Go-Explore is privileged by its resets, not demos)
    # an agent with a ladder configuration (ppo_torch.ladder_args) starts from it; each agent maps its seed to
    # training seeds from 10,000,000 itself (never a pair seed); every agent trains on the fair reward
    make_args = getattr(module, "ladder_args", module.Args)
    args = make_args(env_id=env_id, env_kwargs={**overrides, **fair_reward_kwargs(env_id, overrides)},
                     seed=job["seed"], total_timesteps=job["budget"], out=str(out), **extra)
    rows = []
    progress = out / "checkpoints.jsonl"
    # an interrupted job goes on from the agent's checkpoint.pt when the same job wrote it (job.json), keeping the
    # evaluations it made up to that step; else it starts again
    resume = None
    ckpt, stamp = out / "checkpoint.pt", out / "job.json"
    takes_resume = "resume" in inspect.signature(module.train).parameters
    if takes_resume and ckpt.is_file() and stamp.is_file() and _same_job(stamp, job) and progress.is_file():
        import torch
        at = int(torch.load(ckpt, weights_only=False)["state"]["global_step"])
        rows = [r for r in map(json.loads, progress.read_text().splitlines()) if r["env_steps"] <= at]
        resume = str(ckpt)
    else:
        for stale in (ckpt, progress, out / "progress.csv"):
            stale.unlink(missing_ok=True)
    stamp.write_text(json.dumps(job))
    progress.write_text("".join(json.dumps(r) + "\n" for r in rows))
    t0, c0 = time.perf_counter(), time.process_time()

    def on_checkpoint(env_steps, policy):
        r = evaluate(policy, env_id, overrides, seeds=range(job["eval_seeds"]))
        row = {"env_steps": int(env_steps), "successes": r["successes"], "episodes": r["episodes"],
               "impacts_to_success": r["impacts_to_success"], "wall_s": time.perf_counter() - t0}
        rows.append(row)
        with open(progress, "a") as f:
            f.write(json.dumps(row) + "\n")

    kw = {"resume": resume} if takes_resume else {}
    train = module.train(args, checkpoints=job["checkpoints"], on_checkpoint=on_checkpoint, log=lambda *a: None, **kw)
    return {"job": job, "checkpoints": rows, "train": {k: v for k, v in (train or {}).items() if _plain(v)},
            "seconds": time.perf_counter() - t0, "cpu_seconds": time.process_time() - c0}


def _same_job(stamp: Path, job: dict) -> bool:
    try:
        return json.loads(stamp.read_text()) == job
    except (ValueError, OSError):
        return False


def _plain(v) -> bool:
    return isinstance(v, (int, float, str, bool)) or v is None


# -- the report -----------------------------------------------------------------------------------------------------
def witnessed_by_seed(cell, n: int, pairs_csv=DOCS / "witnesses_pairs.csv") -> np.ndarray | None:
    """The witness study's verdict per pair seed 0..n-1 of ``cell`` (docs/witnesses_pairs.csv), or None."""
    probe, table, law = cell
    with open(pairs_csv) as f:
        rows = [r for r in csv.DictReader(f) if (r["probe"], r["table"], r["law"]) == (probe, table, law)]
    got = {int(r["seed"]): r["witnessed"] in ("1", "True", "true") for r in rows}
    if not all(s in got for s in range(n)):
        return None
    return np.array([got[s] for s in range(n)])


def load_results(cfg, jobs, runs) -> tuple[dict, list]:
    """({(agent, cell tuple): [result of each seed that finished]}, [folders holding a stale result]): only results
    made by the config's own jobs count (studies/jobs.result_of); a damaged result.json stops the report, named."""
    out, stale = {}, []
    for job in jobs:
        result = result_of(runs, job, job_dir)
        if result is not None:
            out.setdefault((job["agent"], tuple(job["cell"])), []).append(result)
        elif (job_dir(runs, job) / "result.json").is_file():
            stale.append(job_dir(runs, job))
    return out, stale


def csv_rows(cfg, results) -> list[dict]:
    rows = []
    for (agent, cell), res in sorted(results.items()):
        a = cfg["agents"][agent]
        for r in res:
            for c in r["checkpoints"]:
                imp = [k for k in c["impacts_to_success"] if k >= 0]
                rows.append({"agent": agent, "label": a.get("label", agent), "privileged": a["privileged"],
                             "probe": cell[0], "table": cell[1], "law": cell[2], "seed": r["job"]["seed"],
                             "env_steps": c["env_steps"], "successes": c["successes"], "episodes": c["episodes"],
                             "impacts_per_success": round(float(np.mean(imp)), 3) if imp else "",
                             "successes_without_impact": sum(1 for k in imp if k == 0)})
    return rows


def final_outcomes(res) -> tuple[np.ndarray, int, list]:
    """(seeds x episodes 0/1 array at each seed's final checkpoint, env steps of it, impacts of the successes)."""
    M, imps, steps = [], [], 0
    for r in res:
        last = r["checkpoints"][-1]
        M.append([1.0 if k >= 0 else 0.0 for k in last["impacts_to_success"]])
        imps += [k for k in last["impacts_to_success"] if k >= 0]
        steps = max(steps, last["env_steps"])
    return np.array(M), steps, imps


def curve(res) -> tuple[np.ndarray, np.ndarray]:
    """(env steps, mean success over the seeds) at the checkpoints every seed reached."""
    steps = sorted(set.intersection(*[{c["env_steps"] for c in r["checkpoints"]} for r in res]))
    mean = [np.mean([next(c["successes"] / c["episodes"] for c in r["checkpoints"] if c["env_steps"] == s)
                     for r in res]) for s in steps]
    return np.array(steps, float), np.array(mean)


def last_decade_rise(res) -> float:
    """Mean success at the final checkpoint minus at the checkpoint a decade of samples before it (nan if none)."""
    steps, mean = curve(res)
    if len(steps) < 2:
        return math.nan
    j = np.searchsorted(steps, steps[-1] / 10.0 - 1e-9)
    j = min(j, len(steps) - 2)
    return float(mean[-1] - mean[j])


def summarize(cfg, results) -> list[dict]:
    """One row per (cell, agent): pooled success with its seed-clustered interval, the witnessed rate of the same
    pair seeds, the share, impacts per success, successes without an impact, the last decade's rise."""
    from studies.stats import seed_clustered_ci
    out = []
    for cell in cfg["cells"]:
        wit = witnessed_by_seed(cell, cfg["eval_seeds"])
        for agent, a in cfg["agents"].items():
            res = results.get((agent, cell))
            if not res:
                continue
            M, steps, imps = final_outcomes(res)
            lo, hi = seed_clustered_ci(M)
            rate = float(M.mean())
            w = float(wit.mean()) if wit is not None else math.nan
            out.append({"cell": cell, "agent": agent, "label": a.get("label", agent), "privileged": a["privileged"],
                        "seeds": len(res), "env_steps": steps, "success": rate, "ci": (lo, hi),
                        "per_seed": [float(m.mean()) for m in M], "witnessed": w,
                        "share": rate / w if w and w > 0 else math.nan,
                        "share_ci": (lo / w, min(hi / w, math.inf)) if w and w > 0 else (math.nan, math.nan),
                        "impacts_per_success": float(np.mean(imps)) if imps else math.nan,
                        "without_impact": sum(1 for k in imps if k == 0), "rise": last_decade_rise(res)})
    return out


def check_theorems(summary) -> None:
    """A success without an impact in a single-input cell, or any success on the plane, contradicts theorems T2 and
    T3: it stops the report (a bug to chase, not a result)."""
    bad = [s for s in summary if s["cell"][0] in ("Steer", "Drive") and (s["without_impact"] > 0
                                                                         or (s["cell"][1] == "plane" and s["success"] > 0))]
    if bad:
        raise RuntimeError("a single-input success without an impact, or a success on the plane: theorems T2/T3 say "
                           "none can happen; chase the bug: " + "; ".join(f"{s['agent']} on {cell_name(s['cell'])}"
                                                                         for s in bad))


def goals(cfg, summary) -> list[str]:
    """The issue's goals, checked from the table."""
    fair_steer = {}
    for s in summary:
        if not s["privileged"] and s["cell"][0] == "Steer" and s["cell"][1] != "plane" and s["share"] >= 0.5:
            fair_steer.setdefault(s["cell"][1], []).append(
                f"{s['agent']} {s['share']:.2f} of it, {s['seeds']} seeds, interval {s['share_ci'][0]:.2f} to "
                f"{min(s['share_ci'][1], 1.0):.2f}")
    single = [c for c in cfg["cells"] if c[0] in ("Steer", "Drive") and c[1] != "plane"]
    priv = {}
    for c in single:
        best = max((s["share"] for s in summary if s["cell"] == c and s["privileged"] and not math.isnan(s["share"])),
                   default=math.nan)
        priv[c] = best
    plane = [s for s in summary if s["cell"][1] == "plane"]
    lines = [f"- an agent without privileged resets reaches at least half the witnessed rate on steer-only park on at "
             f"least two tables: **{'met' if len(fair_steer) >= 2 else 'not met'}** by the pooled rate "
             f"({'; '.join(f'{t}: ' + ', '.join(sorted(set(a))) for t, a in sorted(fair_steer.items())) or 'on no table'}"
             f"; where an interval's lower end is below 0.5, the seeds do not establish it)",
             f"- the privileged agents reach at least 0.8 of the witnessed rate on every witnessed single-input cell: "
             f"**{'met' if priv and all(v >= 0.8 for v in priv.values()) else 'not met'}** (best privileged share per "
             f"cell: {', '.join(f'{cell_name(c)} {v:.2f}' for c, v in priv.items() if not math.isnan(v)) or 'none'}"
             + (f"; no privileged agent ran on {', '.join(cell_name(c) for c, v in priv.items() if math.isnan(v))}"
                if any(math.isnan(v) for v in priv.values()) else "") + ")",
             f"- every agent stays at 0 on the plane: **{'met' if all(s['success'] == 0 for s in plane) else 'NOT met'}** "
             f"({len(plane)} (agent, cell) rows)"]
    return lines


def answer_sentences(cfg, summary) -> list[str]:
    """One sentence per actuation for the README, from the table."""
    out = []
    for probe, words in (("Steer", "steer only, park"), ("Drive", "drive only, reach"), ("Both", "both controls, park")):
        rows = [s for s in summary if s["cell"][0] == probe and s["cell"][1] != "plane"]
        if not rows:
            continue
        best = {}
        for s in rows:
            key = (s["cell"], s["privileged"])
            if key not in best or s["share"] > best[key]["share"]:
                best[key] = s
        fair = [b for (c, p), b in best.items() if not p]
        priv = [b for (c, p), b in best.items() if p]

        def span(bs):
            v = [b["share"] for b in bs if not math.isnan(b["share"])]
            if not v:
                return "-"
            return f"{v[0]:.2f}" if len(v) == 1 else f"{min(v):.2f} to {max(v):.2f}"
        out.append(f"**{words}**: the best agent without privileged resets reaches {span(fair)} of the witnessed rate "
                   f"on the {len(fair)} cell(s) the ladder ran" + (f"; with privileged resets {span(priv)}" if priv else "")
                   + " (pair seeds of the witness study; [docs/ladder.md](docs/ladder.md)).")
    return out


def write_report(cfg, jobs, runs, out: Path, argv, seconds: float, quick: bool) -> Path:
    from studies.common import header
    results, stale = load_results(cfg, jobs, runs)
    summary = summarize(cfg, results)
    check_theorems(summary)
    rows = csv_rows(cfg, results)
    out.parent.mkdir(parents=True, exist_ok=True)
    with open(out.with_suffix(".csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=CSV_FIELDS)
        w.writeheader()
        w.writerows(rows)
    figures = write_figures(cfg, results, out)
    done = sum(len(res) for res in results.values())
    cpu = sum(r.get("cpu_seconds", 0.0) for res in results.values() for r in res)
    lines = header("The agent ladder: learned agents on the single-input cells beside the certified witnesses",
                   "studies.ladder", list(argv))
    lines += [f"- jobs: {done} of {len(jobs)} finished ({cpu / 3600:.1f} CPU hours in the finished jobs; this "
              f"invocation {seconds:.0f} s); seeds per (agent, cell): {_seeds_words(cfg)} (the seeds column counts "
              f"those finished)" + (f"; {len(stale)} result(s) in {runs} made by other job configs not counted "
                                     f"(they rerun)" if stale else "") + "; evaluation: one deterministic "
              f"episode per pair seed 0..{cfg['eval_seeds'] - 1} (training/protocol.evaluate), the witness study's",
              "- privileged agents (PRIVILEGED below) reset their training envs to chosen states and learn from certified "
              f"witness episodes of training seeds {DEMO_SEED}+ (never the pair seeds); the others see only what the env "
              "gives any agent", ""]
    lines += ["## Goals", "", *goals(cfg, summary), ""]
    lines += ["## Per cell", "",
              "Success at the agent's budget, pooled over its seeds, with a 95 % interval clustered by seed (honest at 0 "
              "and 1); the witnessed rate of the same pair seeds (docs/witnesses_pairs.csv); the share; impacts per "
              "successful episode (up to its success) and how many successes had none (the theorems say single-input "
              "successes need one); the rise of the mean success over the last decade of samples (flat: below 0.02).",
              ""]
    for cell in cfg["cells"]:
        srows = [s for s in summary if s["cell"] == cell]
        if not srows:
            continue
        lines += [f"### {cell_name(cell)} ({PROBE_TASKS[cell[0]]}, {cell[1]}, law {cell[2]})", "",
                  "| agent | privileged | seeds | env steps | success [95 % CI] | per seed | witnessed | share | "
                  "impacts per success | successes without impact | rise over the last decade |",
                  "|---|---|---:|---:|---|---|---:|---:|---:|---:|---:|"]
        for s in srows:
            lines.append(f"| {s['label']} | {'PRIVILEGED' if s['privileged'] else 'no'} | {s['seeds']} | "
                         f"{s['env_steps']:.3g} | {s['success']:.3f} [{s['ci'][0]:.3f}, {s['ci'][1]:.3f}] | "
                         f"{', '.join(f'{v:.2f}' for v in s['per_seed'])} | {_f(s['witnessed'])} | {_f(s['share'])} | "
                         f"{_f(s['impacts_per_success'], 1)} | {s['without_impact']} | {_rise(s['rise'])} |")
        if cell_name(cell) in figures:
            lines += ["", f"![{cell_name(cell)}]({figures[cell_name(cell)]})"]
        lines.append("")
    lines += ["CSV: one row per (agent, privileged, probe, table, law, seed, env_steps): "
              f"[{out.with_suffix('.csv').name}]({out.with_suffix('.csv').name}).", ""]
    out.write_text("\n".join(lines))
    if not quick:
        write_readme(answer_sentences(cfg, summary))
    return out


def _f(v, digits=2) -> str:
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.{digits}f}"


def _rise(v) -> str:
    if math.isnan(v):
        return "-"
    return f"{v:+.2f} ({'still rising' if v >= 0.02 else 'flat'})"


def write_figures(cfg, results, out: Path) -> dict:
    """Success against env steps (log axis) per cell, one line per agent (mean over seeds, each seed thin)."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return {}
    figs = {}
    for cell in cfg["cells"]:
        agents = [(a, results[(a, cell)]) for a in cfg["agents"] if (a, cell) in results]
        if not agents:
            continue
        fig, ax = plt.subplots(figsize=(6, 3.6))
        for k, (agent, res) in enumerate(agents):
            color = f"C{k}"
            a = cfg["agents"][agent]
            for r in res:
                ax.plot([c["env_steps"] for c in r["checkpoints"]], [c["successes"] / c["episodes"] for c in
                                                                     r["checkpoints"]], color=color, lw=0.6, alpha=0.5)
            steps, mean = curve(res)
            ax.plot(steps, mean, color=color, lw=2, ls="--" if a["privileged"] else "-",
                    label=a.get("label", agent) + (" (PRIVILEGED)" if a["privileged"] else ""))
        wit = witnessed_by_seed(cell, cfg["eval_seeds"])
        if wit is not None:
            ax.axhline(wit.mean(), color="k", lw=1, ls=":", label="witnessed rate")
        ax.set_xscale("log")
        ax.set_ylim(-0.02, 1.02)
        ax.set_xlabel("env steps")
        ax.set_ylabel("success (pair seeds)")
        ax.set_title(cell_name(cell), fontsize=9)
        ax.legend(fontsize=6, loc="upper left")
        fig.tight_layout()
        png = out.with_name(f"{out.stem}_{cell_name(cell)}.png")
        fig.savefig(png, dpi=100)
        plt.close(fig)
        figs[cell_name(cell)] = png.name
    return figs


def write_readme(sentences) -> None:
    """The README's ladder block, between its markers (written only by a run that writes docs/ladder.md)."""
    from studies.common import replace_block
    replace_block(ROOT / "README.md", README_BEGIN, README_END, "\n\n".join(sentences))


# -- the command ----------------------------------------------------------------------------------------------------
def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", default=None, help=f"ladder config (default {DEFAULT_CONFIG.relative_to(ROOT)})")
    ap.add_argument("--runs", default=None, help="job folders (default runs/ladder; --quick: a new temporary folder)")
    ap.add_argument("--out", default=None, help="report (default docs/ladder.md; --quick: RUNS/ladder.md)")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="parallel jobs (default: all cores)")
    ap.add_argument("--ray", action="store_true", help="run the jobs as Ray tasks (RAY_ADDRESS or a local instance)")
    ap.add_argument("--quick", action="store_true", help=f"{QUICK_CONFIG.relative_to(ROOT)}; never writes into docs/")
    ap.add_argument("--report-only", action="store_true", help="rewrite the report from the finished jobs")
    args = ap.parse_args(argv)
    try:
        if args.workers < 1:
            raise ValueError(f"--workers must be >= 1, got {args.workers}")
        if args.ray:
            check_ray()
        cfg = load_config(Path(args.config) if args.config else (QUICK_CONFIG if args.quick else DEFAULT_CONFIG))
        runs = Path(args.runs) if args.runs else (Path(tempfile.mkdtemp(prefix="ladder_quick_")) if args.quick
                                                  else Path("runs/ladder"))
        out = Path(args.out) if args.out else (runs / "ladder.md" if args.quick else DOCS / "ladder.md")
        if args.quick and DOCS.resolve() in out.resolve().parents:
            raise ValueError(f"--quick never writes into docs/: --out {out}")
        if out.suffix != ".md":
            raise ValueError(f"--out must name a markdown file (.md), got {out}")
    except ValueError as exc:
        ap.error(str(exc))
    jobs = make_jobs(cfg)
    t0 = time.perf_counter()
    from studies.jobs import DamagedResult
    from training.run_folder import RunFolderError, run_lock
    try:
        if not args.report_only:
            with run_lock(runs):  # (one study at a time in a runs folder: two would run the same jobs into it)
                todo = [j for j in jobs if not finished(runs, j, job_dir)]
                print(f"{len(jobs)} jobs, {len(jobs) - len(todo)} already finished in {runs}", flush=True)
                for cell in sorted({tuple(j["cell"]) for j in todo if j["privileged"]}):
                    make_demos(runs, cell, cfg["demos"]["pairs"])
                if todo:
                    run_jobs(run_job, todo, runs, args.workers, job_dir, ray=args.ray)
        path = write_report(cfg, jobs, runs, out, argv, time.perf_counter() - t0,
                            quick=args.quick or out.resolve() != (DOCS / "ladder.md").resolve())
    except (RunFolderError, DamagedResult) as exc:
        raise SystemExit(f"studies.ladder: error: {exc}") from None
    print(f"report: {path}")
    return path


if __name__ == "__main__":
    main()
