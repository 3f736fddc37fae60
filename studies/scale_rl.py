"""Pure PPO at scale on the single-input probes: evaluation success against samples, beside the witnessed rate.

    python -m studies.scale_rl [--cells Steer:stadium:elastic Drive:ellipse:plastic] [--steps 100000000]
                                [--seeds 2] [--num-envs 8192] [--num-steps 32] [--curve-points 10]
                                [--eval-episodes 200] [--device auto] [--env-backend cuda] [--quick] [--out REPORT.md]

The question: does pure RL learn the single-input probes when it gets GPU-scale experience? At
CPU budgets it did not (docs/fair_pure_rl.md: steer park 0/400 at 2M PPO steps per seed). Each cell (probe,
table, law: training/witness_study.cell_spec gives its env id and field overrides) trains training/ppo_torch.py's
PPO with fair_pure_rl's reward (``REWARD``: the success bonus only, so that going to the wall first costs
nothing) and gamma 0.999 (GAE lambda 0.98), for ``--steps`` env steps per seed, on the device asked for (on a GPU:
the env's state on the device and each rollout replayed from a CUDA graph). At ``--curve-points`` log-spaced
sample counts the deterministic policy runs one episode on each of the witness study's pair seeds 0 .. E-1
(``--eval-episodes``); the report gives, per cell and point, the success rate pooled over seeds with its
interval (clustered by seed where there are several seeds: studies/stats.seed_clustered_ci; else exact
Clopper-Pearson, honest at 0 and 1), beside the witnessed rate of that cell (docs/witnesses.csv: the certified
witnesses of studies/witness_study.py on the same pair seeds), and plots success against samples on a log axis.

Output: the report (``--out``, default runs/scale_rl/scale_rl.md; --quick without --out: a new temporary
directory), its CSV (one row per cell, seed and point) and figure (matplotlib, the ``plot`` extra) beside it, and
each run's ppo_torch folder under runs/ (or the temporary directory). ``--quick`` trains a few thousand steps on
the CPU (the tests run it); it never writes into docs/.
"""
from __future__ import annotations

import argparse
import csv
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from studies.fair_pure_rl import GAMMA, REWARD, reward_fields
from studies.stats import clopper_pearson, seed_clustered_ci

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_CELLS = ("Steer:stadium:elastic", "Steer:ellipse:elastic", "Drive:ellipse:plastic", "Drive:ellipse:0.5")
QUICK_CELLS = ("Steer:stadium:elastic", "Drive:ellipse:plastic")
CSV_COLUMNS = ["probe", "table", "law", "env_id", "seed", "global_step", "train_seconds", "successes", "episodes",
               "success_rate"]


def parse_cell(text: str) -> tuple[str, str, str]:
    """'Steer:stadium:elastic' -> ("Steer", "stadium", "elastic") (the witness study's cell names)."""
    from studies.cells import LAWS, PROBE_TASKS as PROBES, TABLES
    parts = text.split(":")
    if len(parts) != 3 or parts[0] not in PROBES or parts[1] not in TABLES or parts[2] not in LAWS:
        raise ValueError(f"cell must be PROBE:TABLE:LAW with PROBE in {list(PROBES)}, TABLE in {list(TABLES)}, LAW in "
                         f"{list(LAWS)}, got {text!r}")
    return parts[0], parts[1], parts[2]


def witnessed_rates(path=ROOT / "docs" / "witnesses.csv") -> dict:
    """(probe, table, law) -> (witnessed, pairs) from the witness study's committed table."""
    out = {}
    if Path(path).exists():
        with open(path) as f:
            for row in csv.DictReader(f):
                out[(row["probe"], row["table"], row["law"])] = (int(row["witnessed"]), int(row["pairs"]))
    return out


def ppo_args(cell, seed: int, a, out: Path):
    """training.ppo_torch's Args of one cell and seed."""
    from training.ppo_torch import Args
    from studies.cells import cell_spec
    env_id, overrides = cell_spec(*cell)
    return Args(env_id=env_id, env_kwargs={**overrides, **reward_fields(env_id, overrides)}, num_envs=a.num_envs,
                total_timesteps=a.steps, cuda_graph=None if a.cuda_graph is None else a.cuda_graph == "on",
                seed=seed, device=a.device, env_backend=a.env_backend, num_steps=a.num_steps,
                minibatch_size=a.minibatch_size, update_epochs=a.update_epochs, gamma=GAMMA, gae_lambda=0.98,
                eval_episodes=a.eval_episodes, curve_points=a.curve_points, quick=False,
                out=str(out / f"{env_id}_{'_'.join(cell)}_{seed}"))


