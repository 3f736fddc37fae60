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
same job config (lab/jobs.py), so an interruption costs at most the job under way (each is under an hour on
one core at the committed budgets). --ray runs the jobs as Ray tasks (RAY_ADDRESS or a local instance).
Demonstrations for the privileged agents are made first, once per cell (RUNS/demos/<cell>.npz).

The report (--out; default docs/ladder.md, with docs/ladder.csv and the figures docs/ladder_<cell>.png beside it):
per cell, every agent's success at its budget with a 95 % interval clustered by seed (honest at 0 and 1:
lab/stats.seed_clustered_ci) beside the witnessed rate of the same pair seeds (docs/witnesses_pairs.csv), the
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
from lab.jobs import check_ray, finished, result_of, run_jobs

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
DEFAULT_CONFIG = ROOT / "configs" / "ladder" / "cpu.yaml"
QUICK_CONFIG = ROOT / "configs" / "ladder" / "quick.yaml"
KEYS = {"eval_seeds", "seeds", "first_checkpoint", "cells", "agents", "demos"}
OPTIONAL_KEYS = {"fall"}  # fall: [AGENT, ...]: recipes whose learning diagnostics are shown side by side
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
    unknown, missing = sorted(set(cfg) - KEYS - OPTIONAL_KEYS), sorted(KEYS - set(cfg))
    if unknown or missing:
        raise ValueError(f"{path}: unknown key(s) {unknown}, missing key(s) {missing}; keys: {sorted(KEYS)} and "
                         f"optionally {sorted(OPTIONAL_KEYS)}")
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
        check_agent_args(module, dict(a.get("args") or {}), f"{path}: agents.{name}.args")
    fall = cfg.get("fall")
    if fall is not None and not (isinstance(fall, list) and len(fall) >= 2 and len(set(fall)) == len(fall)
                                 and all(isinstance(v, str) and v in cfg["agents"] for v in fall)):
        raise ValueError(f"{path}: fall must be a list of at least two of the config's agents, got {fall!r}")
    d = cfg["demos"]
    if not isinstance(d, dict) or set(d) != {"pairs"} or isinstance(d["pairs"], bool) or not isinstance(d["pairs"], int):
        raise ValueError(f"{path}: demos must be {{pairs: N}} (witness episodes per cell for the privileged agents)")
    return cfg


