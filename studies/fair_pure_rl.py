"""A fair chance for pure RL on the single-input probes: SB3 PPO and SAC retrained with a
long discount, a wall-neutral reward and stated budgets, and SAC with the certified witnesses' transitions
in its replay buffer, evaluated on the witness study's pair seeds beside the witness.

    python -m studies.fair_pure_rl [--quick] [--out docs/fair_pure_rl.md] [--cells Steer:ellipse:elastic ...]
                                    [--agents ppo sac sac_witness] [--seeds 2] [--report-only]

Cells (probe, table, law; env id and field overrides from training/witness_study.cell_spec): steer-only park
on the ellipse, the stadium and the rounded rectangle (elastic walls) and drive-only reach on the ellipse under
the three laws (elastic, plastic, restitution 0.5), the cells of docs/fair_rl.md and
docs/fair_rl_extra/rounded_rectangle/fair_rl.md.

Agents (``AGENTS``):

* **ppo**: SB3 PPO, MLP 64 x 64, 16 envs x 256 steps per rollout, gamma ``GAMMA`` = 0.999, gae_lambda 0.98.
* **sac**: SB3 SAC, MLP 64 x 64, 16 envs, 2 gradient steps per vector step, gamma 0.999, automatic entropy.
* **sac_witness**: the same SAC whose replay buffer holds, before the first gradient step, every transition
  of the certified witness episodes on ``demos`` training seeds (DEMO_SEED + i): the witness of
  studies/witness.py is searched and certified on each seed in the probe's own env, and its actions are
  replayed in the training env (same dynamics bitwise, the fair reward below) to record (obs, action,
  reward, next obs, done). The buffer is sized to hold them and every own transition of the budget, so they
  stay for the whole run (nothing is overwritten); they are sampled uniformly with the agent's own.

Fairness (what the issue asks, and how it is met):

* **Discount and horizon.** gamma 0.999 (effective horizon 1 / (1 - gamma) = 1000 steps = 50 s) for PPO and
  SAC, gae_lambda 0.98 for PPO: the success bonus of a 15 to 20 s solution (300 to 400 steps) is discounted
  by 0.999^400 = 0.67, not by 0.99^400 = 0.018 as in the old study (docs/study.md). The episodes are the
  probe's own (steer park 400 steps = 20 s, drive reach 200 steps = 10 s), the time limit the witnesses are
  certified within; truncation at the limit is a time-out (SB3 bootstraps through it), not a terminal state.
* **Reward.** ``REWARD``: the success bonus only (10 on the step that succeeds, which ends the episode);
  progress weight 0, speed cost 0, control cost 0. The packaged reward's progress term (d_prev - d) / L pays
  for every step towards the target and charges every step away, so the witnesses' strategy (roll into the
  wall first, then use the impact) is punished on its way out; the speed cost near the target and the
  control cost punish the spinning and steering the single-input strategies need. A sparse bonus is neutral
  about the route: any successful episode of equal length earns the same return. Success, in training
  curves and evaluation, stays ``info["is_success"]`` of the probe's own env (unchanged termination).
* **Budgets until the curves flatten, or a stated cap.** ``FULL``: PPO and SAC env steps per (cell, agent,
  seed), sized so the whole run fits about 70 minutes of one core; every curve (validation success of the
  deterministic policy on ``val_episodes`` validation seeds, VAL_SEED + i, at ``curve_points`` points) is
  reported with its rise over the last quarter of the budget (training/study_report.last_quarter_change):
  under FLAT = 0.05 (or ending above 0.95) it counts as flattened, else the cap is what stopped it.
* **Witnesses used.** sac_witness (witness transitions in SAC's replay buffer). Behaviour cloning, DAgger and
  an option agent that learns which witness controller to run are docs/fair_rl.md's (studies/fair_rl.py);
  the report compares with their numbers, read from those reports' CSVs.

Evaluation: each final model runs ``eval_episodes`` episodes (deterministic actions) of the probe's own env,
reset with seeds 0 .. E-1, the witness study's pair seeds (a PennyVectorEnv whose sub-env i is seeded i:
the same starts and targets as ``gymnasium.make(id, **overrides).reset(seed=i)``, checked by
tests/studies/test_fair_pure_rl.py). The witness (studies/witness.py) is certified on the same seeds in this run; an
agent's ratio is its success rate (pooled over seeds) over the witnessed rate, and the goal of issue 20 item 4
is a ratio of at least 0.5. Intervals: per seed exact Clopper-Pearson; over seeds clustered by seed
(studies/stats.seed_clustered_ci: t over the seed means, widened to the pooled exact interval).
Seeds: the model and training envs of seed k use TRAIN_SEED + 10000 k (+ sub-env index), disjoint from the
evaluation, validation and demonstration seeds.

--quick: two small cells, one seed, a few thousand steps, into a temporary folder (never docs/), < 90 s.
--report-only: rewrite the report from the CSVs and the run's JSON beside it (no training).
"""
from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from pathlib import Path

import numpy as np

