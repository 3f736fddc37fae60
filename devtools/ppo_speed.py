"""End-to-end training throughput of the ladder's PPO (``python -m training.ppo_torch --ladder``) against
Stable-Baselines3's PPO, on the same env, in one run.

    python -m devtools.ppo_speed [--env-id PennyProbeSteer-Stadium-Elastic-v0] [--rounds 3] [--threads 2]
                                 [--ppo-steps 1048576] [--sb3-steps 65536] [--out docs/ppo_speed.md] [--quick]

Both learners train on the env with the fair reward (training/protocol.py's FAIR_REWARD: the success bonus only)
from a fresh agent with ``--threads`` torch threads (the env's numba threads: the process's default,
NUMBA_NUM_THREADS). They alternate, round after round (ladder PPO, SB3, ladder PPO, ...), so that both see the same
load of a shared machine, and print nothing while they run. One unmeasured short run of each first fills numba's
cache and loads torch's kernels.

* **ladder PPO**: ``python -m training.ppo_torch --ladder`` in a process of its own (4096 envs x 32 steps per
  rollout, 2 epochs of minibatches of 16384, gamma 0.999; the CleanRL-style loop over the native vector env,
  NEXT_STEP autoreset); env-steps/s = env steps / ppo_torch's training seconds (from the first reset to the end of
  the last update, its results.json), with the host seconds in ``env.step`` and in the updates.
* **SB3 PPO**: ``PPO("MlpPolicy")`` over penny_env/sb3.py's PennySB3VecEnv (under VecMonitor) with
  SB3_PPO (16 envs x 256 steps, minibatches of 512, 5 epochs, gamma 0.999, lambda 0.98, 64 x 64: the settings of
  the removed fair_pure_rl study, docs/ladder_archive.csv); env-steps/s = env steps / the wall seconds of ``model.learn``.

The report (``--out``, default docs/ppo_speed.md; ``--quick``: a temporary directory, never docs/) gives the
machine, date and load, every round's rates, the best and the median per learner and their ratio.
``--quick`` (tests): one round of training.ppo_torch's --quick run beside a few hundred SB3 steps, seconds.
"""
from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_ENV = "PennyProbeSteer-Stadium-Elastic-v0"
GOAL = 1.5e5  # env-steps/s end to end on 2 cores: the ladder's goal for its PPO
SB3_PPO = {"n_steps": 256, "batch_size": 512, "n_epochs": 5, "learning_rate": 3e-4, "gamma": 0.999, "gae_lambda": 0.98,
           "policy_kwargs": {"net_arch": [64, 64]}}


def run_ladder_ppo(env_id: str, steps: int, threads: int, quick: bool) -> dict:
    """One training.ppo_torch run with its ladder configuration, through its command line (a process of its own, as
    a user runs it; this tool imports no agent): its own clock, from the first reset to the end of the last update,
    read from its results.json."""
    out = Path(tempfile.mkdtemp(prefix="penny_env-ppo_speed-")) / "run"
    cmd = [sys.executable, "-m", "training.ppo_torch", "--ladder", "--env-id", env_id, "--torch-threads", str(threads),
           "--seed", "0", "--eval-episodes", "1", "--out", str(out)]
    cmd += ["--quick"] if quick else ["--total-timesteps", str(steps)]
    path = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH")) if p)
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, env=dict(os.environ, PYTHONPATH=path))
    res = json.loads((out / "results.json").read_text())
    a = json.loads((out / "config.json").read_text())
    return {"steps": res["timesteps"], "seconds": res["train_seconds"], "env_s": res["env_seconds"],
            "update_s": res["update_seconds"], "config": f"{a['num_envs']} envs x {a['num_steps']} steps, "
            f"{a['update_epochs']} epochs of minibatches of {a['minibatch_size']}, gamma {a['gamma']}"}


def run_sb3_ppo(env_id: str, steps: int, threads: int, quick: bool) -> dict:
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecMonitor

    from penny_env.sb3 import PennySB3VecEnv
    from training.protocol import fair_reward_kwargs
    torch.set_num_threads(threads)
    n_envs = 4 if quick else 16
    hyper = dict(SB3_PPO, n_steps=64, batch_size=128, n_epochs=2) if quick else dict(SB3_PPO)
    venv = VecMonitor(PennySB3VecEnv(env_id, num_envs=n_envs, **fair_reward_kwargs(env_id)))
    venv.seed(0)
    model = PPO("MlpPolicy", venv, seed=0, verbose=0, device="cpu", **hyper)
    t0 = time.perf_counter()
    model.learn(total_timesteps=steps)
    seconds = time.perf_counter() - t0
    venv.close()
    return {"steps": int(model.num_timesteps), "seconds": seconds,
            "config": f"{n_envs} envs x {hyper['n_steps']} steps, {hyper['n_epochs']} epochs of minibatches of "
                      f"{hyper['batch_size']}, gamma {hyper['gamma']}, gae_lambda {hyper['gae_lambda']}"}