def run(a, log=print, after_each=None) -> list[dict]:
    """Train every cell and seed; rows of CSV_COLUMNS (one per cell, seed and evaluation point). after_each(rows)
    is called after each run (the report so far: a run cut short by a time limit keeps the cells done)."""
    from training.ppo_torch import check_args, train_agent
    rows = []
    for text in a.cells:
        cell = parse_cell(text)
        for seed in range(a.seeds):
            args = ppo_args(cell, seed, a, a.runs)
            check_args(args)
            t0 = time.perf_counter()
            _, res = train_agent(args, log=log if a.verbose else None)
            log(f"[scale_rl] {text} seed {seed}: {res['timesteps']:,} steps in {res['train_seconds']:.0f} s "
                f"({res['steps_per_s']:,.0f} steps/s on {res['device']}), final success "
                f"{res['curve'][-1]['success_rate'] if res['curve'] else float('nan'):.3f} "
                f"({time.perf_counter() - t0:.0f} s with evaluations)")
            for point in res["curve"]:
                k = int(round(point["success_rate"] * point["episodes"]))
                rows.append({"probe": cell[0], "table": cell[1], "law": cell[2], "env_id": args.env_id, "seed": seed,
                             "global_step": point["global_step"], "train_seconds": round(point["wall_time_s"], 1),
                             "successes": k, "episodes": point["episodes"], "success_rate": point["success_rate"]})
            if after_each is not None:
                after_each(rows)
    return rows


def summarise(rows) -> list[dict]:
    """Per cell and evaluation point (the seeds' i-th points): pooled successes and the interval."""
    out = []
    cells = dict.fromkeys((r["probe"], r["table"], r["law"]) for r in rows)
    for cell in cells:
        mine = [r for r in rows if (r["probe"], r["table"], r["law"]) == cell]
        seeds = sorted({r["seed"] for r in mine})
        per_seed = [[r for r in mine if r["seed"] == s] for s in seeds]
        for j in range(min(len(p) for p in per_seed)):
            pts = [p[j] for p in per_seed]
            k, n = sum(p["successes"] for p in pts), sum(p["episodes"] for p in pts)
            if len(pts) > 1:
                M = np.array([[1] * p["successes"] + [0] * (p["episodes"] - p["successes"]) for p in pts], dtype=float)
                lo, hi = seed_clustered_ci(M)
            else:
                lo, hi = clopper_pearson(k, n)
            out.append({"cell": cell, "global_step": int(np.mean([p["global_step"] for p in pts])), "successes": k,
                        "episodes": n, "rate": k / n, "lo": lo, "hi": hi,
                        "seed_successes": " ".join(str(p["successes"]) for p in pts)})
    return out


def write_report(a, rows, seconds: float) -> Path:
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    csv_path = out.with_suffix(".csv")
    with open(csv_path, "w", newline="") as f:
        w = csv.DictWriter(f, CSV_COLUMNS)
        w.writeheader()
        w.writerows(rows)
    summary = summarise(rows)
    wit = witnessed_rates()
    fig = plot(summary, wit, out.with_suffix(".png"))
    from studies.common import header
    done = list(dict.fromkeys(" ".join(r["cell"]) for r in summary))
    lines = header("Pure PPO at scale on the single-input probes", "studies.scale_rl", a.argv)
    lines += [f"- device: {a.machine}", "",
             f"{len(done)} of {len(a.cells)} cells done" + ("" if len(done) == len(a.cells) else
                                                          " (the others had not finished when this was written)") +
             f"; {a.seeds} seeds x {a.steps:,} env steps, {a.num_envs} envs x {a.num_steps} steps per rollout, minibatches of "
             f"{a.minibatch_size}, {a.update_epochs} epochs; {seconds / 60:.1f} minutes in all. Reward: fair_pure_rl's "
             f"(the success bonus only: {REWARD}), gamma {GAMMA}, GAE lambda 0.98. Evaluation: the deterministic policy, "
             f"one episode on each of the witness study's pair seeds 0 .. {a.eval_episodes - 1}, at log-spaced sample "
             "counts. Interval: clustered by seed over the seeds (studies/stats.seed_clustered_ci), exact "
             "Clopper-Pearson with one seed. Witnessed: the certified witnesses on the same seeds (docs/witnesses.csv).",
             "", "| cell | env steps (per seed) | successes (per seed) | success rate [95 % CI] | witnessed | ratio |",
             "|---|---:|---|---|---|---:|"]
    for r in summary:
        w = wit.get(r["cell"])
        wr = w[0] / w[1] if w else float("nan")
        lines.append(f"| {' '.join(r['cell'])} | {r['global_step']:,} | {r['seed_successes']} of {a.eval_episodes} | "
                     f"{r['rate']:.3f} [{r['lo']:.3f}, {r['hi']:.3f}] | "
                     f"{f'{w[0]}/{w[1]}' if w else 'n/a'} | {r['rate'] / wr if w and wr else float('nan'):.2f} |")
    lines += ["", f"Per seed and point: [{csv_path.name}]({csv_path.name})."]
    if fig:
        lines += ["", f"![success against samples]({Path(fig).name})"]
    out.write_text("\n".join(lines) + "\n")
    return out


