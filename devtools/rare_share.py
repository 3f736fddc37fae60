"""The share of env-steps that need the rare path (the GPU's rare kernel; the event loop on the CPU), per id.

    python -m devtools.rare_share [--ids ID ...] [--n 4096] [--warmup 300] [--steps 200]
                                  [--policies DIR] [--train-policies DIR] [--before TREE] [--out FILE] [--quick]

A step of one env takes the fast path (backends/env.fast_step_env on CUDA; run_interval's single flow on the CPU)
where it has no pending NEXT_STEP reset, its action is finite and the impact-free certificate
(physics/scalar.period_is_free) passes; every other env-step goes to the rare path (the rare kernel on CUDA, the
event loop on the CPU). The decision depends on the state and the action only, so this CPU command measures it
exactly as the GPU makes it: before each step of a compiled CPU PennyVectorEnv (NEXT_STEP autoreset) it evaluates
the compiled certificate on every env's state and action, and after the step reads which envs had an impact.

Two windows per id: fresh (the first ``--fresh`` steps after a reset with seed 0) and steady (``--steps`` steps after
``--warmup`` >= 300 steps). Two policies: random actions (uniform in the action box, seeded) and a trained policy
(``--policies DIR``: DIR/<env_id>/model.pt of a training.ppo_torch run, its actions sampled as in a training rollout,
noise seeded; ``--train-policies DIR`` first trains them, a quick PPO per id). Columns: the rare share, split into
resets (a pending NEXT_STEP reset), periods with an impact, and certificate failures without an impact (periods
the event loop finished without one: the certificate's waste).

``--before TREE`` runs the same measurement in TREE too (a subprocess importing TREE's penny_env) and reports both,
side by side (the state sequence is the same in both trees where the motion is bitwise the same: the certificate
only decides which path integrates a period). ``--quick``: 64 envs, short windows, two ids (tests).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

IDS = ("PennyReach-Ellipse-v0", "PennyImpacts-Stadium-v0", "PennyProbeSteer-Stadium-Elastic-v0", "PennyPark-Circle-v0")
QUICK_IDS = ("PennyReach-Ellipse-v0", "PennyProbeSteer-Stadium-Elastic-v0")
POLICY_STEPS = 1_000_000


def certifier(kind: int):
    """A compiled loop: ok[i] = the certificate of env i (state S[:, i], heading trig[2:4, i], torques acc1[i], acc2[i])."""
    import numba

    from penny_env.backends.physics import physics_build
    pif = physics_build("cpu", kind).functions["period_is_free"]

    @numba.njit(cache=False)
    def certify(S, trig, acc1, acc2, dt, m, ok):
        for i in range(S.shape[1]):
            s = (S[0, i], S[1, i], S[2, i], S[3, i], S[4, i], S[5, i])
            ok[i] = pif(s, trig[2, i], trig[3, i], acc1[i], acc2[i], dt, m)
    return certify


def torques(actions, p):
    """functional.actuate over envs (numpy, the same operations): (acc1, acc2)."""
    import numpy as np
    a = np.clip(np.asarray(actions, dtype=np.float64).reshape(actions.shape[0], -1), -1.0, 1.0)
    z = np.zeros(a.shape[0])
    if p.n_act == 2:
        return a[:, 0] * p.gain1, a[:, 1] * p.gain2
    return (a[:, 0] * p.gain1, z) if p.steer_only else (z, a[:, 0] * p.gain2)


def load_mean(model_dir):
    """(the network of the actions' mean, the log std) of a training.ppo_torch run folder, rebuilt from the shapes
    its model.pt (the agent's state dict) holds: linear layers with tanh between them, CleanRL's MLP (this tool
    imports no agent)."""
    import torch
    state = torch.load(os.path.join(model_dir, "model.pt"), map_location="cpu")
    idx = sorted({int(k.split(".")[1]) for k in state if k.startswith("actor_mean.")})
    layers = []
    for i in idx:
        w = state[f"actor_mean.{i}.weight"]
        layers += [torch.nn.Linear(w.shape[1], w.shape[0]), torch.nn.Tanh()]
        with torch.no_grad():
            layers[-2].weight.copy_(w)
            layers[-2].bias.copy_(state[f"actor_mean.{i}.bias"])
    return torch.nn.Sequential(*layers[:-1]), state["actor_logstd"]


class Policy:
    """Actions for the vector env: random (uniform, seeded) or a trained ppo_torch agent, sampled with seeded noise."""

    def __init__(self, env, model_dir=None, seed=1):
        import numpy as np
        self.rng = np.random.default_rng(seed)
        self.shape = (env.num_envs, env.single_action_space.shape[0])
        self.mean = None
        if model_dir is not None:
            import torch
            torch.set_num_threads(1)
            self.mean, self.log_std = load_mean(model_dir)
            self.torch = torch

    def __call__(self, obs):
        if self.mean is None:
            return self.rng.uniform(-1.0, 1.0, self.shape)
        torch = self.torch
        with torch.no_grad():
            mean = self.mean(torch.as_tensor(obs, dtype=torch.float32)).numpy().astype(float)
            std = torch.exp(self.log_std).numpy().astype(float)
        return mean + std * self.rng.standard_normal(self.shape)


def measure(env_id: str, n: int, fresh: int, warmup: int, steps: int, model_dir=None) -> dict:
    """{"fresh": counts, "steady": counts} of env_id's vector env (CPU) under the policy."""
    import gymnasium as gym
    import numpy as np

    import penny_env  # noqa: F401
    env = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point")
    u = env.unwrapped
    p, m = u._p, u._m
    certify = None if p.plane else certifier(m.kind)
    policy = Policy(env, model_dir)
    obs, _ = env.reset(seed=0)
    ok = np.ones(n, dtype=bool)
    windows = {"fresh": (0, fresh), "steady": (warmup, warmup + steps)}
    out = {name: {"env_steps": 0, "rare": 0, "reset": 0, "impact": 0, "waste": 0} for name in windows}
    for t in range(warmup + steps):
        a = policy(obs)
        name = next((k for k, (lo, hi) in windows.items() if lo <= t < hi), None)
        if name is not None:
            st = u._runner.st if hasattr(u, "_runner") else u._st  # (this tree's runner; the state itself before it)
            pending = st.pending.copy()
            if certify is not None:
                acc1, acc2 = torques(a, p)
                certify(st.S, st.trig, acc1, acc2, p.dt, m, ok)
        obs, _, _, _, info = env.step(a)
        if name is not None:
            impact = (np.asarray(info["impacts"]) > 0) & ~pending
            failed = ~ok & ~pending
            c = out[name]
            c["env_steps"] += n
            c["reset"] += int(pending.sum())
            c["rare"] += int((pending | failed).sum())
            c["impact"] += int((failed & impact).sum())
            c["waste"] += int((failed & ~impact).sum())
            if (impact & ok).any():
                raise AssertionError(f"{env_id}: an env with an impact in a period its certificate passed")
    env.close()
    return out


def worker(args) -> dict:
    import penny_env
    res = {"penny_env": os.path.dirname(penny_env.__file__), "ids": {}}
    for env_id in args.ids:
        res["ids"][env_id] = {}
        for pol in args.policy_kinds:
            model = None
            if pol == "trained":
                model = os.path.join(args.policies, env_id)
                if not os.path.exists(os.path.join(model, "model.pt")):
                    continue
            t0 = time.perf_counter()
            res["ids"][env_id][pol] = measure(env_id, args.n, args.fresh, args.warmup, args.steps, model)
            print(f"  {env_id} {pol}: {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    return res


def train_policies(ids, folder, steps, quick) -> None:
    """A quick PPO per id into folder/<env_id>: training.ppo_torch's command line (CPU; 64 envs x 64 steps,
    minibatches of 1024, 4 epochs), as a user runs it."""
    import tempfile

    import yaml
    for env_id in ids:
        out = os.path.join(folder, env_id)
        if os.path.exists(os.path.join(out, "model.pt")):
            continue
        with tempfile.TemporaryDirectory() as tmp:
            config = os.path.join(tmp, "ppo.yaml")
            with open(config, "w") as f:
                yaml.safe_dump({"env_id": env_id, "algo": "ppo", "num_envs": 64, "total_timesteps": 4096 if quick
                                else steps, "eval_episodes": 8 if quick else 100,
                                "algo_kwargs": {"n_steps": 64, "batch_size": 1024, "n_epochs": 4}}, f)
            here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
            path = os.pathsep.join(p for p in (here, os.environ.get("PYTHONPATH")) if p)
            subprocess.run([sys.executable, "-m", "training.ppo_torch", "--config", config, "--device", "cpu", "--out",
                            out], check=True, stdout=subprocess.DEVNULL, env=dict(os.environ, PYTHONPATH=path))
        with open(os.path.join(out, "results.json")) as f:
            ev = json.load(f).get("eval") or {}
        print(f"trained {env_id}: evaluation success {ev.get('success_rate')}", flush=True)


def run_tree(tree: str, args) -> dict:
    """The measurement in a subprocess importing ``tree``'s penny_env (this file run as a script)."""
    cmd = [sys.executable, os.path.abspath(__file__), "--worker", "--n", str(args.n), "--fresh", str(args.fresh),
           "--warmup", str(args.warmup), "--steps", str(args.steps), "--ids", *args.ids,
           "--policy-kinds", *args.policy_kinds]
    if args.policies:
        cmd += ["--policies", os.path.abspath(args.policies)]
    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([os.path.abspath(tree), here]))
    r = subprocess.run(cmd, cwd=tree, env=env, capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"rare_share in {tree} failed:\n{r.stderr[-3000:]}")
    sys.stderr.write(r.stderr)
    return json.loads(r.stdout.strip().splitlines()[-1])


def pct(c, key):
    return 100.0 * c[key] / c["env_steps"] if c["env_steps"] else float("nan")


def _options(ap) -> None:
    ap.add_argument("--ids", nargs="+", default=None)
    ap.add_argument("--n", type=int, default=4096)
    ap.add_argument("--fresh", type=int, default=20, help="steps of the fresh window (from the reset)")
    ap.add_argument("--warmup", type=int, default=300, help="steps before the steady window (at least 300)")
    ap.add_argument("--steps", type=int, default=200, help="steps of the steady window")
    ap.add_argument("--policies", default=None, help="DIR with DIR/<env_id>/model.pt (training.ppo_torch runs)")
    ap.add_argument("--train-policies", default=None, metavar="DIR", help="train the policies into DIR first")
    ap.add_argument("--policy-steps", type=int, default=POLICY_STEPS, help="env steps of each quick PPO")
    ap.add_argument("--policy-kinds", nargs="+", default=["random", "trained"], choices=["random", "trained"])
    ap.add_argument("--before", default=None, metavar="TREE", help="also measure TREE (its own penny_env)")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if "--worker" in argv:  # (run in each tree measured)
        ap = argparse.ArgumentParser()
        ap.add_argument("--quick", action="store_true")
        _options(ap)
        a, rep = ap.parse_args(argv), None
    else:
        from lab.common import report_command
        rep = report_command("devtools.rare_share", "rare_share.md", __doc__.splitlines()[0], argv, options=_options,
                             quick="64 envs, short windows, two ids (tests)")
        a = rep.args
    if a.quick:
        a.n, a.fresh, a.warmup, a.steps = min(a.n, 64), 5, 300 if a.warmup >= 300 else a.warmup, 10
    a.ids = a.ids or list(QUICK_IDS if a.quick else IDS)
    if rep is None:
        print(json.dumps(worker(a)))
        return 0
    if a.warmup < 300 and not a.quick:
        rep.error("--warmup must be at least 300 (the steady window)")
    if a.train_policies:
        a.policies = a.train_policies
        train_policies(a.ids, a.train_policies, a.policy_steps, a.quick)
    if a.policies is None:
        a.policy_kinds = [k for k in a.policy_kinds if k != "trained"]
    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    trees = ([("before", a.before)] if a.before else []) + [("after" if a.before else "this tree", here)]
    results = {label: run_tree(tree, a) for label, tree in trees}
    rep.write(rare_report(a, rep, results, trees), echo=True)
    return 0


def rare_report(a, rep, results, trees) -> list:
    lines = rep.header("The share of env-steps on the rare path")
    lines += [f"Trees: {', '.join(f'{label} = {tree}' for label, tree in trees)}. N = {a.n} envs (CPU backend, NEXT_STEP), "
              f"fresh window: steps 0-{a.fresh - 1} after reset(seed=0); steady window: steps {a.warmup}-"
              f"{a.warmup + a.steps - 1}. Shares of env-steps, in %: rare (all), of which a pending reset, a period "
              "with an impact, and a certificate failure without an impact (the event loop found none).", "",
              "| id | policy | window | tree | rare | reset | impact | no impact (waste) |",
              "|---|---|---|---|---:|---:|---:|---:|"]
    for env_id in a.ids:
        for pol in a.policy_kinds:
            for window in ("fresh", "steady"):
                for label, _ in trees:
                    c = results[label]["ids"].get(env_id, {}).get(pol, {}).get(window)
                    if c is None:
                        continue
                    lines.append(f"| {env_id} | {pol} | {window} | {label} | {pct(c, 'rare'):.2f} | {pct(c, 'reset'):.2f} "
                                 f"| {pct(c, 'impact'):.2f} | {pct(c, 'waste'):.2f} |")
    return lines


if __name__ == "__main__":
    raise SystemExit(main())
