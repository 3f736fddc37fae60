"""A fair chance for learned agents on the single-input probes: imitation of the certified
witnesses (studies/witness.py), behaviour cloning then DAgger, evaluated on held-out seeds beside the witness.

    python -m studies.fair_rl [--quick] [--out docs/fair_rl.md] [--cells Steer:ellipse:elastic ...]
                               [--demos N] [--rounds R] [--eval-episodes E] [--workers 1]

Per cell (probe, table, law; env id and overrides from training/witness_study.cell_spec):

1. **Demonstrations.** The witness of each training seed (seeds TRAIN_SEED + i, disjoint from the evaluation
   and validation seeds) is searched and certified exactly as in studies/witness.py, and its episode in the
   package's env is recorded as (observation, action) pairs; only certified (successful) episodes are kept.
2. **Behaviour cloning** (round 0): a torch MLP (2 x 256, tanh output) maps the env's observation to the
   action, trained by mean squared error on the standardised observations.
3. **DAgger** (rounds 1..R, Ross et al. 2011): the current policy drives episodes on fresh training seeds
   (round 1 mixes in the expert's action with probability BETA); every state it visits is labelled by the
   expert, the witness family re-searched from that exact state with the steps the episode has left
   (at the start of an episode, after every impact and every REPLAN steps; in between the chosen controller
   keeps acting along the learner's own trajectory, its memory updated at impacts). The data are aggregated
   and the policy retrained. After each round the policy's success on VAL episodes (validation seeds) makes the
   curve that shows whether the rounds flatten; the cap is R rounds.
4. **Evaluation.** The final policy (and the round-0 BC policy) run E episodes of ``gymnasium.make(id,
   **overrides)`` with the probe's own time limit, reset with seeds 0 .. E-1 (the witness study's pair
   seeds); success is ``info["is_success"]``. The witness is certified on the same seeds in this run, and
   the goal of the issue is met where the agent's rate is at least half the witnessed rate.

Why the observation suffices: the env's observation (PennyEnv docstring) holds the whole state (x, y,
cos/sin theta, cos/sin phi, theta_dot, phi_dot; theta enters no law) and the target. The expert used in
DAgger re-plans from the exact state, so it is a function of the state (between re-plans, of the state
and the plan chosen); the learner sees the same state through the observation (velocities as tanh of
scaled values, standardised before the MLP). No frame stack is needed: the witness's memory (the mode:
"after a slow impact" for steer, "turning" for drive) is readable from theta_dot resp. phi_dot, which
change only at impacts (theorems T2.1 / T3.1 of docs/controllability_theory.md).

Discount and horizon: imitation has no discount; the horizon is the probe's own time limit (steer park
400 steps = 20 s, drive reach 200 steps = 10 s), the one the witnesses are certified within. The loss
does not punish walls (there is no reward in it): the expert goes to the wall first and the learner is
taught to. --quick: two small cells, a few demos, a few hundred gradient steps, a few episodes, into a
temporary folder (never docs/).
"""
from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from pathlib import Path

import numpy as np

from penny_env.step.tasks.park import rest_speed
from studies.stats import clopper_pearson
from studies.witness import V_SWITCH, Witness, positive_int
from studies.cells import LAWS, PROBE_TASKS, TABLE_NAMES, cell_spec

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
TRAIN_SEED = 100_000  # demonstrations and DAgger episodes: seeds TRAIN_SEED + i
VAL_SEED = 50_000  # the curve's validation episodes
BETA = 0.5  # round 1: the expert's action is executed with this probability (later rounds: the learner's)
REPLAN = 10  # steps between the expert's re-plans (besides the episode's start and every impact)
DEFAULT_CELLS = (("Steer", "ellipse", "elastic"), ("Steer", "stadium", "elastic"),
                 ("Drive", "ellipse", "elastic"), ("Drive", "ellipse", "plastic"), ("Drive", "ellipse", "0.5"))