from studies.fair_rl import parse_cell, write_csv
from studies.stats import clopper_pearson, seed_clustered_ci
from studies.study_report import FLAT, last_quarter_change
from studies.witness import Witness, positive_int
from studies.cells import PROBE_TASKS, TABLE_NAMES, cell_spec

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
TRAIN_SEED = 300_000  # training envs of seed k: TRAIN_SEED + 10_000 k + sub-env index
DEMO_SEED = 100_000  # witness demonstrations (sac_witness): seeds DEMO_SEED + i (docs/fair_rl.md's training seeds)
VAL_SEED = 50_000  # the curves' validation episodes (as studies/fair_rl.py)
GAMMA = 0.999
REWARD = {"progress_weight": 0.0, "speed_cost": 0.0, "ctrl_cost": 0.0, "success_bonus": 10.0}


def reward_fields(env_id: str, overrides=None) -> dict:
    """REWARD's fields that the env's task has (speed_cost is park's; a reach probe has none to zero)."""
    from penny_env.envs.scene import env_presets
    from penny_env.step.tasks import config_fields
    spec = {**env_presets()[env_id], **(overrides or {})}
    from penny_env.envs.scene import preset_dict
    kind = spec.get("kind", preset_dict("task", spec["task"]).get("kind", "reach"))
    fields = config_fields(kind)
    return {k: v for k, v in REWARD.items() if k in fields}
AGENTS = ("ppo", "sac", "sac_witness")
DEFAULT_CELLS = (("Steer", "ellipse", "elastic"), ("Steer", "stadium", "elastic"),
                 ("Steer", "rounded_rectangle", "elastic"),
                 ("Drive", "ellipse", "elastic"), ("Drive", "ellipse", "plastic"), ("Drive", "ellipse", "0.5"))
QUICK_CELLS = (("Steer", "stadium", "elastic"), ("Drive", "ellipse", "elastic"))
FULL = {"ppo_steps": {"Steer": 2_000_000, "Drive": 2_000_000}, "sac_steps": {"Steer": 150_000, "Drive": 150_000},
        "num_envs": 16, "learning_starts": 1000, "demos": 100, "val_episodes": 100, "curve_points": 10,
        "eval_episodes": 200, "seeds": 2}
QUICK = {"ppo_steps": {"Steer": 4096, "Drive": 4096}, "sac_steps": {"Steer": 600, "Drive": 600}, "num_envs": 4,
         "learning_starts": 200, "demos": 2, "val_episodes": 4, "curve_points": 2, "eval_episodes": 3, "seeds": 1}
PPO_HYPER = {"n_steps": 256, "batch_size": 512, "n_epochs": 5, "learning_rate": 3e-4, "gamma": GAMMA,
             "gae_lambda": 0.98, "policy_kwargs": {"net_arch": [64, 64]}}
SAC_HYPER = {"learning_rate": 1e-3, "batch_size": 256, "train_freq": 1, "gradient_steps": 2, "gamma": GAMMA,
             "policy_kwargs": {"net_arch": [64, 64]}}
FIELDS = ["probe", "table", "law", "env_id", "overrides", "agent", "seeds", "episodes", "success", "rate",
          "ci_low", "ci_high", "seed_successes", "witnessed", "witness_rate", "ratio", "ratio_high", "goal_met",
          "env_steps", "demo_transitions", "train_s"]
CURVE_FIELDS = ["probe", "table", "law", "agent", "seed", "point", "timesteps", "val_success", "seconds"]
AGENT_TEXT = {"ppo": "PPO (pure RL)", "sac": "SAC (pure RL)", "sac_witness": "SAC + witness transitions"}


# -- one run --------------------------------------------------------------------------------------------
def budget(agent, probe, cfg):
    return int(cfg["ppo_steps" if agent == "ppo" else "sac_steps"][probe])


def success_of(venv, policy, seed):
    """Per-episode success (info["is_success"]) of a deterministic policy on a PennyVectorEnv whose sub-env
    i is reset with seed + i (one episode each)."""
    obs, _ = venv.reset(seed=seed)
    alive = np.ones(venv.num_envs, bool)
    success = np.zeros(venv.num_envs, bool)
    while alive.any():
        obs, _, term, trunc, info = venv.step(policy(obs))
        ended = alive & (term | trunc)
        success[ended] = np.asarray(info["is_success"])[ended]
        alive &= ~ended
    return success


def witness_transitions(env_id, overrides, seeds):
    """The certified witness episodes on `seeds` as transitions of the training env (the fair reward):
    dict of arrays obs, next_obs, action, reward, done, timeout; and the number of certified episodes."""
    import gymnasium as gym
    w = Witness(env_id, overrides)
    env = gym.make(env_id, **overrides, **reward_fields(env_id, overrides))
    out = {k: [] for k in ("obs", "next_obs", "action", "reward", "done", "timeout")}
    n_ok = 0
    try:
        for s in seeds:
            r = w.pair(s)
            if not r.witnessed:
                continue
            o, _ = env.reset(seed=s)
            rec = {k: [] for k in out}
            ok = False
            for a in r.actions:
                o2, rew, term, trunc, info = env.step(a)
                for k, v in zip(out, (o, o2, np.asarray(a, np.float32), rew, term or trunc, trunc and not term)):
                    rec[k].append(v)
                o = o2
                if term or trunc:
                    ok = bool(info["is_success"])
                    break
            if ok:  # replayed in the training env, the episode succeeds as certified (same dynamics)
                n_ok += 1
                for k in out:
                    out[k] += rec[k]
    finally:
        w.close()
        env.close()
    arr = {"obs": np.asarray(out["obs"], np.float32), "next_obs": np.asarray(out["next_obs"], np.float32),
           "action": np.asarray(out["action"], np.float32).reshape(len(out["obs"]), -1),
           "reward": np.asarray(out["reward"], np.float32), "done": np.asarray(out["done"], np.float32),
           "timeout": np.asarray(out["timeout"], bool)}
    return arr, n_ok