def check_agent_args(module, args: dict, where: str) -> None:
    """The agent's own checks of its Args (training/agent_cli.py's, or the agent's check_args) on the config's values,
    before any job runs; ValueError naming the place and the field."""
    from training.agent_cli import check_args
    make = getattr(module, "ladder_args", module.Args)
    probe = {"demos": "demos.npz"} if "demos" in {f.name for f in dataclasses.fields(module.Args)} else {}
    if args.get("device") == "cuda":  # (a GPU config is checked on any machine; its device when its jobs run)
        args = {**args, "device": "cpu"}
    try:
        built = make(**{**probe, **args})
        if hasattr(module, "CHECKS"):
            check_args(built, module.CHECKS)
        elif hasattr(module, "check_args"):
            module.check_args(built)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: {exc}") from None


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
    import numba
    import torch
    # one job per core: the vector env's prange would oversubscribe. The thread count in use, not NUMBA_NUM_THREADS:
    # numba refuses a changed variable once its threads run (a job run in a process that stepped a vector env before)
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
    train = dict(train or {})
    result = {"job": job, "checkpoints": rows, "train": {k: v for k, v in train.items() if _plain(v)},
              "val_curve": [list(map(float, c)) for c in train.get("val_curve", [])]}
    if train.get("final_policy") is not None:  # the last update's policy, beside the kept (best-validated) one
        r = evaluate(train["final_policy"], env_id, overrides, seeds=range(job["eval_seeds"]))
        result["final_eval"] = {"successes": r["successes"], "episodes": r["episodes"]}
    return {**result, "seconds": time.perf_counter() - t0, "cpu_seconds": time.process_time() - c0}


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
    made by the config's own jobs count (lab/jobs.result_of); a damaged result.json stops the report, named."""
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
    """One row per (cell, agent): pooled success with its seed-clustered interval, each seed's rate and their
    minimum, the witnessed rate of the same pair seeds, the shares, impacts per success, successes without an impact,
    the last decade's rise, and (agents that keep a best-validated snapshot) each seed's final policy."""
    from lab.stats import seed_clustered_ci
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
            per_seed = [float(m.mean()) for m in M]
            final = [r["final_eval"]["successes"] / r["final_eval"]["episodes"] if "final_eval" in r else math.nan
                     for r in res]
            out.append({"cell": cell, "agent": agent, "label": a.get("label", agent), "privileged": a["privileged"],
                        "seeds": len(res), "seed_ids": [r["job"]["seed"] for r in res], "env_steps": steps,
                        "success": rate, "ci": (lo, hi), "per_seed": per_seed, "witnessed": w,
                        "share": rate / w if w and w > 0 else math.nan,
                        "share_ci": (lo / w, min(hi / w, math.inf)) if w and w > 0 else (math.nan, math.nan),
                        "min_share": min(per_seed) / w if w and w > 0 else math.nan, "final": final,
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


# the goals of the agent study: (probe, tables, share of the witnessed rate), for the best agent without privileged
# information (its minimum over at least MIN_SEEDS seeds) and for the witness-guided agents (every seed)
UNPRIVILEGED_GOALS = (("Steer", ("stadium", "rounded_rectangle"), 0.9), ("Steer", ("circle", "ellipse"), 0.5),
                      ("Drive", ("ellipse", "stadium"), 0.9))
GUIDED_GOAL = 0.9
MIN_SEEDS = 5
STABLE = 0.03  # the final policy within this of the kept (best-validated) snapshot, on the pair seeds


def verdict(s, goal: float, min_seeds: int = 1) -> tuple[str, str]:
    """("met" | "not established" | "not met", the evidence) for a summary row against a share of the witnessed
    rate: met only where every seed (at least min_seeds) and the interval's lower end clear it."""
    low = s["share_ci"][0]
    shares = ", ".join(f"{v / s['witnessed']:.2f}" for v in s["per_seed"])
    words = (f"{s['agent']}: {s['share']:.2f} of the witnessed rate, {s['seeds']} seeds "
             f"({shares}; minimum {s['min_share']:.2f}), "
             f"interval {low:.2f} to {min(s['share_ci'][1], 1.0):.2f}")
    if s["seeds"] >= min_seeds and s["min_share"] >= goal and low >= goal:
        return "met", words
    if s["share"] >= goal or s["min_share"] >= goal:
        return "not established", words + (f"; fewer than {min_seeds} seeds" if s["seeds"] < min_seeds else "")
    return "not met", words


def goals(cfg, summary) -> list[str]:
    """The study's goals, checked from the table: a line each, "met" only where the seeds and the interval clear."""
    lines = []
    for probe, tables, goal in UNPRIVILEGED_GOALS:
        for table in tables:
            for cell in [c for c in cfg["cells"] if c[0] == probe and c[1] == table]:
                rows = [s for s in summary if s["cell"] == cell and not s["privileged"]]
                if not rows:
                    lines.append(f"- {cell_name(cell)}, without privileged information, the minimum over "
                                 f"{MIN_SEEDS} seeds at {goal} of the witnessed rate: **not run**")
                    continue
                best = max(rows, key=lambda s: (s["seeds"] >= MIN_SEEDS, s["min_share"], s["share"]))
                v, words = verdict(best, goal, MIN_SEEDS)
                lines.append(f"- {cell_name(cell)}, without privileged information, the minimum over {MIN_SEEDS} "
                             f"seeds at {goal} of the witnessed rate: **{v}** ({words})")
    for cell in [c for c in cfg["cells"] if c[0] in ("Steer", "Drive") and c[1] != "plane"]:
        rows = [s for s in summary if s["cell"] == cell and s["privileged"]]
        if not rows:
            lines.append(f"- {cell_name(cell)}, witness-guided (PRIVILEGED) on every seed at {GUIDED_GOAL}: "
                         "**not run**")
            continue
        best = max(rows, key=lambda s: (s["min_share"], s["share"]))
        v, words = verdict(best, GUIDED_GOAL)
        lines.append(f"- {cell_name(cell)}, witness-guided (PRIVILEGED) on every seed at {GUIDED_GOAL}: **{v}** "
                     f"({words})")
    plane = [s for s in summary if s["cell"][1] == "plane"]
    plane_verdict = "not run" if not plane else "met" if all(s["success"] == 0 for s in plane) else "NOT met"
    lines.append(f"- every agent stays at 0 on the plane: **{plane_verdict}**"
                 f" ({len(plane)} (agent, cell) rows, {sum(s['seeds'] for s in plane)} seeds)")
    kept = [(s, f, k) for s in summary for f, k in zip(s["final"], s["per_seed"]) if not math.isnan(f)]
    if kept:
        worst = max(kept, key=lambda x: x[2] - x[1])
        ok = all(k - f <= STABLE for _, f, k in kept)
        lines.append(f"- the final policy of every seed within {STABLE} of its kept best-validated snapshot (pair "
                     f"seeds): **{'met' if ok else 'not met'}** ({len(kept)} seeds; the largest drop "
                     f"{worst[2] - worst[1]:+.3f}, {worst[0]['agent']} on {cell_name(worst[0]['cell'])})")
    return lines


def answer_sentences(cfg, summary, link: str = " ([docs/ladder.md](docs/ladder.md))") -> list[str]:
    """The answer to "do baseline agents learn to use impacts?", one sentence per actuation, from the table.

    `link` ends each sentence: the README's block points at the report; the report itself passes "".
    """
    out = []
    for probe, words in (("Steer", "steer only, park"), ("Drive", "drive only, reach"), ("Both", "both controls, park")):
        rows = [s for s in summary if s["cell"][0] == probe and s["cell"][1] != "plane" and not math.isnan(s["share"])]
        if not rows:
            if any(c[0] == probe and c[1] != "plane" for c in cfg["cells"]):
                out.append(f"**{words}**: no job of this actuation has finished yet; the ladder's jobs wait{link}.")
            continue

        def best_per_cell(privileged):
            best = {}
            for s in rows:
                if s["privileged"] == privileged and (s["cell"] not in best or s["share"] > best[s["cell"]]["share"]):
                    best[s["cell"]] = s
            return list(best.values())

        def span(bs):
            if not bs:
                return None
            lo, hi = min(b["share"] for b in bs), max(b["share"] for b in bs)
            mins = min(b["min_share"] for b in bs)
            return (f"{lo:.2f}" if len(bs) == 1 else f"{lo:.2f} to {hi:.2f}") + \
                f" of the witnessed rate on {len(bs)} cell(s) (the lowest seed {mins:.2f})"
        fair, guided = span(best_per_cell(False)), span(best_per_cell(True))
        impacts = sum(1 for s in rows if s["without_impact"] == 0)
        text = f"**{words}**: " + (f"agents without privileged information reach {fair}" if fair else
                                   "no agent without privileged information ran")
        if guided:
            text += f"; with the witness guiding their training (PRIVILEGED), {guided}"
        if probe != "Both":
            text += f"; every success had an impact ({impacts} of {len(rows)} rows checked)"
        out.append(f"{text}{link}.")
    return out


FALL_COLUMNS = (("val_success", "validation success"), ("train_success", "training success"), ("std", "noise std"),
                ("lr", "learning rate"), ("approx_kl", "approximate KL"), ("clip_frac", "clip fraction"),
                ("explained_variance", "explained variance"), ("grad_norm", "gradient norm"))


FALL_TEXT = ("Recipes of PPO with the heading head on the same cells and seeds (the config's key fall), every "
             "update's diagnostics logged (training/ppo_heading.py's progress.csv). ppo_heading_annealed, the first "
             "recipe: the learning rate annealed linearly to 0 over the budget, the heading noise free to shrink to "
             "0.05 rad, an update stopped at a KL of 0.02; ppo_heading_floor: the first recipe with the noise kept "
             "above 0.15 rad; ppo_heading, the ladder's: the learning rate adapted to the measured KL (RSL-RL's rule, "
             "desired KL 0.01), the noise above 0.15 rad, LayerNorm, Adam with beta1 = beta2; ppo_heading_explore: the "
             "ladder's recipe with the noise floor held at 0.5 rad until the first parks. Per seed: the first parks, "
             "the validation peak, the lowest and the final validation after it, and the learning rate, noise std and "
             "gradient norm at the peak and at the end. Rows marked 'kept run' are single runs kept in docs/ladder_fall/ "
             "(runs.csv: their commit, date and command), shown beside the ladder's own jobs of the same "
             "recipes.")


FALL_ARCHIVE = DOCS / "ladder_fall" / "runs.csv"


FALL_READING = (
    "**What caused the fall, and what holds it** (the rows and the figure below; one seed of the first recipe so far). In the "
    "first recipe's run the validation success peaked and then fell to 0 while the approximate KL stayed small and "
    "the explained variance high: neither the trust region nor the critic broke first. What moved first was the "
    "noise: the heading noise std shrank through learning toward its floor of 0.05 rad, and the gradient norm, "
    "which grows like 1/std for a Gaussian policy's log-likelihood, rose past the clip at 0.5 before the peak and "
    "kept rising after it, while the annealed learning rate shrank: the updates followed the noisiest part of the "
    "gradient with ever less exploration, and the training success fell with the validation's (shrinking "
    "exploration, as PPO-CMA describes). The ladder's recipe keeps the noise above 0.15 rad (its gradient norm "
    "stops growing once the noise is at the floor) and adapts the learning rate to the measured KL instead of "
    "annealing it; it adds LayerNorm and Adam with beta1 = beta2. On the same seed it rose without a fall to the "
    "end of its run. The noise floor alone (ppo_heading_floor) and more seeds of each recipe are the config's jobs "
    "that separate the parts of the cure; until they have run this reading rests on one seed of the first recipe. "
    "The ladder's recipe removes the fall, not the spread between seeds: a seed that starts late is still low at "
    "its budget (the per-seed rates above).\n\n"
    "**Why the seeds differ at the budget, and what closes the spread** (the column 'first parks'). The spread is "
    "not a fall: it is when a seed first parks. The ladder's recipe lets its noise shrink to the floor of 0.15 rad "
    "within its first few tens of millions of env steps; the seeds that parked while the noise was still wide "
    "learned to 0.9 and above, and the seeds that had not parked by then found their first parks only much later, "
    "at the floor, and were still low at the budget. ppo_heading_explore holds the noise floor at the starting "
    "0.5 rad until the training success is above 0 and lowers it to 0.15 rad as the success rises to 0.1 "
    "(training/ppo_heading.py, noise_floor; it never widens again): compare its seeds' first parks and final "
    "rates with the ladder recipe's on the same seeds.")


def progress_of(runs, job) -> dict | None:
    """The job's per-update diagnostics (the agent's progress.csv) as {column: array}, or None."""
    return read_progress(job_dir(runs, job) / "progress.csv")


def archived_fall_runs(cell, path=None) -> dict:
    """{label: [(seed, diagnostics)]} of runs kept in docs/ladder_fall/ (their progress.csv, commit, date and command
    in runs.csv) on ``cell``: the recipes' curves before the ladder's own jobs of them have run."""
    out, path = {}, Path(path or FALL_ARCHIVE)
    if not path.is_file():
        return out
    with open(path) as f:
        for r in csv.DictReader(f):
            if r["cell"] != cell_name(cell):
                continue
            p = read_progress(path.parent / r["file"])
            if p is None:
                raise ValueError(f"{path}: {r['file']} has no rows")
            out.setdefault(f"{r['recipe']} (kept run, {r['commit']})", []).append((int(r["seed"]), p))
    return out


def read_progress(path: Path) -> dict | None:
    """A progress.csv as {column: array}, or None where there is none."""
    if not path.is_file():
        return None
    with open(path) as f:
        rows = list(csv.DictReader(f))
    if not rows:
        return None

    def num(v):
        try:
            return float(v)
        except (TypeError, ValueError):
            return math.nan
    return {c: np.array([num(r.get(c)) for r in rows]) for c in rows[0]}


def fall_section(cfg, jobs, runs, results, out: Path) -> list[str]:
    """The learning diagnostics of recipes side by side (config key fall: a list of agents), on the cells where at
    least two of them ran: per seed, the validation peak, what followed it, and the diagnostics at the peak and at
    the end; a figure of every diagnostic against env steps."""
    fall = cfg.get("fall")
    if not fall:
        return []
    lines = []
    for cell in cfg["cells"]:
        runs_of = archived_fall_runs(cell)
        for agent in fall:
            for job in jobs:
                if job["agent"] == agent and tuple(job["cell"]) == cell and result_of(runs, job, job_dir):
                    p = progress_of(runs, job)
                    if p is not None:
                        runs_of.setdefault(agent, []).append((job["seed"], p))
        if len(runs_of) < 2:
            continue
        lines += [f"### {cell_name(cell)}: {', '.join(runs_of)}", "",
                  "| recipe | seed | first parks (env steps; noise std then) | validation peak (env steps) | after the "
                  "peak: lowest, final | drop after the peak | learning rate at the peak, end | noise std at the peak, "
                  "end | gradient norm at the peak, end |",
                  "|---|---:|---|---|---|---:|---|---|---|"]
        for agent, seeds in runs_of.items():
            for seed, p in seeds:
                v = p["val_success"]
                ok = np.flatnonzero(np.isfinite(v))
                if not len(ok):
                    continue
                i = ok[np.argmax(v[ok])]
                later = ok[ok >= i]
                low, last = float(np.min(v[later])), float(v[ok[-1]])

                def at(col, j):
                    return p[col][j] if col in p else math.nan
                lines.append(f"| {agent} | {seed} | {first_parks(p)} | {v[i]:.2f} ({p['global_step'][i]:.3g}) | "
                             f"{low:.2f}, {last:.2f} "
                             f"| {v[i] - low:+.2f} | {at('lr', i):.1e}, {at('lr', -1):.1e} | {at('std', i):.3f}, "
                             f"{at('std', -1):.3f} | {at('grad_norm', i):.2f}, {at('grad_norm', -1):.2f} |")
        png = write_fall_figure(cell, runs_of, out)
        if png:
            lines += ["", f"![the diagnostics of {cell_name(cell)}]({png})"]
        lines.append("")
    return lines


FIRST_PARKS = 0.01  # validation success that counts as parking


def first_parks(p) -> str:
    """From which validation a run's validation success stayed at or above FIRST_PARKS to its end (an early lucky
    park is not the start of learning; the training success restarts its window at a resume), and its noise std
    then ("-": never)."""
    v = p.get("val_success", np.array([]))
    rows = np.flatnonzero(np.isfinite(v))
    below = rows[v[rows] < FIRST_PARKS]
    later = rows[rows > below[-1]] if len(below) else rows
    if not len(later):
        return "-"
    j = later[0]
    return f"{p['global_step'][j]:.3g} ({p['std'][j]:.3f})" if "std" in p else f"{p['global_step'][j]:.3g}"


def write_fall_figure(cell, runs_of, out: Path) -> str | None:
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    fig, axes = plt.subplots(2, 4, figsize=(13, 5.5), sharex=True)
    for ax, (col, title) in zip(axes.ravel(), FALL_COLUMNS):
        for r, (agent, seeds) in enumerate(runs_of.items()):
            for k, (seed, p) in enumerate(seeds):
                if col not in p:
                    continue
                x, y = p["global_step"], p[col]
                ok = np.isfinite(y)
                ax.plot(x[ok], y[ok], color=f"C{r}", lw=0.8, alpha=0.8, marker="." if col == "val_success" else None,
                        ms=3, label=agent if k == 0 else None)
        ax.set_title(title, fontsize=9)
        if col in ("lr", "approx_kl", "grad_norm"):
            ax.set_yscale("log")
    axes[0, 0].legend(fontsize=7)
    for ax in axes[1]:
        ax.set_xlabel("env steps")
    fig.suptitle(f"{cell_name(cell)}: every update's diagnostics, each seed a line", fontsize=10)
    fig.tight_layout()
    png = out.with_name(f"{out.stem}_fall_{cell_name(cell)}.png")
    fig.savefig(png, dpi=90)
    plt.close(fig)
    return png.name


def archive_rows(cells, path=DOCS / "ladder_archive.csv") -> dict:
    """{cell: [rows]} of earlier studies' agents, kept with their date and commit (not rerun): docs/ladder_archive.csv."""
    if not Path(path).is_file():
        return {}
    out = {}
    with open(path) as f:
        for r in csv.DictReader(f):
            cell = (r["probe"], r["table"], r["law"] if r["table"] != "plane" else "-")
            if cell in cells:
                out.setdefault(cell, []).append(r)
    return out


def write_report(cfg, jobs, runs, out: Path, argv, seconds: float, quick: bool) -> Path:
    from lab.common import header
    results, stale = load_results(cfg, jobs, runs)
    summary = summarize(cfg, results)
    archived = archive_rows(cfg["cells"])
    check_theorems(summary)
    rows = csv_rows(cfg, results)
    out.parent.mkdir(parents=True, exist_ok=True)
    with open(out.with_suffix(".csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=CSV_FIELDS)
        w.writeheader()
        w.writerows(rows)
    figures = write_figures(cfg, results, out)
    done = sum(len(res) for res in results.values())
    # a job's training time over all its resumed parts (the agent's own count; one core per job), else this part's CPU
    cpu = sum((r.get("train") or {}).get("wall_time_s") or r.get("cpu_seconds", 0.0)
              for res in results.values() for r in res)
    lines = header("The agent study: do baseline agents learn to use impacts? Learning agents on the single-input "
                   "cells beside the certified witnesses",
                   "studies.ladder", list(argv))
    lines += [f"- jobs: {done} of {len(jobs)} finished ({cpu / 3600:.1f} hours of training in the finished jobs, "
              f"one core each; this invocation {seconds:.0f} s); seeds per (agent, cell): {_seeds_words(cfg)} (the "
              f"seeds column counts those finished)"
              + (f"; {len(stale)} result(s) in {runs} made by other job configs not counted "
                                     f"(they rerun)" if stale else "") + "; evaluation: one deterministic "
              f"episode per pair seed 0..{cfg['eval_seeds'] - 1} (training/protocol.evaluate), the witness study's",
              "- privileged agents (PRIVILEGED below) are guided in training by certified witness episodes of training "
              f"seeds {DEMO_SEED}+ (never the pair seeds; resets of their training envs to the witnesses' starts); the "
              "policy evaluated sees only the env's observation; the others see only what the env gives any agent",
              ""]
    lines += ["## The answer", "", "Do baseline agents learn to use impacts? Per actuation (the README's block):", "",
              *answer_sentences(cfg, summary, link=""), ""]
    lines += ["## Goals", "", *goals(cfg, summary), ""]
    lines += ["## Per cell", "",
              "Success at the agent's budget (the policy it hands out: with early stopping, its best-validated "
              "snapshot), pooled over its seeds, with a 95 % interval clustered by seed (honest at 0 and 1), each seed's "
              "rate and the lowest seed's share of the witnessed rate; the final policy per seed (the last update's, "
              "without early stopping; '-' where the agent keeps none); the witnessed rate of the same pair seeds "
              "(docs/witnesses_pairs.csv); the share with its interval; impacts per successful episode (up to its "
              "success) and how many successes had none (the theorems say single-input successes need one); the rise "
              "of the mean success over the last decade of samples (flat: below 0.02). Rows marked 'not rerun' are "
              "earlier studies' agents at their date and commit (docs/ladder_archive.csv).", ""]
    for cell in cfg["cells"]:
        srows = [s for s in summary if s["cell"] == cell]
        if not srows:
            continue
        lines += [f"### {cell_name(cell)} ({PROBE_TASKS[cell[0]]}, {cell[1]}, law {cell[2]})", "",
                  "| agent | privileged | seeds | env steps | success [95 % CI] | per seed | lowest seed's share | "
                  "final policy per seed | witnessed | share [95 % CI] | impacts per success | successes without "
                  "impact | rise over the last decade |",
                  "|---|---|---:|---:|---|---|---:|---|---:|---|---:|---:|---:|"]
        for s in srows:
            final = ", ".join("-" if math.isnan(v) else f"{v:.2f}" for v in s["final"])
            lines.append(f"| {s['label']} | {'PRIVILEGED' if s['privileged'] else 'no'} | {s['seeds']} | "
                         f"{s['env_steps']:.3g} | {s['success']:.3f} [{s['ci'][0]:.3f}, {s['ci'][1]:.3f}] | "
                         f"{', '.join(f'{v:.2f}' for v in s['per_seed'])} | {_f(s['min_share'])} | {final} | "
                         f"{_f(s['witnessed'])} | {_f(s['share'])} [{_f(s['share_ci'][0])}, "
                         f"{_f(min(s['share_ci'][1], 1.0))}] | {_f(s['impacts_per_success'], 1)} | "
                         f"{s['without_impact']} | {_rise(s['rise'])} |")
        for r in archived.get(cell, []):
            n, k = int(r["episodes"]), int(r["successes"])
            lines.append(f"| {r['label']} ({r['source']}, {r['date']}, {r['commit']}; not rerun) | "
                         f"{'PRIVILEGED' if r['privileged'] in ('True', 'true', '1') else 'no'} | {r['seeds']} | - | "
                         f"{k / n:.3f} ({k}/{n}) | - | - | - | {r['witnessed_rate'] or '-'} | - | - | - | - |")
        if cell_name(cell) in figures:
            lines += ["", f"![{cell_name(cell)}]({figures[cell_name(cell)]})"]
        lines.append("")
    fall = fall_section(cfg, jobs, runs, results, out)
    if fall:
        lines += ["## What made PPO fall, and what holds it", "", FALL_TEXT, "", FALL_READING, "", *fall]
    lines += ["CSV: one row per (agent, privileged, probe, table, law, seed, env_steps): "
              f"[{out.with_suffix('.csv').name}]({out.with_suffix('.csv').name}).", ""]
    out.write_text("\n".join(lines))
    if not quick:
        status = (f"So far {done} of the grid's {len(jobs)} jobs have finished ({cpu / 3600:.1f} core-hours of training); the "
                  "rest wait, resumable job by job, and each answer below holds for the jobs finished.")
        write_readme([status, *answer_sentences(cfg, summary)])
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
    from lab.common import replace_block
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
    from lab.jobs import DamagedResult
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