QUICK_CELLS = (("Steer", "stadium", "elastic"), ("Drive", "ellipse", "elastic"))
SINGLE_INPUT = ("Steer", "Drive")
FULL = {"demos": 100, "rounds": 3, "dagger_episodes": 25, "grad_steps": 3000, "val_episodes": 20,
        "eval_episodes": 200}
QUICK = {"demos": 3, "rounds": 1, "dagger_episodes": 1, "grad_steps": 200, "val_episodes": 2, "eval_episodes": 3}
HIDDEN = 256
BATCH = 512
LR = 1e-3
FIELDS = ["probe", "table", "law", "env_id", "overrides", "agent", "episodes", "success", "rate", "ci_low",
          "ci_high", "witnessed", "witness_rate", "ratio", "goal_met", "samples", "train_s"]


# -- the expert: the witness family, re-planned from any state -----------------------------------------
class Expert:
    """The cell's witness family (studies/witness.py) searched from an arbitrary exact state with the steps
    left. :meth:`outcomes` runs every candidate to its end (success per candidate); :meth:`plan` returns the
    one-row controller of the best-ranked successful candidate (None where none succeeds). The ranking (set
    by :meth:`rank`: the candidates' success rates from the training seeds' starts, best first) makes the
    expert's choice consistent from state to state, which the learner can imitate; the witness of
    studies/witness.py takes the candidate that succeeds soonest instead."""

    def __init__(self, probe, table, law):
        self.cell = (probe, table, law)
        self.env_id, self.overrides = cell_spec(probe, table, law)
        self.w = Witness(self.env_id, self.overrides)
        self.core, self.family, self.cands = self.w.core, self.w.family, self.w.cands
        self.max_steps = self.w.max_steps
        self.v_switch = V_SWITCH * rest_speed(self.core.task)
        self.order = np.arange(len(self.cands))  # candidate indices, preferred first

    def close(self):
        self.w.close()

    def controller(self, params, S):
        """The family's controller for rows params, its memory set from the state rows S (the witness's
        modes are functions of the state: steer 'after a slow impact' <=> |R theta_dot| < v_switch, theta_dot
        changing only at impacts; drive 'tracking' <=> |phi_dot| > w_min, phi_dot changing only at impacts)."""
        ctrl = self.family(self.core, params)
        if self.family.__name__ == "SteerPark":
            ctrl.mode = np.where(np.abs(self.core.R * S[:, 4]) < self.v_switch, 2, 0)
        elif self.family.__name__ == "DriveReach":
            ctrl.mode = np.where(np.abs(S[:, 5]) > np.maximum(ctrl.w_min, 1e-6), 1, 0)
        return ctrl

    def outcomes(self, state, target, remaining):
        """(K,) bool: which candidates, started (memory from the state) at this exact state, succeed within
        `remaining` steps; None where the vector env's reset refuses the state (an end on the wall within
        round-off)."""
        vec = self.w.vec.unwrapped if hasattr(self.w.vec, "unwrapped") else self.w.vec
        K = len(self.cands)
        S0 = np.tile(state, (K, 1))
        try:
            vec.reset(options={"state": S0, "target": np.tile(target, (K, 1))})
        except ValueError:
            return None
        ctrl = self.controller(self.cands, S0)
        impacts = np.zeros(K, np.int64)
        done = np.zeros(K, bool)
        succ = np.zeros(K, bool)
        for _ in range(remaining):
            acts = ctrl(vec.states, vec.targets, impacts)
            _, _, term, trunc, info = vec.step(acts)
            impacts = np.asarray(info["impacts"])
            succ |= term & ~done
            done |= term | trunc
            if done.all():
                break
        return succ

    def rank(self, successes):
        """Set the preference order from rows of outcomes (success rate per candidate, best first)."""
        rate = np.mean(successes, axis=0)
        self.order = np.argsort(-rate, kind="stable")

    def choose(self, succ):
        """The best-ranked successful candidate's index, or None."""
        if succ is None or not succ.any():
            return None
        return int(self.order[np.argmax(succ[self.order])])


