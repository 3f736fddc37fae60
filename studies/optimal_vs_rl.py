"""The optimal controls of studies/optimal_control.py against the RL agents of studies/study.py, on the
same start/target pairs.

The study's both-controls park probes on the elastic ellipse and stadium (PennyProbeBoth-*-Elastic-v0)
run on the same table, law, torques and control period as the optimal-control park problems of those
scenes (checked field by field, not assumed). Each trained agent of the study (every PPO and SAC seed
found under the study's job folder) and the feedback controller run one episode from each optimal-control
pair (reset options set the start state and the target), judged by the optimal-control terminal set: the
probes also ask |phi_dot| < spin_tolerance, so that check is switched off here (spin_tolerance=None).
Times are to the first success, in control rows x control_dt, like the minimum times.
"""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

CELLS = {"ellipse": "PennyProbeBoth-Ellipse-Elastic-v0", "stadium": "PennyProbeBoth-Stadium-Elastic-v0"}
AGENTS = ("ppo", "sac")
SCENE_FIELDS = ("table", "law", "actuation", "torque_limits", "control_dt", "params")
TASK_FIELDS = ("kind", "tolerance", "speed_tolerance")


def mismatch(scene: str, cell: str) -> str:
    """'' if the optimal-control park problem of `scene` and the probe `cell` pose the same problem (up to the
    spin check and the start distribution, which the pairs replace), else the first field that differs."""
    from penny_env.envs.scene import env_presets, resolve

    oc_sc, oc_tk = resolve(scene, "park")
    cell_sc, cell_tk = resolve(**env_presets()[cell])
    for name in SCENE_FIELDS:
        a, b = getattr(oc_sc, name, None), getattr(cell_sc, name, None)
        if dataclasses.is_dataclass(a):
            a, b = dataclasses.asdict(a), dataclasses.asdict(b)
        if a != b:
            return f"scene field {name}: {a!r} here, {b!r} in {cell}"
    for name in TASK_FIELDS:
        if getattr(oc_tk, name, None) != getattr(cell_tk, name, None):  # (speed_tolerance: a park task's field)
            return f"task field {name}: {getattr(oc_tk, name, None)!r} here, {getattr(cell_tk, name, None)!r} in {cell}"
    return ""


def park_pairs(rows, scene):
    """The minimum-time park rows of a scene (both controls), in pair order."""
    sel = [r for r in rows if r["scene"] == scene and r["task"] == "park" and r["objective"] == "time"
           and r.get("actuation", "both") == "both" and "start" in r]
    return sorted(sel, key=lambda r: r["pair"])


def agent_runs(study_runs: Path, cell: str):
    """(agent, run folders with a saved model) of the study's trained agents on a cell."""
    for agent in AGENTS:
        dirs = sorted(d for d in (Path(study_runs) / cell / agent).glob("seed*") if (d / "model.zip").is_file())
        if dirs:
            yield agent, dirs


def episodes_on_pairs(cell, policy, sel):
    from training.episodes import run_episodes

    starts = np.stack([r["start"] for r in sel])
    targets = np.stack([r["target"] for r in sel])
    return run_episodes(cell, policy, len(sel), seed=0, options={"state": starts, "target": targets},
                        spin_tolerance=None)


def compare(rows, study_runs) -> tuple[list[dict], list[str]]:
    """Per (scene, agent): the agents on the optimal-control pairs. Returns (rows, notes on what was not run)."""
    from training.episodes import make_vector_env
    from training.policies import reference_policy
    from training.runner import load_run

    out, notes = [], []
    for scene, cell in CELLS.items():
        sel = park_pairs(rows, scene)
        if not sel:
            continue
        why = mismatch(scene, cell)
        if why:
            notes.append(f"{scene}: not compared, {cell} is another problem ({why})")
            continue
        runs = list(agent_runs(study_runs, cell))
        if not runs:
            notes.append(f"{scene}: no trained agents of {cell} under {study_runs} (run python -m studies.study)")
        results = []
        for agent, dirs in runs:
            eps = []
            for d in dirs:
                _, model = load_run(d)
                eps.append(episodes_on_pairs(cell, lambda o, m=model: m.predict(o, deterministic=True)[0], sel))
            results.append((agent, eps))
        venv = make_vector_env(cell, 1)
        feedback = reference_policy("feedback", venv._core, 0)
        venv.close()
        results.append(("feedback", [episodes_on_pairs(cell, feedback, sel)]))
        for agent, eps in results:
            out.append(summarise_agent(scene, cell, agent, sel, eps))
    return out, notes


