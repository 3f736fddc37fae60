"""training.ppo_torch next to Stable-Baselines3's PPO: success against wall time, and throughput.

    python -m studies.ppo_compare [--quick] [--timesteps 245760] [--device cpu] [--runs runs/ppo_compare]
                                   [--out docs/ppo_torch.md]

Both train on the same native vector env (PennyVectorEnv of configs/train/ppo_reach_ellipse.yaml's
env id, the same num_envs and seed) with the config's hyperparameters, for the same budget of env steps,
one after the other in this process with one torch thread: SB3 through penny_env/sb3.py as training.train
and training.runner build it (runner.make_train_env, runner.algo_class: a VecMonitor over PennySB3VecEnv),
without runner's periodic evaluations and checkpoints so that the wall time is training alone; the torch
PPO through training.ppo_torch.train_agent. After every update each records (env steps, wall seconds since the
start of training, success rate over its last 100 finished training episodes, their mean return). The
trained policies are then evaluated with deterministic actions on the same held-out seeds
(training.episodes.run_episodes; seeds from training.runner.eval_seed(seed)).

Writes the report (--out; default runs/reports/ppo_torch.md, --quick: a new temporary directory; --quick
refuses an --out in docs/), the plot beside it (<out stem>.png: success against wall-clock seconds and against env
steps, both implementations), and the runs (--runs, default runs/ppo_compare; --quick: a temporary
directory): torch_seed<S>/ (ppo_torch's folders), sb3_seed<S>/ (model.zip, curve.csv) and curves.json. Seeds:
--seeds (default 0 1 2), the runs alternating (ppo_torch seed 0, SB3 seed 0, ppo_torch seed 1, ...).
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

CONFIG = "configs/train/ppo_reach_ellipse.yaml"
ROOT = Path(__file__).resolve().parents[1]


def quick_config(cfg: dict) -> dict:
    """training.train's --quick settings: a pipeline check, seconds long."""
    cfg = dict(cfg, eval_episodes=8)
    cfg["algo_kwargs"] = dict(cfg["algo_kwargs"], n_steps=32, batch_size=256, n_epochs=2)
    return cfg