# -- episodes -----------------------------------------------------------------------------------------
def episode(expert: Expert, seed: int, decide, act=None, beta=1.0, rng=None, label=True):
    """One episode of the cell's env from reset(seed). At the start and after every impact (the decision
    points) decide(obs, state, target, t) returns a candidate index (or None: keep the controller) and the
    family's controller of that candidate acts until the next decision point. act (obs -> action, the flat
    learner) drives instead with probability 1 - beta. Returns (obs per step, expert action per step where
    label, success, decision points, [(obs, outcomes)] recorded by decide)."""
    env = expert.w.env
    u = env.unwrapped
    o, _ = env.reset(seed=seed)
    ctrl, impacts = None, np.zeros(1, np.int64)
    obs_l, lab_l = [], []
    n_dec = 0
    info = {"is_success": False}
    for t in range(expert.max_steps):
        if ctrl is None or impacts[0] > 0:
            idx = decide(o, u.state.copy(), u.target.copy(), t)
            n_dec += 1
            if idx is not None:
                ctrl, impacts = expert.controller(expert.cands[idx:idx + 1], u.state[None, :]), np.zeros(1, np.int64)
        a_exp = ctrl(u.state[None, :], u.target[None, :], impacts)[0] if ctrl is not None else None
        if label and a_exp is not None:
            obs_l.append(o)
            lab_l.append(np.asarray(a_exp, np.float32))
        if a_exp is None:
            a = act(o[None, :])[0] if act is not None else np.zeros(expert.core.n_act)
        elif act is not None and rng.random() >= beta:
            a = act(o[None, :])[0]
        else:
            a = a_exp
        o, _, term, trunc, info = env.step(a)
        impacts = np.array([info["impacts"]], np.int64)
        if term or trunc:
            break
    return obs_l, lab_l, bool(info["is_success"]), n_dec


class Recorder:
    """decide() of the expert that records (obs, outcomes) at every decision point (the option learner's data)."""

    def __init__(self, expert, chooser=None):
        self.expert, self.chooser = expert, chooser
        self.X, self.Y = [], []

    def __call__(self, o, state, target, t):
        succ = self.expert.outcomes(state, target, self.expert.max_steps - t)
        if succ is not None:
            self.X.append(np.asarray(o, np.float32))
            self.Y.append(succ.astype(np.float32))
        if self.chooser is not None:  # the option learner acts; the outcomes only label its state
            return self.chooser(o, state, target, t)
        return self.expert.choose(succ)


# -- the learners -------------------------------------------------------------------------------------
class MLP:
    """A 2 x HIDDEN tanh MLP on standardised inputs: torch to train, numpy to act."""

    def __init__(self, obs_dim, out_dim, seed, squash):
        import torch
        torch.manual_seed(seed)
        layers = [torch.nn.Linear(obs_dim, HIDDEN), torch.nn.Tanh(), torch.nn.Linear(HIDDEN, HIDDEN), torch.nn.Tanh(),
                  torch.nn.Linear(HIDDEN, out_dim)]
        self.squash = squash
        self.net = torch.nn.Sequential(*layers)
        self.mu, self.sd = np.zeros(obs_dim, np.float32), np.ones(obs_dim, np.float32)
        self.rng = np.random.default_rng(seed)
        self._np = None

    def fit(self, X, Y, steps, loss_kind):
        import torch
        self.mu, self.sd = X.mean(0), X.std(0) + 1e-3
        Xt, Yt = torch.as_tensor((X - self.mu) / self.sd), torch.as_tensor(Y)
        opt = torch.optim.Adam(self.net.parameters(), lr=LR)
        sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, steps)
        bce = torch.nn.BCEWithLogitsLoss()
        last = 0.0
        for _ in range(steps):
            idx = torch.as_tensor(self.rng.integers(0, len(Xt), min(BATCH, len(Xt))))
            out = self.net(Xt[idx])
            loss = torch.mean((torch.tanh(out) - Yt[idx]) ** 2) if loss_kind == "mse" else bce(out, Yt[idx])
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            last = float(loss.detach())
        self._np = [(m.weight.detach().numpy().T.astype(np.float64), m.bias.detach().numpy().astype(np.float64))
                    for m in self.net if isinstance(m, torch.nn.Linear)]
        return last

    def __call__(self, obs):
        h = (np.asarray(obs, np.float64) - self.mu) / self.sd
        for i, (W, b) in enumerate(self._np):
            h = h @ W + b
            if i < len(self._np) - 1 or self.squash:
                h = np.tanh(h)
        return h