def plot(summary, wit, path) -> str | None:
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    cells = list(dict.fromkeys(r["cell"] for r in summary))
    fig, ax = plt.subplots(figsize=(7, 4))
    for j, cell in enumerate(cells):
        pts = [r for r in summary if r["cell"] == cell]
        x = [p["global_step"] for p in pts]
        line = ax.plot(x, [p["rate"] for p in pts], marker="o", label=" ".join(cell))[0]
        ax.fill_between(x, [p["lo"] for p in pts], [p["hi"] for p in pts], color=line.get_color(), alpha=0.15)
        if cell in wit:
            w = wit[cell]
            ax.axhline(w[0] / w[1], color=line.get_color(), ls="--", lw=1)
    ax.set_xscale("log")
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel("env steps per seed")
    ax.set_ylabel("evaluation success (dashed: witnessed)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return str(path)


def parse(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cells", nargs="+", default=None, help=f"PROBE:TABLE:LAW cells (default {' '.join(DEFAULT_CELLS)})")
    ap.add_argument("--steps", type=float, default=1e8, help="env steps per seed (default 1e8)")
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--num-envs", type=int, default=8192)
    ap.add_argument("--num-steps", type=int, default=32)
    ap.add_argument("--minibatch-size", type=int, default=65536)
    ap.add_argument("--update-epochs", type=int, default=4)
    ap.add_argument("--curve-points", type=int, default=10)
    ap.add_argument("--eval-episodes", type=int, default=200)
    ap.add_argument("--device", default="auto")
    ap.add_argument("--env-backend", default=None, help="the vector env's backend (cuda on a GPU: the default there)")
    ap.add_argument("--cuda-graph", default=None, choices=["on", "off"],
                    help="replay each rollout from a CUDA graph (default off: eager rollouts, as training.ppo_torch)")
    ap.add_argument("--quick", action="store_true", help="a few thousand CPU steps per cell (checks the pipeline)")
    ap.add_argument("--verbose", action="store_true", help="ppo_torch's progress lines")
    ap.add_argument("--out", default=None, help="the report (default runs/scale_rl/scale_rl.md; --quick: a temp dir)")
    a = ap.parse_args(argv)
    a.argv = list(argv if argv is not None else __import__("sys").argv[1:])
    if a.cells is None:
        a.cells = list(QUICK_CELLS if a.quick else DEFAULT_CELLS)
    for text in a.cells:
        try:
            parse_cell(text)
        except ValueError as exc:
            ap.error(str(exc))
    if a.quick:
        a.steps, a.seeds, a.num_envs, a.num_steps, a.minibatch_size, a.update_epochs = 2048, 1, 16, 32, 256, 1
        a.curve_points, a.eval_episodes = 2, min(a.eval_episodes, 4)
    a.steps = int(a.steps)
    for name in ("steps", "seeds", "num_envs", "num_steps", "minibatch_size", "update_epochs", "curve_points",
                 "eval_episodes"):
        if getattr(a, name) < 1:
            ap.error(f"--{name.replace('_', '-')} must be a positive integer, got {getattr(a, name)}")
    import torch
    if a.env_backend is None and a.device in ("auto", "cuda") and torch.cuda.is_available():
        a.env_backend = "cuda"
    on_gpu = a.device in ("auto", "cuda") and torch.cuda.is_available()
    a.machine = (f"cuda ({torch.cuda.get_device_name(0)}), env backend {a.env_backend}" if on_gpu else
                 f"cpu ({platform.processor() or platform.machine()}), env backend {a.env_backend or 'auto'}")
    if a.quick and Path(a.out or "runs").resolve().is_relative_to(ROOT / "docs"):
        ap.error("--quick never writes into docs/: give --out a path outside it")
    if a.out is None:
        base = Path(tempfile.mkdtemp(prefix="penny_env-scale-rl-quick-")) if a.quick else Path("runs") / "scale_rl"
        a.out = str(base / "scale_rl.md")
    a.runs = Path(a.out).parent / "runs" if a.quick else Path("runs") / "scale_rl"
    return a


def main(argv=None) -> int:
    a = parse(argv)
    t0 = time.perf_counter()
    rows = run(a, after_each=lambda so_far: write_report(a, so_far, time.perf_counter() - t0))
    out = write_report(a, rows, time.perf_counter() - t0)
    print(f"[scale_rl] report: {out}")
    return 0



if __name__ == "__main__":
    raise SystemExit(main())
