"""PPO with agent-side control heads and potential-based shaping from the task's success test (the ladder's
"ppo_heading"), one file in CleanRL's style over penny_env's native vector env; with ``guide`` it is the ladder's
witness-guided PRIVILEGED agent (training/guides.py).

    python -m training.ppo_heading [--env-id PennyProbeSteer-Stadium-Elastic-v0] [--total-timesteps 1e8]
                                   [--seed 0] [--set FIELD=VALUE ...] [--hp NAME=VALUE ...] [--demos NPZ]
                                   [--quick] [--eval] [--out DIR | --resume DIR]

**What it may use** (without ``guide``: no privileged information): the env's observation, its reward (the *fair*
reward: the success bonus only), terminated/truncated, ``info["impacts"]`` (counted into the agent's own impact
counter), ``info["is_success"]`` (training statistics only), and the task's published constants (training/agent_side
.TaskConsts: R, the inertias and torque limits, the observation scales, the length scale L, the tolerances, the time
limit) to decode the observation into physical units. It never reads the env's state or target arrays and never
resets an env to a chosen state: its only resets are the task's own start draws.

**With ``guide``** ("jsrl" or "curriculum", and ``demos``: certified witness episodes of training seeds): PRIVILEGED
in training, labelled so in every table. The witness drives the first part of a share of the training episodes from
their starts (privileged resets to the demonstrations' starts), the learner takes over, and the part shrinks as the
learner succeeds (training/guides.py). The evaluated policy is the same network as without a guide.

**Agent design** (all of it on the agent's side of the env's interface; training/agent_side.py):

* Features (19): the observation decoded with the published constants, the agent's impact counter and its clock.
* Action heads (by the probe's actuation): steering: a world-frame heading psi (a 2-vector's angle; Gaussian noise
  on the angle) that the agent's PD law turns into the steering torque; rolling: a rolling-speed request that its P
  law turns into the rolling torque (the servo gains of studies/witness.py; not its strategy).
* Shaping: F = gamma Phi(s') - Phi(s) added to the fair reward (potential-based: the fair reward's optimal policies
  are kept, Ng et al. 1999), Phi from the success test's quantities (agent_side.potential).
* Desynchronised episodes: before training, env i restarts (the task's own draw) at a random step of a warm-up one
  time limit long.

**The learner, and why** (docs/ladder.md, "What made PPO fall, and what holds it"): CleanRL's continuous-action PPO
(clipped objective, GAE, advantages normalised per minibatch, NEXT_STEP autoreset with the reset steps masked), on
4096 envs x 32 steps. The learning rate follows the measured KL (``lr_schedule="kl"``: x 1.5 when an update's mean
approximate KL is under half of ``desired_kl``, / 1.5 above twice it, within [lr_min, lr_max]; RSL-RL's rule)
instead of annealing to 0 over the budget; the heading noise has a floor (``std_min``); the networks carry LayerNorm;
Adam runs with beta1 = beta2 (``adam_betas``). The learner logs, per update, into ``progress.csv``: the approximate
KL, the clip fraction, the noise std, the value loss, the explained variance, the gradient norm, the learning rate,
the training success and, every ``val_every`` env steps, the validation success on seeds VAL_SEED.. (never the
evaluation's 0..199). ``keep_best`` hands each checkpoint the best-validated snapshot so far: a safety net; the
final policy is expected within a few points of it.

Protocol (training/protocol.py) and command line (training/agent_cli.py): ``Args``, ``train(args, checkpoints,
on_checkpoint, log, resume)``, ``checkpoint.pt`` every ``save_every`` env steps and on Ctrl-C, ``--resume``. Seeds:
training envs ``TRAIN_SEED + 100_000 seed`` (+ sub-env index; + 1000 per resume), validation ``VAL_SEED`` ..
``+ val_episodes``.
"""
from __future__ import annotations

import copy
import dataclasses
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
import torch.nn as nn

from training import agent_side as A
from training.agent_cli import Interrupted, non_negative, one_of, positive, unit_interval
from training.protocol import evaluate, fair_reward_kwargs

TRAIN_SEED, VAL_SEED = 10_000_000, 50_000