class OptionChooser:
    """The option learner's decide(): the candidate with the highest predicted success logit."""

    def __init__(self, net):
        self.net = net

    def __call__(self, o, state, target, t):
        return int(np.argmax(self.net(o[None, :])[0]))


def evaluate_flat(env, act, seeds):
    """Success per seed of act (obs -> action) on env (gymnasium.make of the cell, its own time limit)."""
    out = []
    for s in seeds:
        o, _ = env.reset(seed=s)
        while True:
            o, _, term, trunc, info = env.step(act(o[None, :])[0])
            if term or trunc:
                out.append(bool(info["is_success"]))
                break
    return out


def evaluate_options(expert, net, seeds):
    """Success per seed of the option learner (its choices from the observation; no search)."""
    choose = OptionChooser(net)
    return [episode(expert, s, choose, label=False)[2] for s in seeds]


def _row(cell, expert, agent, succ, wit, samples, secs):
    probe, table, law = cell
    k, n, kw = int(sum(succ)), len(succ), int(sum(wit))
    lo, hi = clopper_pearson(k, n)
    return {"probe": probe, "table": table, "law": law, "env_id": expert.env_id,
            "overrides": " ".join(f"{a}={b}" for a, b in expert.overrides.items()), "agent": agent, "episodes": n,
            "success": k, "rate": k / n, "ci_low": lo, "ci_high": hi, "witnessed": kw, "witness_rate": kw / n,
            "ratio": (k / kw) if kw else float("nan"),
            "goal_met": "" if agent == "witness" else ("yes" if kw and 2 * k >= kw else "no"),
            "samples": samples, "train_s": round(secs, 1)}