def summarise_agent(scene, cell, agent, sel, eps) -> dict:
    """Success, time to success and impacts of an agent's episodes (one list per seed) on the pairs `sel`,
    against the minimum times with and without impacts on the same pairs."""
    with_t = np.array([r["with"].rows * r["with"].dt if r["with"].ok else math.nan for r in sel])
    without_t = np.array([r["without"].rows * r["without"].dt if r["without"].ok else math.nan for r in sel])
    succ = np.array([e["success"] for e in eps], bool)           # (seeds, pairs)
    time_ = np.array([e["time"] for e in eps], float)
    imp = np.array([e["impacts"] for e in eps], int)
    both = succ & np.isfinite(with_t)[None, :]
    ratio = time_[both] / np.broadcast_to(with_t, succ.shape)[both]
    solved = succ & (np.isfinite(with_t) & np.isfinite(without_t))[None, :]  # the optimal times' common episodes
    return {"scene": scene, "cell": cell, "agent": agent, "seeds": len(eps), "pairs": len(sel),
            "episodes": int(succ.size), "success": float(succ.mean()),
            "rl_time": float(time_[succ].mean()) if succ.any() else math.nan,
            "oc_with": float(np.broadcast_to(with_t, succ.shape)[solved].mean()) if solved.any() else math.nan,
            "oc_without": float(np.broadcast_to(without_t, succ.shape)[solved].mean()) if solved.any() else math.nan,
            "ratio_median": float(np.median(ratio)) if ratio.size else math.nan,
            "rl_faster": int((ratio < 1.0 - 1e-9).sum()), "compared": int(ratio.size),
            "impact_share": float((imp[succ] > 0).mean()) if succ.any() else math.nan}


def markdown(results, notes, study_runs) -> list[str]:
    def f(v, spec=".2f"):
        return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, spec)

    lines = ["## Against the RL agents of the study, on the same pairs", "",
             "Every minimum-time park pair of the elastic ellipse and stadium above, run by the study's trained "
             f"agents (every PPO and SAC seed under `{study_runs}`: "
             f"{', '.join(CELLS.values())}, deterministic policies) and by the feedback controller, "
             "one episode per pair (`studies/optimal_vs_rl.py`; the probes' extra spin check is switched off so "
             "that success is the same terminal set as here). Times are to the first success; the optimal times "
             "are averaged over the agent's successful episodes on pairs that both optimal solves converged on; the "
             "ratio is per successful episode against the optimum with impacts allowed.", "",
             "| scene | agent | seeds | episodes | success | mean time to success [s] | optimal time, impacts "
             "allowed [s] | optimal time, impacts forbidden [s] | agent / optimal time (median) | agent faster "
             "than the optimum | agent successes with impacts |",
             "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in results:
        lines.append(f"| {r['scene']} | {r['agent']} | {r['seeds']} | {r['episodes']} | {f(r['success'])} | "
                     f"{f(r['rl_time'])} | {f(r['oc_with'])} | {f(r['oc_without'])} | {f(r['ratio_median'])} | "
                     f"{r['rl_faster']}/{r['compared']} | {f(r['impact_share'])} |")
    if not results:
        lines.append("| - | - | - | - | - | - | - | - | - | - | - |")
        if not notes:
            notes = ["no minimum-time park pairs of the elastic ellipse or stadium in this run"]
    lines += [""] + [f"* {n}" for n in notes]
    lines += ["", "An agent faster than the optimum shows where the local solver (SLSQP from a few starts) missed "
              "the global minimum time; the optimal times are upper bounds on the true ones."]
    return lines