LEARNERS = {"ladder PPO (training.ppo_torch)": run_ladder_ppo, "SB3 PPO": run_sb3_ppo}


def measure(env_id: str, rounds: int, threads: int, ppo_steps: int, sb3_steps: int, quick: bool) -> dict:
    import torch
    torch.set_num_threads(threads)
    budget = {"ladder PPO (training.ppo_torch)": ppo_steps, "SB3 PPO": sb3_steps}
    warm = {"ladder PPO (training.ppo_torch)": 4096, "SB3 PPO": 256}
    for name, fn in LEARNERS.items():  # unmeasured: the compiled step's load, torch's first kernels
        fn(env_id, warm[name], threads, True)
    runs = {name: [] for name in LEARNERS}
    for _ in range(rounds):
        for name, fn in LEARNERS.items():
            runs[name].append(fn(env_id, budget[name], threads, quick))
    return runs


def report(runs: dict, env_id: str, threads: int, rep) -> str:
    import numba
    lines = rep.header("PPO throughput: the ladder's PPO and SB3's PPO, side by side")
    lines += [f"- env: `{env_id}` with the fair reward (success bonus only); torch threads: {threads}; numba "
              f"threads: {numba.config.NUMBA_NUM_THREADS}; learners alternate round after round (the ladder PPO by "
              "its command line in a process of its own, SB3's in this one)", ""]
    for name, rs in runs.items():
        lines.append(f"- {name}: {rs[0]['config']}")
    lines += ["", "| round | learner | env steps | wall s | env-steps/s | env.step s | update s |",
              "| ---: | --- | ---: | ---: | ---: | ---: | ---: |"]
    rates = {name: [r["steps"] / r["seconds"] for r in rs] for name, rs in runs.items()}
    for k in range(len(next(iter(runs.values())))):
        for name, rs in runs.items():
            r = rs[k]
            extra = (f"{r['env_s']:.1f} | {r['update_s']:.1f}" if "env_s" in r else "- | -")
            lines.append(f"| {k + 1} | {name} | {r['steps']:,} | {r['seconds']:.1f} | {rates[name][k]:,.0f} | {extra} |")
    names = list(runs)
    lines += ["", "| learner | best env-steps/s | median env-steps/s |", "| --- | ---: | ---: |"]
    for name in names:
        lines.append(f"| {name} | {max(rates[name]):,.0f} | {statistics.median(rates[name]):,.0f} |")
    ratio = statistics.median(rates[names[0]]) / statistics.median(rates[names[1]])
    best = max(rates[names[0]])
    lines += ["", f"Ratio of the medians, ladder PPO / SB3 PPO: **{ratio:.1f}**. The ladder PPO's best rate is "
              f"{best:,.0f} env-steps/s, {'at or above' if best >= GOAL else 'below'} the goal of "
              f"{GOAL:,.0f} on 2 cores (with {threads} torch thread{'s' if threads != 1 else ''}; a shared machine's "
              "load, in the header, slows both learners alike)."]
    return "\n".join(lines) + "\n"


def main(argv=None):
    from lab.common import report_command

    def options(ap):
        ap.add_argument("--env-id", default=DEFAULT_ENV)
        ap.add_argument("--rounds", type=int, default=3)
        ap.add_argument("--threads", type=int, default=2, help="torch threads of both learners (default 2)")
        ap.add_argument("--ppo-steps", type=int, default=8 * 4096 * 32, help="env steps of each ladder PPO run")
        ap.add_argument("--sb3-steps", type=int, default=65536, help="env steps of each SB3 run")
    rep = report_command("devtools.ppo_speed", "ppo_speed.md", __doc__, argv, options=options, docs_default=True,
                         quick="one round of a few thousand steps (tests)")
    a = rep.args
    if a.rounds < 1 or a.threads < 1 or a.ppo_steps < 1 or a.sb3_steps < 1:
        rep.error("--rounds, --threads, --ppo-steps and --sb3-steps must be positive")
    if a.quick:
        runs = measure(a.env_id, 1, a.threads, 4096, 512, True)
    else:
        runs = measure(a.env_id, a.rounds, a.threads, a.ppo_steps, a.sb3_steps, False)
    text = report(runs, a.env_id, a.threads, rep)
    rep.write(text, echo=True)
    return text


if __name__ == "__main__":
    main()