def run_cell(cell, cfg, seed=0, log=print):
    """Rows (witness, bc, dagger, options) and the curves of one cell."""
    import gymnasium as gym

    probe, table, law = cell
    t_cell = time.perf_counter()
    expert = Expert(probe, table, law)
    env = gym.make(expert.env_id, **expert.overrides)
    rng = np.random.default_rng(seed)
    eval_seeds = list(range(cfg["eval_episodes"]))
    val_seeds = list(range(VAL_SEED, VAL_SEED + cfg["val_episodes"]))
    wit = [expert.w.pair(s).witnessed for s in eval_seeds]  # the witness of studies/witness.py, same seeds
    log(f"{probe} {table} {law}: witness {sum(wit)}/{len(wit)} on the evaluation seeds "
        f"({time.perf_counter() - t_cell:.0f} s)")
    # the expert's ranking from the demonstration seeds' starts, then its episodes (demonstrations)
    seeds = iter(range(TRAIN_SEED, TRAIN_SEED + 10 ** 6))
    demo_seeds = [next(seeds) for _ in range(cfg["demos"])]
    starts = []
    for s in demo_seeds:
        expert.w.env.reset(seed=s)
        u = expert.w.env.unwrapped
        starts.append(expert.outcomes(u.state.copy(), u.target.copy(), expert.max_steps))
    expert.rank([x for x in starts if x is not None])
    rec = Recorder(expert)
    Xf, Yf, demo_ok = [], [], 0
    for s in demo_seeds:
        o, lab, ok, _ = episode(expert, s, rec)
        demo_ok += ok
        Xf += o
        Yf += lab
    X, Y = np.asarray(Xf, np.float32), np.asarray(Yf, np.float32)
    t_demo = time.perf_counter() - t_cell
    log(f"  expert: {demo_ok}/{len(demo_seeds)} demonstrations succeeded, {len(X)} steps, "
        f"{len(rec.X)} decision points ({t_demo:.0f} s)")
    curves = []
    # flat learner: BC (round 0), then DAgger
    pol = MLP(X.shape[1], Y.shape[1], seed, squash=True)
    pol.fit(X, Y, cfg["grad_steps"], "mse")
    val = float(np.mean(evaluate_flat(env, pol, val_seeds)))
    curves.append({"learner": "flat", "round": 0, "samples": len(X), "val_success": val,
                   "seconds": round(time.perf_counter() - t_cell, 1)})
    log(f"  flat round 0 (BC): {len(X)} samples, validation {val:.2f}")
    bc = evaluate_flat(env, pol, eval_seeds)
    bc_samples, bc_s = len(X), time.perf_counter() - t_cell
    plan = Recorder(expert)  # (records too; its outcomes are the option learner's extra data)
    for r in range(1, cfg["rounds"] + 1):
        beta = BETA if r == 1 else 0.0
        for _ in range(cfg["dagger_episodes"]):
            o, lab, _, _ = episode(expert, next(seeds), plan, act=pol, beta=beta, rng=rng)
            if o:
                X, Y = np.concatenate([X, np.asarray(o, np.float32)]), np.concatenate([Y, np.asarray(lab, np.float32)])
        pol = MLP(X.shape[1], Y.shape[1], seed + r, squash=True)
        pol.fit(X, Y, cfg["grad_steps"], "mse")
        val = float(np.mean(evaluate_flat(env, pol, val_seeds)))
        curves.append({"learner": "flat", "round": r, "samples": len(X), "val_success": val,
                       "seconds": round(time.perf_counter() - t_cell, 1)})
        log(f"  flat round {r} (DAgger): {len(X)} samples, validation {val:.2f} ({time.perf_counter() - t_cell:.0f} s)")
    dagger = evaluate_flat(env, pol, eval_seeds)
    dagger_samples, dagger_s = len(X), time.perf_counter() - t_cell
    # option learner: success per option from the decision points' outcomes, then its own on-policy rounds
    t_opt = time.perf_counter()
    OX, OY = list(rec.X) + list(plan.X), list(rec.Y) + list(plan.Y)
    net = MLP(X.shape[1], len(expert.cands), seed, squash=False)
    net.fit(np.asarray(OX), np.asarray(OY), cfg["grad_steps"], "bce")
    val = float(np.mean(evaluate_options(expert, net, val_seeds)))
    curves.append({"learner": "options", "round": 0, "samples": len(OX), "val_success": val,
                   "seconds": round(time.perf_counter() - t_cell, 1)})
    log(f"  options round 0: {len(OX)} decision points, validation {val:.2f}")
    for r in range(1, cfg["rounds"] + 1):
        own = Recorder(expert, OptionChooser(net))
        for _ in range(cfg["dagger_episodes"]):
            episode(expert, next(seeds), own, label=False)
        OX += own.X
        OY += own.Y
        net = MLP(X.shape[1], len(expert.cands), seed + r, squash=False)
        net.fit(np.asarray(OX), np.asarray(OY), cfg["grad_steps"], "bce")
        val = float(np.mean(evaluate_options(expert, net, val_seeds)))
        curves.append({"learner": "options", "round": r, "samples": len(OX), "val_success": val,
                       "seconds": round(time.perf_counter() - t_cell, 1)})
        log(f"  options round {r}: {len(OX)} decision points, validation {val:.2f} "
            f"({time.perf_counter() - t_cell:.0f} s)")
    options = evaluate_options(expert, net, eval_seeds)
    opt_s = time.perf_counter() - t_opt + t_demo
    env.close()
    expert.close()
    rows = [_row(cell, expert, "witness", wit, wit, demo_ok, 0.0),
            _row(cell, expert, "bc", bc, wit, bc_samples, bc_s),
            _row(cell, expert, "dagger", dagger, wit, dagger_samples, dagger_s),
            _row(cell, expert, "options", options, wit, len(OX), opt_s)]
    for c in curves:
        c.update(probe=probe, table=table, law=law)
    return rows, curves