def run_sb3(cfg: dict, total: int, run_dir: Path, log=print) -> dict:
    """SB3's PPO on the config's env for `total` env steps: curve rows after each update, timing, model."""
    import torch
    from stable_baselines3.common.callbacks import BaseCallback
    from training.runner import algo_class, check_hyperparameters, make_train_env

    torch.set_num_threads(1)
    run_dir.mkdir(parents=True, exist_ok=True)
    hyper = {**cfg["algo_kwargs"], "policy_kwargs": dict(cfg["policy_kwargs"])}
    check_hyperparameters("ppo", hyper)
    venv = make_train_env(cfg["env_id"], cfg["num_envs"], cfg["seed"])
    model = algo_class("ppo")("MlpPolicy", venv, seed=cfg["seed"], verbose=0, device="cpu", **hyper)
    rows, clock = [], {"env": 0.0, "update": 0.0, "update_start": None}
    adapter = venv.venv  # PennySB3VecEnv under VecMonitor: time its step (the native env's step and the adapter)
    step_wait = adapter.step_wait

    def timed_step_wait():
        t = time.perf_counter()
        out = step_wait()
        clock["env"] += time.perf_counter() - t
        return out
    adapter.step_wait = timed_step_wait

    class Curve(BaseCallback):
        def _on_training_start(self):
            self.t0 = time.perf_counter()

        def _on_rollout_end(self):  # SB3's update (model.train) runs from here to the next rollout's start
            clock["update_start"] = time.perf_counter()

        def _update_done(self):
            if clock["update_start"] is not None:
                clock["update"] += time.perf_counter() - clock["update_start"]
                clock["update_start"] = None

        def _row(self):
            m = self.model
            succ = float(np.mean(m.ep_success_buffer)) if len(m.ep_success_buffer) else float("nan")
            ret = float(np.mean([e["r"] for e in m.ep_info_buffer])) if len(m.ep_info_buffer) else float("nan")
            rows.append((int(self.num_timesteps), time.perf_counter() - self.t0, succ, ret, len(m.ep_success_buffer)))
            if len(rows) % 10 == 0:
                log(f"[sb3] {rows[-1][0]:,} steps, {rows[-1][0] / rows[-1][1]:,.0f} steps/s, success {succ:.2f}, "
                    f"{rows[-1][1]:.0f} s")

        def _on_rollout_start(self):  # the previous update is done: the row after it
            self._update_done()
            if self.num_timesteps > 0:
                self._row()

        def _on_step(self):
            return True

        def _on_training_end(self):
            self._update_done()
            self._row()

    model.learn(total_timesteps=total, callback=Curve())
    model.save(run_dir / "model.zip")
    venv.close()
    with open(run_dir / "curve.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["global_step", "wall_time_s", "success_rate", "mean_return", "episodes_in_window"])
        w.writerows(rows)
    return {"rows": rows, "steps": rows[-1][0], "seconds": rows[-1][1], "env_seconds": clock["env"],
            "update_seconds": clock["update"], "policy": lambda o: model.predict(o, deterministic=True)[0]}


def run_torch(cfg: dict, total: int, run_dir: Path, device: str, quick: bool, log=print) -> dict:
    import torch
    from training import ppo_torch

    args = ppo_torch.args_from_config(cfg, total_timesteps=total, device=device, out=str(run_dir))
    rows = []
    agent, res = ppo_torch.train_agent(args, log=log, on_update=lambda r: rows.append(
        (r["global_step"], r["wall_time_s"], r["success_rate"], r["mean_return"], min(r["episodes"], args.success_window))))
    agent = agent.cpu()

    def policy(obs):
        with torch.no_grad():
            return agent.act(torch.as_tensor(obs)).numpy()
    return {"rows": rows, "steps": res["timesteps"], "seconds": res["train_seconds"], "policy": policy,
            "env_seconds": res["env_seconds"], "update_seconds": res["update_seconds"],
            "device": res["device"], "own_eval": res["eval"]}


def _fmt(x, spec=".2f"):
    return "n/a" if x is None or (isinstance(x, float) and np.isnan(x)) else format(x, spec)


FULL_WINDOW = 100  # the success window (SB3's ep_success_buffer, ppo_torch's success_window)


def first_time_at(rows, level):
    """(wall seconds, env steps) of the first row whose training success over a full window of 100
    episodes reaches level (None if none): the first few episodes to end are short, mostly successes."""
    for step, wall, succ, _, n in rows:
        if n >= FULL_WINDOW and succ >= level:
            return wall, step
    return None


NAMES = {"torch": "training.ppo_torch", "sb3": "Stable-Baselines3 PPO"}


def plot(results: dict, path: Path, env_id: str, total: int) -> None:
    """Success against wall seconds (left) and env steps (right): one thin line per seed."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    for key, color in (("torch", "C0"), ("sb3", "C1")):
        runs = results[key]
        rate = sum(r["steps"] for r in runs) / sum(r["seconds"] for r in runs)
        for i, r in enumerate(runs):
            steps, wall, succ, _, n = (np.array(c, dtype=float) for c in zip(*r["rows"]))
            succ = np.where(n >= 20, succ, np.nan)  # from 20 finished episodes on
            label = f"{NAMES[key]} ({rate:,.0f} steps/s)" if i == 0 else None
            axes[0].plot(wall, succ, color=color, lw=1.2, alpha=0.8, label=label)
            axes[1].plot(steps, succ, color=color, lw=1.2, alpha=0.8, label=NAMES[key] if i == 0 else None)
    axes[0].set_xlabel("wall-clock seconds of training (one CPU thread)")
    axes[1].set_xlabel("env steps")
    axes[0].set_ylabel("success rate, last 100 training episodes\n(drawn from 20 finished episodes on)")
    for ax in axes:
        ax.set_ylim(-0.02, 1.02)
        ax.grid(alpha=0.3)
        ax.legend(loc="lower right", fontsize=8)
    n = len(results["torch"])
    fig.suptitle(f"PPO on {env_id}, {total:,} env steps per run, {n} seed(s) each (one line per seed): success "
                 "against wall time (left) and env steps (right)", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def throughput(runs) -> float:
    return sum(r["steps"] for r in runs) / sum(r["seconds"] for r in runs)


def report(results: dict, cfg: dict, total: int, argv, png: Path, quick: bool, seconds: float) -> str:
    from studies.common import header

    lines = header(f"Compact PPO in torch next to Stable-Baselines3 ({cfg['env_id']})", "studies.ppo_compare",
                   list(argv))
    kw = cfg["algo_kwargs"]
    t, s = results["torch"], results["sb3"]
    seeds = [r["seed"] for r in t]
    lines += [
        f"- wall time of the whole command: {seconds / 60:.1f} minutes", "",
        f"Both PPOs train on the native vector env of `{cfg['env_id']}` ({cfg['num_envs']} envs) with the "
        f"hyperparameters of `{CONFIG}`{' (--quick: n_steps 32, batch 256, 2 epochs)' if quick else ''} "
        f"(n_steps {kw['n_steps']}, batch {kw['batch_size']}, {kw['n_epochs']} epochs, lr {kw['learning_rate']}, "
        f"gamma {kw['gamma']}, GAE lambda {kw['gae_lambda']}, entropy {kw['ent_coef']}, net "
        f"{cfg['policy_kwargs'].get('net_arch')}; the rest SB3's defaults, which training.ppo_torch copies) for "
        f"{total:,} env steps per run, seeds {seeds}, in one process with one torch thread, alternating "
        f"(ppo_torch seed {seeds[0]}, SB3 seed {seeds[0]}, ppo_torch seed {seeds[1] if len(seeds) > 1 else '...'}, "
        f"...; ppo_torch on {t[0]['device']}, SB3 on cpu). Wall time counts training alone, from the first reset "
        "to the last update (no periodic evaluations, no checkpoints; the env's compilation happens before). "
        "The training success is the share of successes among the last 100 finished training episodes (SB3's "
        "`ep_success_buffer`; the same window in ppo_torch); the evaluation runs "
        f"{cfg['eval_episodes']} deterministic episodes on held-out seeds (from training.runner.eval_seed(seed)), "
        "the same for both.", "",
        f"![success against wall time and env steps]({png.name})", "",
        "| implementation | seed | env steps | training wall s | steps/s | training success (last 100 episodes) | "
        "evaluation success | evaluation mean return | load (1 min) before / after |",
        "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- |"]
    for key in ("torch", "sb3"):
        for r in results[key]:
            lines.append(f"| {NAMES[key]} | {r['seed']} | {r['steps']:,} | {r['seconds']:.1f} | "
                         f"{r['steps'] / r['seconds']:,.0f} | {_fmt(r['rows'][-1][2])} | {r['eval']['success_rate']:.3f} | "
                         f"{r['eval']['mean_return']:.2f} | {r['load'][0]:.2f} / {r['load'][1]:.2f} |")
    for key in ("torch", "sb3"):
        runs = results[key]
        lines.append(f"| **{NAMES[key]}, all seeds** | | {sum(r['steps'] for r in runs):,} | "
                     f"{sum(r['seconds'] for r in runs):.1f} | **{throughput(runs):,.0f}** | "
                     f"{np.nanmean([r['rows'][-1][2] for r in runs]):.2f} | "
                     f"**{np.mean([r['eval']['success_rate'] for r in runs]):.3f}** | "
                     f"{np.mean([r['eval']['mean_return'] for r in runs]):.2f} | |")
    ratio = throughput(t) / throughput(s)
    pairs = [(a["steps"] / a["seconds"]) / (b["steps"] / b["seconds"]) for a, b in zip(t, s)]
    succ_t = np.mean([r["eval"]["success_rate"] for r in t])
    succ_s = np.mean([r["eval"]["success_rate"] for r in s])
    lines += ["", f"Throughput ratio, training.ppo_torch / SB3: **{ratio:.2f}** (env steps per wall second, rollouts "
                  f"and updates together; per seed pair {min(pairs):.2f} to {max(pairs):.2f}). Evaluation success, "
                  f"mean over seeds: {succ_t:.3f} (ppo_torch) and {succ_s:.3f} (SB3), ratio "
                  f"{succ_t / succ_s if succ_s > 0 else float('nan'):.2f}.", ""]
    lines += ["Where the wall time goes (all seeds; host clock): `env.step` (for SB3 through its VecEnv adapter, "
              "whose step includes the native env's), the rest of the rollouts (the policy's forward pass, the "
              f"buffers, the bookkeeping) and the updates (advantages and {kw['n_epochs']} epochs of minibatch gradient "
              "steps):", "",
              "| implementation | env.step | rest of the rollouts | updates |", "| --- | ---: | ---: | ---: |"]
    for key in ("torch", "sb3"):
        runs = results[key]
        total_s = sum(r["seconds"] for r in runs)
        env_s = sum(r["env_seconds"] for r in runs)
        upd_s = sum(r["update_seconds"] for r in runs)
        rest = total_s - env_s - upd_s
        lines.append(f"| {NAMES[key]} | {env_s:.1f} s ({100 * env_s / total_s:.0f} %) | {rest:.1f} s "
                     f"({100 * rest / total_s:.0f} %) | {upd_s:.1f} s ({100 * upd_s / total_s:.0f} %) |")
    lines.append("")
    own = [r.get("own_eval") for r in t]
    if all(own):
        lines += ["Cross-check: ppo_torch's own evaluation (`training.ppo_torch.evaluate`: the same seeds, its env made "
                  "by `gymnasium.make_vec`) gives success " + ", ".join(f"{o['success_rate']:.3f}" for o in own)
                  + " (per seed; above: " + ", ".join(f"{r['eval']['success_rate']:.3f}" for r in t) + ").", ""]
    levels = [lv for lv in (0.25, 0.5, 0.75, 0.9)
              if any(first_time_at(r["rows"], lv) is not None for r in t + s)]
    if levels:
        lines += ["Wall seconds until the training success over 100 finished episodes first reaches a level, per seed "
                  "(env steps in brackets):", "",
                  "| level | training.ppo_torch | Stable-Baselines3 PPO |", "| ---: | --- | --- |"]
        for lv in levels:
            cells = []
            for runs in (t, s):
                hits = [first_time_at(r["rows"], lv) for r in runs]
                cells.append(", ".join("not reached" if h is None else f"{h[0]:.0f} s ({h[1]:,})" for h in hits))
            lines.append(f"| {lv:.2f} | {cells[0]} | {cells[1]} |")
        lines.append("")
    lines += [
        "Reading: the two are the same algorithm with the same hyperparameters on the same env; they differ in "
        "what each does around it. The torch PPO steps the native vector env in NEXT_STEP autoreset mode (each "
        "episode end costs one masked reset step, counted in its env steps) and keeps the rollout in tensors; SB3 "
        "goes through its VecEnv adapter (a list of info dicts per step, SAME_STEP autoreset), VecMonitor and its "
        "rollout buffer in numpy. What this report does not measure: a GPU run (`--device cuda` with the env's "
        "CUDA backend), where the torch PPO keeps the env's outputs and the policy on the device and syncs "
        "with the host once per rollout. Success at a given budget differs from seed to "
        "seed within one implementation as well: read the spread of the lines, not a single figure.", ""]
    return "\n".join(lines)


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="a few thousand steps, one seed: checks the pipeline")
    ap.add_argument("--timesteps", type=int, default=None,
                    help="env steps per run (default: the config's total_timesteps, 1,000,000; --quick 4,096)")
    ap.add_argument("--seeds", type=int, nargs="+", default=None, help="seeds (default 0 1 2; --quick 0)")
    ap.add_argument("--device", default="cpu", help="training.ppo_torch's device: cpu (default), cuda or auto; "
                                                    "SB3 runs on cpu")
    ap.add_argument("--config", default=None, help=f"the training config (default {CONFIG} of this checkout)")
    ap.add_argument("--runs", default=None, help="folder of the runs (default runs/ppo_compare; --quick: temporary)")
    ap.add_argument("--out", default=None, help="the report (.md; the plot goes beside it as .png); default "
                                                "runs/reports/ppo_torch.md (--quick: a temporary directory)")
    a = ap.parse_args(argv)
    try:
        from training.train import load_config
        cfg = load_config(a.config or ROOT / CONFIG)
        if cfg["algo"] != "ppo":
            raise ValueError(f"{a.config}: algo must be ppo, got {cfg['algo']!r}")
        total = a.timesteps if a.timesteps is not None else (4096 if a.quick else cfg["total_timesteps"])
        if total < 1:
            raise ValueError(f"--timesteps must be a positive integer, got {total}")
        seeds = a.seeds if a.seeds is not None else ([0] if a.quick else [0, 1, 2])
        if any(sd < 0 for sd in seeds) or len(set(seeds)) != len(seeds):
            raise ValueError(f"--seeds must be distinct non-negative integers, got {seeds}")
        if a.device not in ("auto", "cpu", "cuda"):
            raise ValueError(f"--device must be auto, cpu or cuda, got {a.device!r}")
        if a.quick and a.out is not None:
            o = Path(a.out).resolve()
            if (ROOT / "docs") in o.parents or Path.cwd().resolve() / "docs" in o.parents:
                raise ValueError(f"--quick never writes into docs/ (got --out {a.out})")
    except ValueError as exc:
        ap.error(str(exc))
    if a.quick:
        cfg = quick_config(cfg)
    t_start = time.perf_counter()
    from studies.common import report_path
    out = report_path(a.out, a.quick, "ppo_torch.md")
    if a.runs:
        runs = Path(a.runs).resolve()
    elif a.quick:  # beside a quick report (a temporary directory unless --out) or in a new temporary directory
        runs = (Path(tempfile.mkdtemp(prefix="penny_env-quick-")) if a.out else out.parent) / "runs"
    else:
        runs = Path("runs/ppo_compare").resolve()
    out.parent.mkdir(parents=True, exist_ok=True)
    runs.mkdir(parents=True, exist_ok=True)
    print(f"runs: {runs}; report: {out}", flush=True)

    from training.episodes import run_episodes
    from training.runner import eval_seed
    results = {"torch": [], "sb3": []}
    for seed in seeds:
        c = dict(cfg, seed=seed)
        for key in ("torch", "sb3"):
            before = os.getloadavg()[0]
            if key == "torch":
                r = run_torch(c, total, runs / f"torch_seed{seed}", a.device, a.quick)
            else:
                r = run_sb3(c, total, runs / f"sb3_seed{seed}")
            r["seed"], r["load"] = seed, (before, os.getloadavg()[0])
            ep = run_episodes(cfg["env_id"], r["policy"], cfg["eval_episodes"], eval_seed(seed))
            r["eval"] = {"success_rate": float(np.mean(ep["success"])), "mean_return": float(np.mean(ep["return"])),
                         "episodes": cfg["eval_episodes"], "seed": eval_seed(seed)}
            results[key].append(r)
            print(f"[{key} seed {seed}] {r['steps']:,} steps in {r['seconds']:.1f} s: "
                  f"{r['steps'] / r['seconds']:,.0f} steps/s; evaluation success {r['eval']['success_rate']:.3f} "
                  f"over {cfg['eval_episodes']} deterministic episodes", flush=True)
    (runs / "curves.json").write_text(json.dumps(
        {k: [{kk: r[kk] for kk in ("seed", "rows", "steps", "seconds", "env_seconds", "update_seconds", "eval", "load")}
             for r in results[k]]
         for k in results}, indent=1))
    png = out.with_suffix(".png")
    plot(results, png, cfg["env_id"], total)
    out.write_text(report(results, cfg, total, argv, png, a.quick, time.perf_counter() - t_start))
    print(out.read_text())
    print(f"wrote {out}\nwrote {png}\nruns: {runs}", flush=True)
    return results


if __name__ == "__main__":
    main()