@dataclass
class Args:
    env_id: str = "PennyProbeSteer-Stadium-Elastic-v0"
    env_kwargs: dict = field(default_factory=dict)  # the cell's field overrides (the fair reward goes on top)
    seed: int = 0
    total_timesteps: int = 100_000_000
    torch_threads: int = 1
    out: str | None = None
    num_envs: int = 4096
    num_steps: int = 32
    minibatch_size: int = 16384
    update_epochs: int = 2
    learning_rate: float = 3e-4  # the first learning rate (lr_schedule "kl": then it follows the KL)
    lr_schedule: str = "kl"      # "kl": adapted to the measured KL; "anneal": linearly to 0 over the budget; "constant"
    desired_kl: float = 0.01
    lr_min: float = 1e-5
    lr_max: float = 1e-3
    adam_betas: tuple = (0.9, 0.9)
    layer_norm: bool = True
    gamma: float = 0.999
    gae_lambda: float = 0.95
    clip_coef: float = 0.2
    clip_vloss: bool = True
    target_kl: float = 0.05  # stop an update's minibatches once approx KL passes it (0: never)
    vf_coef: float = 0.5
    ent_coef: float = 0.0
    max_grad_norm: float = 0.5
    reward_scale: float = 0.1  # (fair reward + shaping) x this: returns of order 1
    hidden: int = 64
    std_init: float = 0.5  # initial action noise (heading: rad; speed: units of V_MAX)
    std_min: float = 0.15  # noise floor and ceiling (the log-std is clamped)
    std_max: float = 2.0
    explore_until: float = 0.0  # > 0: the noise floor stays at std_init until training success appears, and lowers
    #                             to std_min as it rises to this (never rising again); 0: the floor is std_min
    norm_coef: float = 0.1  # pulls the heading 2-vector's length to 1 (its angle's gradient stays bounded)
    heading_init: float = 0.01  # the heading 2-vector's output weights' scale at the start
    shaping: bool = True  # the potential-based shaping (agent_side.potential); off: the fair reward alone
    v_flat: float = 0.5  # park potential: speeds under this x speed_tolerance count as 0
    desync: bool = True
    val_every: int = 5_000_000  # env steps between validation evaluations (0: none)
    keep_best: bool = True  # with val_every: the policy handed out is the best-validated so far (early stopping)
    val_episodes: int = 100
    save_every: int = 10_000_000  # env steps between checkpoint.pt saves (with out)
    demos: str | None = None  # .npz of training.protocol.save_demos: the guide's demonstrations (PRIVILEGED)
    guide: str = "none"  # "none", "jsrl" or "curriculum" (training/guides.py; needs demos)
    guide_step: float = 0.1
    guide_threshold: float = 0.5
    guide_min_episodes: int = 256  # jsrl: guided episodes per stage (all demos); curriculum: per demonstration
    guide_p_own: float = 0.1
    quick: bool = False


CHECKS = {"num_envs": positive, "num_steps": positive, "minibatch_size": positive, "update_epochs": positive,
          "learning_rate": positive, "lr_schedule": one_of("kl", "anneal", "constant"), "desired_kl": positive,
          "lr_min": positive, "lr_max": positive, "gamma": unit_interval, "gae_lambda": unit_interval,
          "clip_coef": positive, "target_kl": non_negative, "vf_coef": non_negative, "ent_coef": non_negative,
          "max_grad_norm": positive, "reward_scale": positive, "hidden": positive, "std_init": positive,
          "std_min": positive, "std_max": positive, "explore_until": unit_interval, "norm_coef": non_negative,
          "heading_init": positive,
          "v_flat": non_negative,
          "val_every": non_negative, "val_episodes": positive, "save_every": positive,
          "guide": one_of("none", "jsrl", "curriculum"), "guide_step": unit_interval,
          "guide_threshold": unit_interval, "guide_min_episodes": positive, "guide_p_own": unit_interval,
          None: lambda args: check_guide(args)}


def check_guide(args: Args) -> None:
    if args.guide != "none" and not args.demos:
        raise ValueError(f"guide {args.guide!r} needs demos (--demos: an .npz of training.protocol.save_demos, e.g. "
                         "python -m studies.witness_demos ENV_ID OUT.npz --pairs 64)")


def quick_args(args: Args) -> Args:
    """--quick: a few tens of thousands of steps on 64 envs (seconds; checks the pipeline, learns nothing)."""
    return dataclasses.replace(args, num_envs=64, num_steps=32, minibatch_size=1024, val_every=64 * 32 * 2,
                               total_timesteps=min(args.total_timesteps, 64 * 32 * 4), val_episodes=16,
                               guide_min_episodes=4, quick=True)