# -- command line and report --------------------------------------------------------------------------
AGENT_TEXT = {"witness": "witness (search with the simulator, studies/witness.py)",
              "bc": "flat MLP, behaviour cloning", "dagger": "flat MLP, DAgger",
              "options": "option MLP (learned success per witness option)"}
CURVE_FIELDS = ["probe", "table", "law", "learner", "round", "samples", "val_success", "seconds"]


def parse_cell(text: str):
    """('Steer', 'ellipse', 'elastic') from 'Steer:ellipse:elastic'; ValueError naming what is wrong."""
    parts = text.split(":")
    if len(parts) != 3:
        raise ValueError(f"cell {text!r} must be PROBE:TABLE:LAW, e.g. Steer:ellipse:elastic")
    probe, table, law = parts
    if probe not in SINGLE_INPUT:
        raise ValueError(f"cell {text!r}: unknown probe {probe!r}; single-input probes: {list(SINGLE_INPUT)}")
    if table not in TABLE_NAMES or table == "plane":
        raise ValueError(f"cell {text!r}: unknown table {table!r}; tables with walls: "
                         f"{[t for t in TABLE_NAMES if t != 'plane']}")
    if law not in LAWS:
        raise ValueError(f"cell {text!r}: unknown law {law!r}; laws: {list(LAWS)}")
    return probe, table, law


def write_csv(path, rows, fields):
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fields)
        w.writeheader()
        for r in rows:
            w.writerow({k: r.get(k, "") for k in fields})


def _f(v, spec=".2f"):
    return "-" if v is None or (isinstance(v, float) and v != v) else format(v, spec)