def add_to_buffer(buffer, demo, n_envs):
    """Add the transitions to an SB3 ReplayBuffer n_envs at a time (the last group padded by repeating the
    first transitions)."""
    n = len(demo["obs"])
    if n == 0:
        return 0
    pad = (-n) % n_envs
    idx = np.concatenate([np.arange(n), np.arange(pad) % n])
    for i in range(0, len(idx), n_envs):
        j = idx[i:i + n_envs]
        infos = [{"TimeLimit.truncated": bool(demo["timeout"][t])} for t in j]
        buffer.add(demo["obs"][j], demo["next_obs"][j], demo["action"][j], demo["reward"][j], demo["done"][j],
                   infos)
    return len(idx)


def train_one(cell, agent, seed, cfg, demo=None, log=print):
    """Train one (cell, agent, seed); returns (per-episode success on the evaluation seeds, curve rows,
    env steps, seconds)."""
    import torch
    from stable_baselines3 import PPO, SAC
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.vec_env import VecMonitor
    from penny_env.sb3 import PennySB3VecEnv
    from training.episodes import make_vector_env

    torch.set_num_threads(1)
    probe = cell[0]
    env_id, overrides = cell_spec(*cell)
    steps = budget(agent, probe, cfg)
    n_envs = cfg["num_envs"]
    t0 = time.perf_counter()
    venv = VecMonitor(PennySB3VecEnv(env_id, num_envs=n_envs, **overrides, **reward_fields(env_id, overrides)))
    venv.seed(TRAIN_SEED + 10_000 * seed)
    if agent == "ppo":
        hyper = dict(PPO_HYPER, batch_size=min(PPO_HYPER["batch_size"], PPO_HYPER["n_steps"] * n_envs))
        model = PPO("MlpPolicy", venv, seed=TRAIN_SEED + 10_000 * seed, verbose=0, device="cpu", **hyper)
    else:
        n_demo = 0 if demo is None else len(demo["obs"]) + n_envs
        model = SAC("MlpPolicy", venv, seed=TRAIN_SEED + 10_000 * seed, verbose=0, device="cpu",
                    buffer_size=steps + n_demo + 2 * n_envs, learning_starts=cfg["learning_starts"], **SAC_HYPER)
        if agent == "sac_witness":
            add_to_buffer(model.replay_buffer, demo, n_envs)
    val_env = make_vector_env(env_id, cfg["val_episodes"], **overrides)
    every = max(1, steps // cfg["curve_points"])
    curve = []

    def validate(t):
        s = success_of(val_env, lambda o: model.predict(o, deterministic=True)[0], VAL_SEED)
        curve.append({"point": len(curve), "timesteps": int(t), "val_success": float(np.mean(s)),
                      "seconds": round(time.perf_counter() - t0, 1)})

    class Curve(BaseCallback):
        def _on_training_start(self):
            validate(0)
            self.next = every

        def _on_step(self):
            if self.num_timesteps >= self.next:
                validate(self.num_timesteps)
                self.next += every
            return True

    model.learn(total_timesteps=steps, callback=Curve())
    if curve[-1]["timesteps"] < model.num_timesteps:
        validate(model.num_timesteps)
    val_env.close()
    venv.close()
    eval_env = make_vector_env(env_id, cfg["eval_episodes"], **overrides)
    succ = success_of(eval_env, lambda o: model.predict(o, deterministic=True)[0], 0)
    eval_env.close()
    secs = time.perf_counter() - t0
    log(f"  {agent} seed {seed}: {int(succ.sum())}/{len(succ)} on the evaluation seeds; curve "
        + " ".join(f"{c['val_success']:.2f}" for c in curve) + f" ({model.num_timesteps} steps, {secs:.0f} s)")
    for c in curve:
        c.update(probe=cell[0], table=cell[1], law=cell[2], agent=agent, seed=seed)
    return succ, curve, int(model.num_timesteps), secs


def agent_row(cell, env_id, overrides, agent, succ_by_seed, witnessed, n, steps, demo_n, secs):
    """The results row of one (cell, agent) from the per-seed success counts (each of n episodes)."""
    probe, table, law = cell
    S = len(succ_by_seed)
    k = int(sum(succ_by_seed))
    M = np.array([[1.0] * s + [0.0] * (n - s) for s in succ_by_seed])
    lo, hi = seed_clustered_ci(M) if S > 1 else clopper_pearson(k, n)
    wr = witnessed / n
    rate = k / (S * n)
    return {"probe": probe, "table": table, "law": law, "env_id": env_id,
            "overrides": " ".join(f"{a}={b}" for a, b in overrides.items()), "agent": agent, "seeds": S,
            "episodes": S * n, "success": k, "rate": rate, "ci_low": lo, "ci_high": hi,
            "seed_successes": " ".join(str(int(s)) for s in succ_by_seed), "witnessed": witnessed,
            "witness_rate": wr, "ratio": rate / wr if witnessed else float("nan"),
            "ratio_high": hi / wr if witnessed else float("nan"),
            "goal_met": "" if agent == "witness" else ("yes" if witnessed and 2 * rate >= wr else "no"),
            "env_steps": steps, "demo_transitions": demo_n, "train_s": round(secs, 1)}


def run_cell(cell, agents, cfg, log=print):
    """Rows (witness, then each agent) and curve rows of one cell."""
    t_cell = time.perf_counter()
    env_id, overrides = cell_spec(*cell)
    n = cfg["eval_episodes"]
    w = Witness(env_id, overrides)
    try:
        wit = int(sum(w.pair(s).witnessed for s in range(n)))
    finally:
        w.close()
    log(f"{' '.join(cell)}: witness {wit}/{n} on the evaluation seeds ({time.perf_counter() - t_cell:.0f} s)")
    rows = [agent_row(cell, env_id, overrides, "witness", [wit], wit, n, 0, 0, 0.0)]
    demo, demo_eps = None, 0
    if "sac_witness" in agents:
        t = time.perf_counter()
        demo, demo_eps = witness_transitions(env_id, overrides, range(DEMO_SEED, DEMO_SEED + cfg["demos"]))
        log(f"  witness demonstrations: {demo_eps}/{cfg['demos']} certified episodes, {len(demo['obs'])} "
            f"transitions ({time.perf_counter() - t:.0f} s)")
    curves = []
    for agent in agents:
        succs, secs, steps = [], 0.0, 0
        for seed in range(cfg["seeds"]):
            s, c, st, sec = train_one(cell, agent, seed, cfg, demo if agent == "sac_witness" else None, log)
            succs.append(int(s.sum()))
            curves += c
            secs += sec
            steps = st
        demo_n = len(demo["obs"]) if agent == "sac_witness" else 0
        rows.append(agent_row(cell, env_id, overrides, agent, succs, wit, n, steps, demo_n, secs))
    return rows, curves


# -- the report -----------------------------------------------------------------------------------------
def read_csv(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def _num(v):
    if isinstance(v, (int, float)):
        return v
    if v in ("", None):
        return float("nan")
    try:
        return int(v)
    except ValueError:
        return float(v)


def _f(v, spec=".2f"):
    v = _num(v)
    return "-" if v != v else format(v, spec)


def curve_summary(curves):
    """Per (cell, agent): mean over seeds of the curve at 0, 1/4, 1/2, 3/4 and the end of the budget
    (interpolated), the peak, the last-quarter rise (mean over seeds) and whether it flattened."""
    out = {}
    keys = []
    for c in curves:
        k = (c["probe"], c["table"], c["law"], c["agent"])
        if k not in keys:
            keys.append(k)
    for k in keys:
        by_seed = {}
        for c in curves:
            if (c["probe"], c["table"], c["law"], c["agent"]) == k:
                by_seed.setdefault(int(_num(c["seed"])), []).append((float(_num(c["timesteps"])),
                                                                     float(_num(c["val_success"]))))
        pts, rises, peaks, ends, total = [], [], [], [], 0.0
        for pts_s in by_seed.values():
            pts_s.sort()
            t, y = np.array(pts_s).T
            total = t[-1]
            pts.append([float(np.interp(f * t[-1], t, y)) for f in (0.0, 0.25, 0.5, 0.75, 1.0)])
            rises.append(last_quarter_change(pts_s) if len(pts_s) > 1 else float("nan"))
            peaks.append(float(y.max()))
            ends.append(float(y[-1]))
        rise, end = float(np.mean(rises)), float(np.mean(ends))
        out[k] = {"points": np.mean(pts, axis=0).tolist(), "peak": float(np.mean(peaks)), "rise": rise,
                  "flat": "yes" if (rise < FLAT or end > 1 - FLAT) else "no", "steps": int(total),
                  "seeds": len(by_seed)}
    return out


def imitation_rows():
    """docs/fair_rl.md's and docs/fair_rl_extra/*/fair_rl.md's rows (bc, dagger, options), by cell."""
    out = {}
    for path in [DOCS / "fair_rl.csv", *sorted((DOCS / "fair_rl_extra").glob("*/fair_rl.csv"))]:
        if not path.is_file():
            continue
        for r in read_csv(path):
            if r["agent"] != "witness":
                out.setdefault((r["probe"], r["table"], r["law"]), {})[r["agent"]] = r
    return out


def _cells(rows):
    cells = []
    for r in rows:
        c = (r["probe"], r["table"], r["law"])
        if c not in cells:
            cells.append(c)
    return cells


def write_report(path: Path, rows, curves, meta):
    cfg = meta["config"]
    lines = ["# A fair chance for pure RL on the single-input probes: PPO, SAC and SAC with witness transitions",
             "", *meta["machine"],
             f"- command: `{meta['command']}` ({meta['wall_s']:.0f} s wall, finished {meta['date']})",
             "- regenerate: run the command above from the repository root (one process, torch and numba on one "
             "thread)"]
    if meta.get("sources"):
        lines.append(meta["sources"])
    caps = ", ".join(f"{p.lower()} {cfg['ppo_steps'][p]:,} PPO / {cfg['sac_steps'][p]:,} SAC env steps"
                     for p in ("Steer", "Drive"))
    lines += ["", f"Budget (the cap) per (cell, agent, seed): {caps}; {cfg['seeds']} seed(s) per (cell, agent); "
              f"{cfg['num_envs']} training envs; validation curve at {cfg['curve_points']} points of "
              f"{cfg['val_episodes']} episodes (seeds from {VAL_SEED}); evaluation on {cfg['eval_episodes']} "
              f"episodes (seeds 0 .. {cfg['eval_episodes'] - 1}, the witness study's pair seeds); sac_witness: "
              f"the certified witness episodes of {cfg['demos']} training seeds (from {DEMO_SEED}) in the replay "
              "buffer. The whole run was sized to about 70 minutes of one core. Method and every choice: "
              "[studies/fair_pure_rl.py](../studies/fair_pure_rl.py) (module docstring).", "",
              "## Fairness settings", "",
              f"* **Discount and horizon**: gamma {GAMMA} (effective horizon 1000 steps = 50 s) for PPO and SAC, "
              f"PPO's gae_lambda {PPO_HYPER['gae_lambda']}; the success bonus of a 20 s (400-step) solution keeps "
              f"{GAMMA ** 400:.2f} of its value (0.99 in the old study: {0.99 ** 400:.3f}). Episodes: the probe's "
              "own time limit (steer park 400 steps = 20 s, drive reach 200 steps = 10 s).",
              "* **Reward**: the success bonus only (" + ", ".join(f"{k} {v:g}" for k, v in REWARD.items())
              + "): it neither charges the way out to the wall (the packaged progress term (d_prev - d) / L does) "
              "nor the spinning and steering the single-input strategies need (speed and control costs). "
              "Success is the probe's own `info[\"is_success\"]`.",
              "* **Budgets**: the cap above; the curves below say whether they had flattened (rise of the "
              f"validation success over the last quarter under {FLAT:.2f}, or ending above {1 - FLAT:.2f}).",
              "* **Witnesses**: sac_witness starts with the witness transitions in its replay buffer and keeps "
              "them for the whole run (the buffer holds the budget and the demonstrations; nothing is "
              "overwritten). Behaviour cloning, DAgger and the option agent are "
              "[fair_rl.md](fair_rl.md)'s, compared below.", "",
              "PPO: " + ", ".join(f"{k} {v}" for k, v in PPO_HYPER.items() if k != "policy_kwargs")
              + ", MLP 64 x 64. SAC: " + ", ".join(f"{k} {v}" for k, v in SAC_HYPER.items() if k != "policy_kwargs")
              + f", learning_starts {cfg['learning_starts']}, automatic entropy, MLP 64 x 64.", "",
              "## Results", "",
              "Success of the final model (deterministic actions), pooled over seeds; the interval is clustered "
              "by seed where there is more than one (studies/stats.seed_clustered_ci), else exact "
              "Clopper-Pearson. Ratio: the agent's rate over the witness's on the same seeds (its interval's upper "
              "end over the witnessed rate in brackets); the goal of issue 20 item 4 is a ratio of at least 0.5, "
              "judged on the point estimate, as in fair_rl.md. With two seeds the seed-clustered interval is a t "
              "interval with one degree of freedom (t = 12.7): wide wherever the seeds disagree (a rate near 0.5 "
              "can then span [0, 1]); the per-seed column shows the spread.",
              "",
              "| actuation | table | law | agent | success [95 % CI] | per seed | witnessed | ratio [upper] | "
              "goal (>= 0.5) |",
              "| --- | --- | --- | --- | --- | --- | --- | ---: | --- |"]
    for r in rows:
        n_seed = int(_num(r["episodes"])) // max(1, int(_num(r["seeds"])))
        lines.append(f"| {PROBE_TASKS[r['probe']]} | {TABLE_NAMES[r['table']]} | {r['law']} | {r['agent']} | "
                     f"{r['success']}/{r['episodes']} = {_f(r['rate'], '.3f')} [{_f(r['ci_low'], '.3f')}, "
                     f"{_f(r['ci_high'], '.3f')}] | {' · '.join(f'{s}/{n_seed}' for s in str(r['seed_successes']).split())} | "
                     f"{r['witnessed']}/{n_seed} | {_f(r['ratio'])} [{_f(r['ratio_high'])}] | {r['goal_met'] or '-'} |")
    cells = _cells(rows)
    lines += ["", "## Verdict per cell (this run's agents)", ""]
    for c in cells:
        rs = [r for r in rows if (r["probe"], r["table"], r["law"]) == c and r["agent"] != "witness"]
        if not rs:
            continue
        best = max(rs, key=lambda r: _num(r["rate"]))
        met = [r["agent"] for r in rs if r["goal_met"] == "yes"]
        lines.append(f"* {PROBE_TASKS[c[0]]}, {TABLE_NAMES[c[1]]}, {c[2]}: "
                     + (f"**goal met** by {', '.join(met)} (best {best['agent']}: ratio {_f(best['ratio'])})" if met
                        else f"**goal not met**: best {best['agent']}, ratio {_f(best['ratio'])} (upper end of its "
                        f"interval over the witnessed rate: {_f(best['ratio_high'])})"))
    summ = curve_summary(curves)
    lines += ["", "## Curves: validation success vs env steps", "",
              f"Mean over seeds of the deterministic policy's success on {cfg['val_episodes']} validation episodes, "
              "at fractions of the budget (interpolated between the curve's points); rise: the last point minus "
              "the curve at 3/4 of the budget (mean over seeds); flattened: rise under "
              f"{FLAT:.2f} or ending above {1 - FLAT:.2f}. Per point `fair_pure_rl_curves.csv`.", "",
              "| actuation | table | law | agent | 0 | 1/4 | 1/2 | 3/4 | end | peak | rise over the last quarter | "
              "flattened | env steps (cap) | seeds |",
              "| --- | --- | --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- | ---: | ---: |"]
    for k, s in summ.items():
        lines.append(f"| {PROBE_TASKS[k[0]]} | {TABLE_NAMES[k[1]]} | {k[2]} | {k[3]} | "
                     + " | ".join(f"{v:.2f}" for v in s["points"])
                     + f" | {s['peak']:.2f} | {s['rise']:+.2f} | {s['flat']} | {s['steps']:,} | {s['seeds']} |")
    not_flat = [k for k, s in summ.items() if s["flat"] == "no"]
    lines += ["", ("All curves had flattened at the cap." if not not_flat else
                   f"Still rising at the cap ({len(not_flat)} of {len(summ)}): "
                   + "; ".join(f"{PROBE_TASKS[k[0]]} {TABLE_NAMES[k[1]]} {k[2]} {k[3]} "
                               f"({summ[k]['rise']:+.2f})" for k in not_flat)
                   + ". Their rates are lower bounds of what a larger budget gives.")]
    lines += what_works(rows, cells, summ)
    lines += ["", "CSV: per cell and agent `fair_pure_rl.csv`, curves `fair_pure_rl_curves.csv`, the run's "
              "configuration `fair_pure_rl_run.json` (beside this report)."]
    path.write_text("\n".join(lines).rstrip() + "\n")


def what_works(rows, cells, summ):
    """The comparison with docs/fair_rl.md's imitation and option agents, and item 4's verdict over every
    learned agent."""
    imi = imitation_rows()
    lines = ["", "## What works: pure RL, RL with witness transitions, imitation and options", "",
             "Ratio to the witnessed rate per cell (same evaluation seeds 0 .. 199 in both reports; bc, dagger and "
             "options from [fair_rl.md](fair_rl.md) and [fair_rl_extra/](fair_rl_extra/), one seed each).", "",
             "| actuation | table | law | " + " | ".join(AGENTS) + " | bc | dagger | options | goal met by |",
             "| --- | --- | --- | " + " | ".join("---:" for _ in AGENTS) + " | ---: | ---: | ---: | --- |"]
    all_cells = list(cells) + [c for c in imi if c not in cells and c[0] in ("Steer", "Drive")]
    met_by = {}
    for c in all_cells:
        here = {r["agent"]: r for r in rows if (r["probe"], r["table"], r["law"]) == c}
        there = imi.get(c, {})
        ratios = {a: (_num(here[a]["ratio"]), here[a]["goal_met"]) for a in AGENTS if a in here}
        ratios.update({a: (_num(there[a]["ratio"]), there[a]["goal_met"]) for a in ("bc", "dagger", "options")
                       if a in there})
        met = [a for a, (_, g) in ratios.items() if g == "yes"]
        met_by[c] = met
        lines.append(f"| {PROBE_TASKS[c[0]]} | {TABLE_NAMES[c[1]]} | {c[2]} | "
                     + " | ".join(_f(ratios[a][0]) if a in ratios else "-" for a in (*AGENTS, "bc", "dagger", "options"))
                     + f" | {', '.join(met) or 'none'} |")
    pure = [r for r in rows if r["agent"] in ("ppo", "sac")]
    sw = [r for r in rows if r["agent"] == "sac_witness"]

    def span(rs, probe):
        v = [_num(r["ratio"]) for r in rs if r["probe"] == probe]
        v = [x for x in v if x == x]
        return (f"{min(v):.2f}" if min(v) == max(v) else f"{min(v):.2f} to {max(v):.2f}") if v else None

    def upper(rs, probe):
        v = [_num(r["ratio_high"]) for r in rs if r["probe"] == probe]
        v = [x for x in v if x == x]
        return f"{max(v):.2f}" if v else None

    para = []
    for probe, name in (("Steer", "steer-only park"), ("Drive", "drive-only reach")):
        if span(pure, probe) is not None:
            para.append(f"On {name}, pure RL (PPO, SAC) with the fair settings reaches {span(pure, probe)} of the "
                        f"witnessed rate (upper ends of the intervals up to {upper(pure, probe)})"
                        + (f"; SAC with the witness transitions in its buffer {span(sw, probe)} (up to "
                           f"{upper(sw, probe)})" if span(sw, probe) is not None else "") + ".")
    steer_rl = [c for c in cells if c[0] == "Steer" and any(a in AGENTS for a in met_by.get(c, []))]
    drive_rl = [c for c in cells if c[0] == "Drive" and any(a in AGENTS for a in met_by.get(c, []))]
    para.append(f"Of this run's agents, the goal is met on {len(steer_rl)} steer-park table(s) "
                f"({', '.join(TABLE_NAMES[c[1]] for c in steer_rl) or 'none'}) and under {len(drive_rl)} drive-reach "
                f"law(s) ({', '.join(c[2] for c in drive_rl) or 'none'}).")
    opt = [c for c in all_cells if "options" in met_by.get(c, [])]
    flat = ("bc", "dagger", *AGENTS)
    flat_met = [c for c in all_cells if any(a in flat for a in met_by.get(c, []))]
    k_sac = sum(int(_num(r["success"])) for r in rows if r["agent"] == "sac")
    k_sw = sum(int(_num(r["success"])) for r in rows if r["agent"] == "sac_witness")
    n_sac = sum(int(_num(r["episodes"])) for r in rows if r["agent"] == "sac")
    if n_sac and sw:
        para.append(f"The witness transitions in SAC's buffer change its successes, summed over the cells, from "
                    f"{k_sac} to {k_sw} of {n_sac} episodes.")
        if k_sw < k_sac:
            gap = max((c for c in cells if any(r["agent"] == "sac" for r in rows if (r["probe"], r["table"], r["law"]) == c)
                       and any(r["agent"] == "sac_witness" for r in rows if (r["probe"], r["table"], r["law"]) == c)),
                      key=lambda c: _num(next(r["rate"] for r in rows if (r["probe"], r["table"], r["law"]) == c
                                              and r["agent"] == "sac"))
                      - _num(next(r["rate"] for r in rows if (r["probe"], r["table"], r["law"]) == c
                                  and r["agent"] == "sac_witness")))
            rate = {r["agent"]: _num(r["rate"]) for r in rows if (r["probe"], r["table"], r["law"]) == gap}
            para.append(f"They hurt here, most on {PROBE_TASKS[gap[0]]} {TABLE_NAMES[gap[1]]} {gap[2]} (SAC "
                        f"{rate['sac']:.2f}, with the witness transitions {rate['sac_witness']:.2f}; the curves "
                        "above show when). The cause was not isolated within this budget; a "
                        "known failure of off-policy RL from a fixed set of demonstrations is the critic's error on "
                        "actions the demonstrations do not cover (the witnesses' torques are saturated feedback "
                        "laws), which methods such as RLPD (symmetric sampling of demonstrations and own data, "
                        "normalised critics) or AWAC (an advantage-weighted actor) address; neither was tried.")
    if imi:
        ran = [c for c in all_cells if c in imi]
        para.append(f"A flat torque policy (bc, dagger, ppo, sac, sac_witness) meets the goal in {len(flat_met)} of "
                    f"the {len(all_cells)} cells "
                    f"({', '.join(f'{c[0].lower()} {TABLE_NAMES[c[1]]} {c[2]}' for c in flat_met) or 'none'}); "
                    f"the option agent of fair_rl.md, which learns from the observation which witness controller to "
                    f"run after each impact, meets it in {len(opt)} of the {len(ran)} cells it ran.")
    pure_met = [c for c in cells if any(a in ("ppo", "sac") for a in met_by.get(c, []))]
    if not pure_met and len(opt) > len(flat_met):
        para.append("What works is the structure the witnesses give (which wall-first manoeuvre to commit to after "
                    "each impact), not a longer discount, a wall-neutral reward or more steps alone: the witnesses' "
                    "solutions are manoeuvres of many seconds through the wall, which exploration from a sparse "
                    "bonus in the raw torque space rarely finds within these budgets (the curves above).")
    lines += ["", " ".join(para)]
    # item 4's verdict over every learned agent (this run and fair_rl.md's)
    steer = [c for c in all_cells if c[0] == "Steer"]
    drive = [c for c in all_cells if c[0] == "Drive"]
    steer_met = [c for c in steer if met_by.get(c)]
    drive_met = [c for c in drive if met_by.get(c)]
    laws = list(dict.fromkeys(c[2] for c in drive))
    ok_steer, ok_drive = len(steer_met) >= 2, bool(drive) and len(drive_met) == len(drive)
    pure_cells = [c for c in cells if any(a in ("ppo", "sac") for a in met_by.get(c, []))]
    only_opt = [c for c in steer_met + drive_met if met_by[c] == ["options"]]
    lines += ["", "## Item 4's goal, counting every learned agent", "",
              f"* Steer-only park, at least two tables: **{'met' if ok_steer else 'not met'}** on "
              f"{len(steer_met)} of {len(steer)} tables run ("
              + "; ".join(f"{TABLE_NAMES[c[1]]}: {', '.join(met_by[c])}" for c in steer_met) + ")"
              + (f"; not on {', '.join(TABLE_NAMES[c[1]] + ' ' + c[2] for c in steer if c not in steer_met)}"
                 if len(steer_met) < len(steer) else "") + ".",
              f"* Drive-only reach, every law: **{'met' if ok_drive else 'not met'}** under {len(drive_met)} of "
              f"{len(drive)} laws run ({', '.join(laws)}) ("
              + "; ".join(f"{c[2]}: {', '.join(met_by[c])}" for c in drive_met) + ")"
              + (f"; not under {', '.join(c[2] for c in drive if c not in drive_met)}"
                 if len(drive_met) < len(drive) else "") + ".",
              f"* Overall: **{'met' if ok_steer and ok_drive else 'not met'}** counting every learned agent"
              + (f" (met only by the option agent of fair_rl.md, which uses the witnesses, on "
                 f"{', '.join(f'{c[0].lower()} {TABLE_NAMES[c[1]]} {c[2]}' for c in only_opt)})" if only_opt else "")
              + ". Pure RL "
              "(PPO or SAC without witnesses) with the fair discount, reward and budget meets it "
              + (f"only on {', '.join(f'{c[0].lower()} {TABLE_NAMES[c[1]]} {c[2]}' for c in pure_cells)}"
                 if pure_cells else "on no cell") + f" of the {len(cells)} it ran.",
              ]
    return lines


# -- command line -----------------------------------------------------------------------------------------
def _out_paths(out: Path):
    stem = out.with_suffix("")
    return (stem.parent / (stem.name + ".csv"), stem.parent / (stem.name + "_curves.csv"),
            stem.parent / (stem.name + "_run.json"))


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m studies.fair_pure_rl", description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="tiny run (< 90 s) into a temporary folder, never docs/")
    ap.add_argument("--out", help="the report's path (default: docs/fair_pure_rl.md; --quick: a temporary folder)")
    ap.add_argument("--cells", nargs="+", metavar="PROBE:TABLE:LAW",
                    help="cells (default: steer park on ellipse, stadium, rounded_rectangle; drive reach on the "
                         "ellipse under elastic, plastic, 0.5)")
    ap.add_argument("--agents", nargs="+", metavar="AGENT", help=f"agents, of {list(AGENTS)} (default: all)")
    ap.add_argument("--seeds", type=positive_int("--seeds"), help="seeds per (cell, agent) (default 2; --quick 1)")
    ap.add_argument("--report-only", action="store_true",
                    help="rewrite the report from the CSVs and the run's JSON beside it (no training)")
    args = ap.parse_args(argv)
    try:
        cells = [parse_cell(c) for c in args.cells] if args.cells else list(QUICK_CELLS if args.quick else DEFAULT_CELLS)
    except ValueError as exc:
        ap.error(str(exc))
    agents = list(args.agents or AGENTS)
    bad = [a for a in agents if a not in AGENTS]
    if bad:
        ap.error(f"unknown agent(s) {bad}; agents: {list(AGENTS)}")
    cfg = json.loads(json.dumps(QUICK if args.quick else FULL))
    if args.seeds is not None:
        cfg["seeds"] = args.seeds
    if args.out:
        out = Path(args.out).resolve()
    elif args.quick:
        import tempfile
        out = Path(tempfile.mkdtemp(prefix="penny_env-quick-")) / "fair_pure_rl.md"
    else:
        out = DOCS / "fair_pure_rl.md"
    if args.quick and (out.parent == DOCS.resolve() or out.parent.is_relative_to(DOCS.resolve())
                       or out.parent == ROOT):
        ap.error(f"--quick never writes into docs/ or the repository root; give another --out (got {args.out})")
    csv_path, curves_path, run_path = _out_paths(out)
    from studies.provenance import REPORTS, stamp_line
    rel = out.relative_to(ROOT).as_posix() if out.is_relative_to(ROOT) else None
    if args.report_only:
        if not (csv_path.is_file() and curves_path.is_file() and run_path.is_file()):
            ap.error(f"--report-only needs {csv_path.name}, {curves_path.name} and {run_path.name} beside {out}")
        meta = json.loads(run_path.read_text())
        meta["sources"] = stamp_line(rel) if rel in REPORTS else None
        rows, curves = read_csv(csv_path), read_csv(curves_path)
        write_report(out, rows, curves, meta)
        print(f"wrote {out} (from {csv_path.name}, {curves_path.name})")
        return rows
    import torch
    torch.set_num_threads(1)
    from studies.common import command_line, machine_lines
    out.parent.mkdir(parents=True, exist_ok=True)
    sources = stamp_line(rel) if rel in REPORTS else None  # the sources as they are when the run starts
    t0 = time.perf_counter()
    rows, curves = [], []
    for cell in cells:
        r, c = run_cell(cell, agents, cfg)
        rows += r
        curves += c
        sys.stdout.flush()
    meta = {"command": command_line("studies.fair_pure_rl", list(sys.argv[1:] if argv is None else argv)),
            "machine": machine_lines(), "wall_s": time.perf_counter() - t0,
            "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
            "sources": sources, "config": cfg,
            "cells": [":".join(c) for c in cells], "agents": agents, "reward": REWARD, "gamma": GAMMA,
            "ppo": PPO_HYPER, "sac": SAC_HYPER}
    write_csv(csv_path, rows, FIELDS)
    write_csv(curves_path, curves, CURVE_FIELDS)
    run_path.write_text(json.dumps(meta, indent=1))
    write_report(out, rows, curves, meta)
    print(f"wrote {out} ({meta['wall_s']:.0f} s)")
    return rows


if __name__ == "__main__":
    main()