# -- the agent ---------------------------------------------------------------------------------------------------
def mlp(n_in, n_out, hidden, out_std, layer_norm):
    def block(i):
        return [A.layer(i, hidden)] + ([nn.LayerNorm(hidden)] if layer_norm else []) + [nn.Tanh()]
    return nn.Sequential(*block(n_in), *block(hidden), A.layer(hidden, n_out, out_std))


class Agent(nn.Module):
    """Actor: features -> [heading 2-vector (steer)] + [speed request (drive)]; its action (what PPO samples and
    scores) is [heading angle psi] + [a], one noise std per action. Critic: features -> value."""

    def __init__(self, k: A.TaskConsts, hidden: int, std_init: float, std_min: float, std_max: float,
                 layer_norm: bool, heading_init: float = 0.01):
        super().__init__()
        self.steer, self.drive = bool(k.gain1), bool(k.gain2)
        self.n_act = self.steer + self.drive
        self.critic = mlp(A.FEATURES_DIM, 1, hidden, 1.0, layer_norm)
        self.actor = mlp(A.FEATURES_DIM, 2 * self.steer + self.drive, hidden, 0.01, layer_norm)
        # the heading 2-vector's scale at the start (its angle's sensitivity to the weights ~ 1 / length); 0.01 is the
        # output layer's own initialisation
        if self.steer and heading_init != 0.01:
            nn.init.orthogonal_(self.actor[-1].weight[:2], heading_init)
        self.log_std = nn.Parameter(torch.full((1, self.n_act), math.log(std_init)))
        self.log_std_range = (math.log(std_min), math.log(std_max))

    def value(self, x):
        return self.critic(x).squeeze(-1)

    def mean(self, x):
        """(action means (N, n_act), heading 2-vector length (N,) or None)."""
        y = self.actor(x)
        if not self.steer:
            return y, None
        mu = torch.atan2(y[:, 1], y[:, 0])[:, None]
        return torch.cat([mu, y[:, 2:]], 1), torch.sqrt(y[:, 0] ** 2 + y[:, 1] ** 2)

    def std(self):
        return self.log_std.clamp(*self.log_std_range).exp()

    def log_prob(self, mean, action):
        """Gaussian log-density, the heading's difference taken on the circle."""
        diff = action - mean
        if self.steer:
            diff = torch.cat([torch.remainder(diff[:, :1] + math.pi, 2 * math.pi) - math.pi, diff[:, 1:]], 1)
        log_std = self.log_std.clamp(*self.log_std_range)
        return (-0.5 * (diff / log_std.exp()) ** 2 - log_std - 0.5 * math.log(2 * math.pi)).sum(-1)


class HeadingPolicy:
    """The deterministic policy of training/protocol.py: the mean heading / speed request through the agent's servo
    laws, with the agent's own clock and impact counter (a frozen copy of the agent)."""

    def __init__(self, agent: Agent, k: A.TaskConsts):
        self.agent = copy.deepcopy(agent).eval()
        self.k = k
        self.mem = torch.zeros(0, 2)
        self.started = False

    def reset(self, num_envs: int) -> None:
        self.mem = torch.zeros(num_envs, 2)
        self.started = False

    @torch.no_grad()
    def __call__(self, obs, info) -> np.ndarray:
        if self.started:  # (the reset's info has no step behind it)
            self.mem[:, 0] += torch.as_tensor(np.asarray(info["impacts"]), dtype=torch.float32)
            self.mem[:, 1] += 1
        self.started = True
        o = torch.as_tensor(np.asarray(obs), dtype=torch.float32)
        mean, _ = self.agent.mean(A.features(o, self.mem, self.k))
        return A.servo(o, mean, self.k).numpy().astype(np.float64)


# -- training ----------------------------------------------------------------------------------------------------
def training_kwargs(args: Args) -> dict:
    """The training env's fields: the cell's overrides and the fair reward's (those the task has)."""
    return {**args.env_kwargs, **fair_reward_kwargs(args.env_id, args.env_kwargs)}


def explained_variance(pred: torch.Tensor, target: torch.Tensor) -> float:
    var = float(target.var())
    return 1.0 - float((target - pred).var()) / var if var > 0 else float("nan")