def write_report(path: Path, rows, curves, cfg, meta):
    lines = ["# A fair chance for learned agents on the single-input probes: imitation of the witnesses", "",
             *meta["machine"], f"- command: `{meta['command']}` ({meta['wall_s']:.0f} s wall, finished {meta['date']})",
             "- regenerate: run the command above from the repository root (one process, torch and numba on one "
             "thread)"]
    if meta.get("sources"):
        lines.append(meta["sources"])
    lines += ["", f"Budget per cell: {cfg['demos']} expert demonstrations, {cfg['rounds']} DAgger rounds of "
              f"{cfg['dagger_episodes']} episodes per learner, {cfg['grad_steps']} gradient steps per fit (batch "
              f"{BATCH}, Adam {LR:g}), {cfg['val_episodes']} validation episodes per round, evaluation on "
              f"{cfg['eval_episodes']} episodes (seeds 0 .. {cfg['eval_episodes'] - 1}, the witness study's pair "
              f"seeds; training seeds from {TRAIN_SEED}, validation seeds from {VAL_SEED}). Method: "
              "[studies/fair_rl.py](../studies/fair_rl.py) (module docstring).", "",
              "## The agents", "",
              "* **witness**: the certified witness of [witnesses.md](witnesses.md) (studies/witness.py), run on "
              "the same evaluation seeds in this run: the reference rate. It searches with the simulator from the "
              "exact start of each episode.",
              "* **bc / dagger** (flat): an MLP from the env's observation to the torque (the raw action), trained "
              "on the expert's episodes (bc), then by DAgger rounds in which the learner drives and the expert "
              "labels every state it visits. The expert: the witness family re-planned from the exact state at "
              "the start and after every impact, taking the best-ranked candidate that succeeds from there (the "
              "ranking: the candidates' success rates from the training starts), so that its choice is "
              "consistent from state to state.",
              "* **options**: an MLP from the observation to the success probability of each of the witness "
              "family's parametrised controllers (576 for steer, 64 for drive) if committed to from here; at the "
              "start and after every impact the agent takes the option with the highest predicted success and "
              "that controller's feedback law acts until the next impact. Trained (binary cross-entropy) on "
              "Monte-Carlo outcomes: at every decision point of the expert's, the flat learner's and (rounds "
              "1..R) its own episodes every option is simulated from the exact state to the time limit. "
              "**No search at test time**: the choice is the network's. Its low-level controllers are the "
              "witness family's (studies/witness.py), which read the exact state, the same quantities as the "
              "observation in float64; the agent learns *which* controller, not the torque law.",
              "",
              "The evaluation env is `gymnasium.make(env id, **overrides)` with the probe's own time limit (steer "
              "park 400 steps = 20 s, drive reach 200 steps = 10 s); success is `info[\"is_success\"]`. Intervals: "
              "exact 95 % Clopper-Pearson (studies/study_report.py). Ratio: the agent's successes over the "
              "witness's on the same seeds; the goal of issue 20 item 4 is a ratio of at least 0.5.", "",
              "## Results", "",
              "| actuation | table | law | agent | success [95 % CI] | witnessed | ratio to the witness | goal (>= 0.5) |",
              "| --- | --- | --- | --- | --- | --- | ---: | --- |"]
    for r in rows:
        lines.append(f"| {PROBE_TASKS[r['probe']]} | {TABLE_NAMES[r['table']]} | {r['law']} | {r['agent']} | "
                     f"{r['success']}/{r['episodes']} = {r['rate']:.3f} [{r['ci_low']:.3f}, {r['ci_high']:.3f}] | "
                     f"{r['witnessed']}/{r['episodes']} | {_f(r['ratio'])} | {r['goal_met'] or '-'} |")
    lines += ["", "## Verdict per cell", ""]
    cells = []
    for r in rows:
        if (r["probe"], r["table"], r["law"]) not in cells:
            cells.append((r["probe"], r["table"], r["law"]))
    for c in cells:
        rs = [r for r in rows if (r["probe"], r["table"], r["law"]) == c and r["agent"] != "witness"]
        best = max(rs, key=lambda r: r["success"])
        met = [r["agent"] for r in rs if r["goal_met"] == "yes"]
        lines.append(f"* {PROBE_TASKS[c[0]]}, {TABLE_NAMES[c[1]]}, {c[2]}: "
                     + (f"**goal met** by {', '.join(met)} (best {best['agent']}: ratio {_f(best['ratio'])})"
                        if met else f"**goal not met**: best learned agent {best['agent']}, ratio {_f(best['ratio'])} "
                        f"(upper end of its interval over the witnessed rate: "
                        f"{_f(best['ci_high'] / best['witness_rate'] if best['witness_rate'] else None)})"))
    steer_met = sum(1 for c in cells if c[0] == "Steer" and any(
        r["goal_met"] == "yes" for r in rows if (r["probe"], r["table"], r["law"]) == c))
    drive_cells = [c for c in cells if c[0] == "Drive"]
    drive_met = sum(1 for c in drive_cells if any(
        r["goal_met"] == "yes" for r in rows if (r["probe"], r["table"], r["law"]) == c))
    lines += ["", f"Steer-only park: goal met on {steer_met} table(s) (the issue asks for at least 2). "
              f"Drive-only reach: goal met under {drive_met} of {len(drive_cells)} law(s) run (the issue asks "
              "for every law).", "",
              "## Curves: validation success per round", "",
              "Round 0 is behaviour cloning (flat) or the option network fitted on the expert's decision points "
              "(options); rounds 1.. add DAgger data (flat) or the option agent's own episodes (options). "
              f"{cfg['val_episodes']} validation episodes per point, so steps of 1/{cfg['val_episodes']} are "
              "noise.", "",
              "| actuation | table | law | learner | " + " | ".join(f"round {i}" for i in range(cfg["rounds"] + 1))
              + " | samples at the end | cell seconds at the end |",
              "| --- | --- | --- | --- | " + " | ".join("---:" for _ in range(cfg["rounds"] + 1)) + " | ---: | ---: |"]
    keys = []
    for c in curves:
        k = (c["probe"], c["table"], c["law"], c["learner"])
        if k not in keys:
            keys.append(k)
    for k in keys:
        cs = sorted((c for c in curves if (c["probe"], c["table"], c["law"], c["learner"]) == k),
                    key=lambda c: c["round"])
        lines.append(f"| {PROBE_TASKS[k[0]]} | {TABLE_NAMES[k[1]]} | {k[2]} | {k[3]} | "
                     + " | ".join(f"{float(c['val_success']):.2f}" for c in cs)
                     + f" | {cs[-1]['samples']} | {float(cs[-1]['seconds']):.0f} |")
    lines += ["", "CSV: per cell and agent `fair_rl.csv`, curves `fair_rl_curves.csv` (beside this report)."]
    path.write_text("\n".join(lines).rstrip() + "\n")


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m studies.fair_rl", description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="tiny run (< 1 min) into a temporary folder, never docs/")
    ap.add_argument("--out", help="the report's path (default: docs/fair_rl.md; --quick: a temporary folder)")
    ap.add_argument("--cells", nargs="+", metavar="PROBE:TABLE:LAW",
                    help="cells to run (default: steer park on ellipse and stadium, drive reach on the ellipse "
                         "under every law)")
    for key in ("demos", "rounds", "dagger_episodes", "grad_steps", "val_episodes", "eval_episodes"):
        ap.add_argument("--" + key.replace("_", "-"), type=positive_int("--" + key.replace("_", "-"),
                                                                        0 if key == "rounds" else 1))
    ap.add_argument("--seed", type=positive_int("--seed", 0), default=0, help="the learners' seed")
    ap.add_argument("--workers", type=positive_int("--workers"), default=1,
                    help="processes (only 1 is supported: the cells run one after the other on one core)")
    args = ap.parse_args(argv)
    if args.workers != 1:
        ap.error(f"--workers {args.workers}: only --workers 1 is supported (the run is sized for one core)")
    try:
        cells = [parse_cell(c) for c in args.cells] if args.cells else list(QUICK_CELLS if args.quick else DEFAULT_CELLS)
    except ValueError as exc:
        ap.error(str(exc))
    cfg = dict(QUICK if args.quick else FULL)
    for key in cfg:
        if getattr(args, key) is not None:
            cfg[key] = getattr(args, key)
    if args.out:
        out = Path(args.out).resolve()
    elif args.quick:
        import tempfile
        out = Path(tempfile.mkdtemp(prefix="penny_env-quick-")) / "fair_rl.md"
    else:
        out = DOCS / "fair_rl.md"
    if args.quick and (out.parent == DOCS.resolve() or out.parent == ROOT):
        ap.error(f"--quick never writes into docs/ or the repository root; give another --out (got {args.out})")
    import torch
    torch.set_num_threads(1)
    from studies.common import command_line, machine_lines
    out.parent.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    rows, curves = [], []
    for i, cell in enumerate(cells):
        r, c = run_cell(cell, cfg, seed=args.seed + 1000 * i)
        rows += r
        curves += c
    sources = None
    from studies.provenance import REPORTS, stamp_line
    rel = out.relative_to(ROOT).as_posix() if out.is_relative_to(ROOT) else None
    if rel in REPORTS:  # a committed report (docs/fair_rl.md, docs/fair_rl_extra/*): its sources' hash
        sources = stamp_line(rel)
    meta = {"command": command_line("studies.fair_rl", list(sys.argv[1:] if argv is None else argv)),
            "machine": machine_lines(), "wall_s": time.perf_counter() - t0,
            "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "sources": sources, "config": cfg,
            "cells": [":".join(c) for c in cells]}
    stem = out.with_suffix("")
    write_csv(stem.parent / (stem.name + ".csv"), rows, FIELDS)
    write_csv(stem.parent / (stem.name + "_curves.csv"), curves, CURVE_FIELDS)
    (stem.parent / (stem.name + "_run.json")).write_text(json.dumps(meta, indent=1))
    write_report(out, rows, curves, cfg, meta)
    print(f"wrote {out} ({meta['wall_s']:.0f} s)")
    return rows


if __name__ == "__main__":
    main()