PROGRESS = ["global_step", "wall_s", "train_success", "val_success", "steps_per_s", "std", "approx_kl", "clip_frac",
            "value_loss", "explained_variance", "grad_norm", "lr", "minibatches", "guide_frac", "guide_done",
            "guide_success", "std_floor"]


def train(args: Args, checkpoints=(), on_checkpoint=None, log=print, resume=None) -> dict:
    """Train for args.total_timesteps env steps (training/protocol.py); ``resume``: a checkpoint.pt of this run to go
    on from (its learner; the envs start new episodes). Returns the results dict."""
    if args.quick:
        args = quick_args(args)
    check_guide(args)
    torch.set_num_threads(args.torch_threads)
    torch.manual_seed(args.seed)
    rng = np.random.default_rng(args.seed)
    out = Path(args.out) if args.out else None
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
    N, T = args.num_envs, args.num_steps
    env = A.make_vec(args.env_id, N, training_kwargs(args))
    k = A.TaskConsts.of(env)
    agent = Agent(k, args.hidden, args.std_init, args.std_min, args.std_max, args.layer_norm, args.heading_init)
    opt = torch.optim.Adam(agent.parameters(), lr=args.learning_rate, eps=1e-5, betas=tuple(args.adam_betas))
    guide = None
    if args.guide != "none":
        from training.guides import Guide
        from training.protocol import load_demos
        guide = Guide(load_demos(args.demos), N, rng, args.guide, args.guide_step, args.guide_threshold,
                      args.guide_min_episodes, args.guide_p_own)
    iterations = max(1, -(-int(args.total_timesteps) // (N * T)))
    best = {"val": -1.0, "agent": None}  # keep_best: the best-validated snapshot so far
    state = {"it": 0, "global_step": 0, "curve": [], "wall": 0.0,
             "floor": max(args.std_init, args.std_min) if args.explore_until > 0 else args.std_min}
    if resume is not None:
        saved = torch.load(resume, weights_only=False)
        agent.load_state_dict(saved["agent"])
        opt.load_state_dict(saved["opt"])
        if saved["best_agent"] is not None:
            best.update(val=saved["best_val"], agent=copy.deepcopy(agent))
            best["agent"].load_state_dict(saved["best_agent"])
        state.update(saved["state"])
        torch.set_rng_state(saved["torch_rng"])
        rng.bit_generator.state = saved["np_rng"]
        if guide is not None and saved.get("guide") is not None:
            guide.load_state_dict(saved["guide"])
        if log:
            log(f"[ppo_heading] resumed from {resume} at {state['global_step']:,} env steps")

    def save(path):
        tmp = Path(str(path) + ".tmp")
        torch.save({"agent": agent.state_dict(), "opt": opt.state_dict(), "best_val": best["val"],
                    "best_agent": None if best["agent"] is None else best["agent"].state_dict(), "state": dict(state),
                    "torch_rng": torch.get_rng_state(), "np_rng": rng.bit_generator.state,
                    "guide": None if guide is None else guide.state_dict()}, tmp)
        tmp.replace(path)
        return Path(path)

    def policy():
        """The current policy, or with keep_best the best-validated one so far (a snapshot: training goes on)."""
        return HeadingPolicy(best["agent"] if args.keep_best and best["agent"] is not None else agent, k)

    A_ = agent.n_act
    X = torch.zeros(T, N, A.FEATURES_DIM)
    ACT = torch.zeros(T, N, A_)
    LP, RW, V, TERM, DONE, VALID = (torch.zeros(T, N) for _ in range(6))

    obs_np, _ = env.reset(seed=TRAIN_SEED + 100_000 * args.seed + 1000 * state["it"])
    if args.desync:  # env i restarts (the task's own start draw) at a random step of one time limit
        when = rng.integers(0, k.max_steps, N)
        zero = np.zeros((N, A_), np.float64)
        for step in range(k.max_steps):
            env.step(zero)
            obs_np, _ = env.reset(options={"reset_mask": when == step})
    obs = torch.as_tensor(obs_np)
    mem = torch.zeros(N, 2)  # the agent's impact counter and clock
    resetting = np.zeros(N, bool)  # (NEXT_STEP: this step resets these envs)

    def start_guided(rows):
        """Rows whose episode just began (the env's own draw): the guide may move them to a demonstration's start."""
        nonlocal obs
        states, targets, guided = guide.start(rows)
        if guided.any():
            mask = np.zeros(N, bool)
            mask[rows[guided]] = True
            S, G = np.tile(states[guided][:1], (N, 1)), np.tile(targets[guided][:1], (N, 1))
            S[rows[guided]], G[rows[guided]] = states[guided], targets[guided]
            o, _ = env.reset(options={"state": S, "target": G, "reset_mask": mask})
            obs[mask] = torch.as_tensor(o[mask])

    if guide is not None:
        start_guided(np.arange(N))
    phi = A.potential(obs, k, args.v_flat) if args.shaping else torch.zeros(N)
    checkpoints = sorted(int(c) for c in checkpoints)
    passed = {c for c in checkpoints if c <= state["global_step"]}  # (a resumed run: evaluated before it stopped)
    called_at = set()
    val_next = (state["global_step"] // args.val_every + 1) * args.val_every if args.val_every else None
    save_next = (state["global_step"] // args.save_every + 1) * args.save_every
    ep_window = []
    t0 = time.perf_counter() - state["wall"]
    t_env = t_upd = t_aside = 0.0
    stats = {}
    progress = None
    if out is not None:
        kept = []
        if resume is not None and (out / "progress.csv").is_file():  # the rows up to the checkpoint's step
            kept = [r for r in (out / "progress.csv").read_text().splitlines()[1:]
                    if r.split(",")[0].isdigit() and int(r.split(",")[0]) <= state["global_step"]]
        progress = open(out / "progress.csv", "w")
        progress.write("".join(r + "\n" for r in [",".join(PROGRESS)] + kept))
    train_success = float("nan")
    try:
        for it in range(state["it"] + 1, iterations + 1):
            if args.lr_schedule == "anneal":
                opt.param_groups[0]["lr"] = args.learning_rate * (1.0 - (it - 1) / iterations)
            state["floor"] = noise_floor(args, state["floor"], train_success)
            agent.log_std_range = (math.log(min(state["floor"], args.std_max)), math.log(args.std_max))
            succ = ends = 0
            with torch.no_grad():
                for t in range(T):
                    x = A.features(obs, mem, k)
                    X[t] = x
                    mean, _ = agent.mean(x)
                    act = mean + agent.std() * torch.randn_like(mean)
                    ACT[t] = act
                    LP[t] = agent.log_prob(mean, act)
                    V[t] = agent.value(x)
                    env_act = A.servo(obs, act, k).numpy().astype(np.float64)
                    guided = guide.actions(env_act) if guide is not None else np.zeros(N, bool)
                    VALID[t] = torch.as_tensor(~(resetting | guided), dtype=torch.float32)
                    te = time.perf_counter()
                    nobs, r, term, trunc, info = env.step(env_act)
                    t_env += time.perf_counter() - te
                    nobs = torch.as_tensor(nobs)
                    term_t = torch.as_tensor(term, dtype=torch.float32)
                    done = np.asarray(term, bool) | np.asarray(trunc, bool)
                    done_t = torch.as_tensor(done, dtype=torch.float32)
                    phi_next = A.potential(nobs, k, args.v_flat) if args.shaping else torch.zeros(N)
                    shaped = torch.as_tensor(r, dtype=torch.float32) + args.gamma * phi_next * (1 - term_t) - phi
                    RW[t] = shaped * args.reward_scale * VALID[t]
                    TERM[t], DONE[t] = term_t, done_t
                    ended = done & ~resetting
                    if ended.any():
                        won = np.asarray(info["is_success"], bool)
                        own = ended if guide is None else ended & (guide.demo < 0)
                        succ += int(won[own].sum())
                        ends += int(own.sum())
                        if guide is not None:
                            guide.record(np.flatnonzero(ended), won[ended])
                    if guide is not None:
                        guide.advance()
                    keep = torch.as_tensor(~resetting, dtype=torch.float32)
                    mem[:, 0] = (mem[:, 0] + torch.as_tensor(np.asarray(info["impacts"]), dtype=torch.float32)) * keep
                    mem[:, 1] = (mem[:, 1] + 1) * keep
                    obs, phi = nobs, phi_next
                    if guide is not None and resetting.any():  # their reset step: the next episode's start
                        start_guided(np.flatnonzero(resetting))
                        phi = A.potential(obs, k, args.v_flat) if args.shaping else torch.zeros(N)
                    resetting = done
                ep_window = (ep_window + [(succ, ends)])[-(k.max_steps // T + 1):]
                tu = time.perf_counter()
                next_v = agent.value(A.features(obs, mem, k))
                adv = torch.zeros(T, N)
                last = torch.zeros(N)
                for t in reversed(range(T)):
                    nv = next_v if t == T - 1 else V[t + 1]
                    delta = RW[t] + args.gamma * nv * (1 - TERM[t]) - V[t]
                    last = (delta + args.gamma * args.gae_lambda * (1 - DONE[t]) * last) * VALID[t]
                    adv[t] = last
                ret = adv + V
            stats = {**update(agent, opt, args, X, ACT, LP, adv, ret, V, VALID), "std_floor": state["floor"]}
            t_upd += time.perf_counter() - tu
            state["it"], state["global_step"] = it, it * N * T
            global_step = state["global_step"]
            wall = time.perf_counter() - t0 - t_aside
            state["wall"] = wall
            sc, ec = map(sum, zip(*ep_window))
            train_success = sc / ec if ec else float("nan")
            ta = time.perf_counter()
            val = float("nan")
            if val_next is not None and (global_step >= val_next or it == iterations):
                while val_next <= global_step:
                    val_next += args.val_every
                ev = evaluate(HeadingPolicy(agent, k), args.env_id, args.env_kwargs,
                              range(VAL_SEED, VAL_SEED + args.val_episodes))
                val = ev["successes"] / ev["episodes"]
                state["curve"].append((global_step, val))
                if val >= best["val"]:  # (ties: the later, longer-trained policy)
                    best.update(val=val, agent=copy.deepcopy(agent))
                if log:
                    log(f"[ppo_heading] {global_step:,} steps, {global_step / wall:,.0f} steps/s, train success "
                        f"{train_success:.3f}, validation {val:.3f}, std {stats['std']:.3f}, kl "
                        f"{stats['approx_kl']:.4f}, lr {stats['lr']:.1e}"
                        + (f", guide {guide.summary()['guide_frac']:.2f}" if guide is not None else ""))
            if progress:
                row = {"global_step": global_step, "wall_s": round(wall, 1), "train_success": round(train_success, 4),
                       "val_success": val, "steps_per_s": round(global_step / wall), **stats,
                       **(guide.summary() if guide is not None else {})}
                progress.write(",".join(str(row.get(c, "")) for c in PROGRESS) + "\n")
                progress.flush()
            for c in checkpoints:
                if global_step >= c and c not in passed:
                    passed.add(c)
                    if on_checkpoint is not None and global_step not in called_at:
                        called_at.add(global_step)
                        on_checkpoint(global_step, policy())
            if out is not None and (global_step >= save_next or it == iterations):
                while save_next <= global_step:
                    save_next += args.save_every
                save(out / "checkpoint.pt")
            t_aside += time.perf_counter() - ta
    except KeyboardInterrupt:
        if progress:
            progress.close()
        env.close()
        path = save(out / "checkpoint.pt") if out is not None and state["it"] > 0 else None
        raise Interrupted(state["global_step"], path) from None
    global_step = state["global_step"]
    wall = time.perf_counter() - t0 - t_aside
    env.close()
    if progress:
        progress.close()
    if on_checkpoint is not None and global_step not in called_at:
        on_checkpoint(global_step, policy())
    results = {"env_id": args.env_id, "env_kwargs": args.env_kwargs, "seed": args.seed, "env_steps": global_step,
               "wall_time_s": wall, "steps_per_s": global_step / max(wall, 1e-9), "env_time_s": t_env,
               "update_time_s": t_upd, "train_success": train_success, "val_curve": state["curve"],
               "best_val": best["val"] if best["agent"] is not None else None,
               **stats, **(guide.summary() if guide is not None else {})}
    if out is not None:
        torch.save(agent.state_dict(), out / "model.pt")
        if best["agent"] is not None:
            torch.save(best["agent"].state_dict(), out / "best_model.pt")
    if log:
        log(f"[ppo_heading] {global_step:,} steps in {wall:.0f} s ({global_step / max(wall, 1e-9):,.0f} steps/s; env "
            f"{t_env:.0f} s, update {t_upd:.0f} s), train success {train_success:.3f}")
    results["policy"] = policy()
    results["final_policy"] = HeadingPolicy(agent, k)  # (the last update's, without early stopping)
    return results


def noise_floor(args: Args, floor: float, train_success: float) -> float:
    """The noise floor for the next update (``explore_until`` > 0): std_init while the training success is 0,
    std_min once it reaches explore_until, linear between, and never above the floor before (a success that falls
    later does not widen the noise again). Why: with the floor at std_min from the start, the noise reached it
    (about 2e7 env steps) before some seeds had parked once, and those seeds then took 5e7-6e7 env steps to find
    their first parks (docs/ladder.md, the seeds' curves); the seeds that parked while the noise was wide learned."""
    if args.explore_until <= 0 or math.isnan(train_success):
        return floor
    top = max(args.std_init, args.std_min)
    share = min(max(1.0 - train_success / args.explore_until, 0.0), 1.0)
    return min(floor, args.std_min + (top - args.std_min) * share)


def update(agent: Agent, opt, args: Args, X, ACT, LP, adv, ret, V, VALID) -> dict:
    """Epochs of clipped-objective minibatch updates on the valid transitions; the learning rate adapted to the
    update's mean KL (lr_schedule "kl"); the update's diagnostics."""
    keep = VALID.reshape(-1).bool()
    bx, ba, blp = X.reshape(-1, X.shape[-1])[keep], ACT.reshape(-1, ACT.shape[-1])[keep], LP.reshape(-1)[keep]
    badv, bret, bval = adv.reshape(-1)[keep], ret.reshape(-1)[keep], V.reshape(-1)[keep]
    n = bx.shape[0]
    kls, clips, vls, gns = [], [], [], []
    stop = False
    for _ in range(args.update_epochs):
        perm = torch.randperm(n)
        for s0 in range(0, n, args.minibatch_size):
            mb = perm[s0:s0 + args.minibatch_size]
            if len(mb) < 2:
                continue
            mean, norm = agent.mean(bx[mb])
            logratio = agent.log_prob(mean, ba[mb]) - blp[mb]
            ratio = logratio.exp()
            with torch.no_grad():
                kls.append(float(((ratio - 1) - logratio).mean()))
                clips.append(float(((ratio - 1).abs() > args.clip_coef).float().mean()))
            ma = badv[mb]
            ma = (ma - ma.mean()) / (ma.std() + 1e-8)
            pg = torch.max(-ma * ratio, -ma * ratio.clamp(1 - args.clip_coef, 1 + args.clip_coef)).mean()
            v_new = agent.value(bx[mb])
            vl = (v_new - bret[mb]) ** 2
            if args.clip_vloss:
                v_clip = bval[mb] + (v_new - bval[mb]).clamp(-args.clip_coef, args.clip_coef)
                vl = torch.max(vl, (v_clip - bret[mb]) ** 2)
            entropy = (0.5 + 0.5 * math.log(2 * math.pi) + agent.log_std.clamp(*agent.log_std_range)).sum()
            loss = pg + args.vf_coef * vl.mean() - args.ent_coef * entropy
            if norm is not None:
                loss = loss + args.norm_coef * ((norm - 1.0) ** 2).mean()
            opt.zero_grad()
            loss.backward()
            gns.append(float(nn.utils.clip_grad_norm_(agent.parameters(), args.max_grad_norm)))
            vls.append(float(vl.mean().detach()))
            opt.step()
            if args.target_kl and kls[-1] > args.target_kl:
                stop = True
                break
        if stop:
            break
    kl = float(np.mean(kls)) if kls else 0.0
    if args.lr_schedule == "kl":
        lr = opt.param_groups[0]["lr"]
        if kl > 2.0 * args.desired_kl:
            lr = max(args.lr_min, lr / 1.5)
        elif kl < 0.5 * args.desired_kl:
            lr = min(args.lr_max, lr * 1.5)
        opt.param_groups[0]["lr"] = lr
    return {"approx_kl": kl, "clip_frac": float(np.mean(clips)) if clips else 0.0, "minibatches": len(kls),
            "std": float(agent.std().mean().detach()), "value_loss": float(np.mean(vls)) if vls else 0.0,
            "explained_variance": explained_variance(bval, bret), "grad_norm": float(np.mean(gns)) if gns else 0.0,
            "lr": float(opt.param_groups[0]["lr"])}


def main(argv=None):
    """The command line every ladder agent shares (training/agent_cli.py)."""
    from training.agent_cli import cli
    return cli("training.ppo_heading", Args, train, argv, quick_args, CHECKS)


if __name__ == "__main__":
    main()
