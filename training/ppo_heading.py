"""PPO with agent-side control heads and potential-based shaping from the task's success test (the ladder's
"ppo_heading"), one file in CleanRL's style over penny_env's native vector env.

    python -m training.ppo_heading [--env-id PennyProbeSteer-Stadium-Elastic-v0] [--total-timesteps 1e8]
                                   [--seed 0] [--set FIELD=VALUE ...] [--hp NAME=VALUE ...] [--quick] [--out DIR]

**What it may use** (no privileged information): the env's observation, its reward (the *fair* reward: the
success bonus only; progress, speed and control costs set to 0 in the training env), terminated/truncated,
``info["impacts"]`` (counted into the agent's own impact counter), ``info["is_success"]`` (training statistics
only), and the task's published constants (``env.scene``: R, the inertias and torque limits, the observation
scales, the length scale L; ``env.task``: tolerances, the time limit) to decode the observation into physical
units. It never reads the env's state or target arrays (``states``, ``targets``) and never resets an env to a
chosen state: its only resets are the task's own start draws (``reset(seed=...)`` and, once before training,
``reset(options={"reset_mask": ...})`` to spread the episodes' phases).

**Agent design** (all of it on the agent's side of the env's interface):

* Features (19, :func:`features`): the observation decoded with the published constants (rolling speed in
  units of the park speed tolerance, or of 0.1 m/s for reach; a slow flag; phi_dot; the target offset in
  L units, its distance and its body-frame coordinates), the agent's impact counter (log(1 + n), n > 0) and
  its clock (steps since its episode began / the time limit).
* Action heads (by the probe's actuation, read from the action space and the torque limits):
  - steering (steer and both probes): the policy outputs a world-frame heading psi (the angle of a 2-vector
    of the actor, Gaussian noise on the angle with a state-independent std kept in [STD_MIN, STD_MAX]); the
    agent's own PD law ``u1 = clip((KP wrap(psi - phi) - KD phi_dot) / gain1)`` on the observed heading and
    phi_dot turns it into the steering action (the gains of studies/witness.py's heading law);
  - rolling (drive and both probes): the policy outputs a desired rolling speed ``v = V_MAX clip(a, -1, 1)``
    and the agent's own P law ``u2 = clip(KW (v / R - theta_dot) / gain2)`` on the observed theta_dot turns
    it into the rolling action (the gain of studies/witness.py's DriveReach).
  The witness's *strategy* (which heading or speed, when) is not used; only the two servo laws' gains.
* Shaping: F = gamma Phi(s') - Phi(s) added to the fair reward (Phi of a terminal state 0; potential-based, so
  the fair reward's optimal policies are kept, Ng et al. 1999). Park (:func:`park_potential`): the success
  test's three quantities, Phi = -(clip(|v| - v_flat, 0, 5 - v_flat) / (5 - v_flat) + 2 [slow ? min(d/L, 1) : 1]
  + 0.5 [slow ? min(|phi_dot| / spin_tol, 20) / 20 : 1]), v in speed tolerances, slow = |v| < 1. Reach
  (:func:`reach_potential`): Phi = -2 min(d / L, 1).
* Desynchronised episodes: before training, env i restarts (the task's own draw) at a random step of a
  warm-up one time limit long, so a 32-step rollout does not hold every episode at the same phase.

**Stabilisation** (the research prototype, /work/scratch/ladder/ppo_fast.py "v2", collapsed on one of two
seeds when success first became common): the heading is an angle with bounded noise (the prototype's 2-vector
mean could shrink and make its heading noise uniform), the rewards are scaled by REWARD_SCALE (returns of
order 1), the value loss is clipped, each update stops early once its approximate KL passes TARGET_KL, and
the learning rate anneals linearly to 0 over the budget.

PPO: CleanRL's ppo_continuous_action (clipped objective, GAE, advantages normalised per minibatch, separate
tanh MLPs), NEXT_STEP autoreset with the reset transitions masked as in training/ppo_torch.py.

Early stopping on validation (``keep_best``, with ``val_every``): PPO's success rose and then fell on both seeds of
the stadium (train success 0.50 at 5.7e7 env steps, 0.18 at 1e8: the ladder's run of 2026-11-27); the policy handed
to each checkpoint is the one with the best success so far on the validation seeds (VAL_SEED.., never the
evaluation's), a snapshot taken when it was validated.

Protocol (training/protocol.py): ``Args``, ``train(args, checkpoints, on_checkpoint, log)`` and
:class:`HeadingPolicy` (deterministic: the mean heading/speed; its own clock and impact counter, reset by
``reset(num_envs)``). Seeds: training envs ``TRAIN_SEED + 100_000 seed`` (+ sub-env index), validation
``VAL_SEED`` .. + ``val_episodes`` (never the evaluation's pair seeds 0..199).
"""
from __future__ import annotations

import copy
import dataclasses
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
import torch.nn as nn
from training.protocol import evaluate, fair_reward_kwargs

# -- hyperparameters ------------------------------------------------------------------------------------
TRAIN_SEED, VAL_SEED = 10_000_000, 50_000
KP, KD = 25.0, 10.0  # heading PD law [1/s^2, 1/s] (studies/witness.py's)
KW = 40.0  # rolling-speed P law [1/s] (studies/witness.py's DriveReach)
V_MAX = 0.3  # [m/s] the rolling head's largest speed request


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
    learning_rate: float = 3e-4
    anneal_lr: bool = True
    gamma: float = 0.999
    gae_lambda: float = 0.95
    clip_coef: float = 0.2
    clip_vloss: bool = True
    target_kl: float = 0.02  # stop an update's minibatches once approx KL passes it (0: never)
    vf_coef: float = 0.5
    ent_coef: float = 0.0
    max_grad_norm: float = 0.5
    reward_scale: float = 0.1  # (fair reward + shaping) x this: returns of order 1
    hidden: int = 64
    std_init: float = 0.5  # initial action noise (heading: rad; speed: units of V_MAX)
    std_min: float = 0.05  # noise floor and ceiling (the log-std is clamped)
    std_max: float = 2.0
    norm_coef: float = 0.1  # pulls the heading 2-vector's length to 1 (its angle's gradient stays bounded)
    v_flat: float = 0.5  # park potential: speeds under this x speed_tolerance count as 0
    desync: bool = True
    val_every: int = 0  # env steps between validation evaluations (0: none)
    keep_best: bool = True  # with val_every: the policy handed out is the best-validated so far (early stopping)
    val_episodes: int = 200
    quick: bool = False


def quick_args(args: Args) -> Args:
    """--quick: a few tens of thousands of steps on 64 envs (seconds; checks the pipeline, learns nothing)."""
    return dataclasses.replace(args, num_envs=64, num_steps=32, minibatch_size=1024,
                               total_timesteps=min(args.total_timesteps, 64 * 32 * 4), val_episodes=16)


# -- the task's published constants -------------------------------------------------------------------------
class Consts:
    """Constants of the task's definition (scene and task configuration), never the episode's state."""

    def __init__(self, env):
        scene, task = env.scene, env.task
        p = scene.params
        self.R, self.L = float(p["R"]), float(scene.length_scale())
        self.plane = scene.make_table() is None
        self.s_theta, self.s_phi = float(scene.obs_scale["theta_dot"]), float(scene.obs_scale["phi_dot"])
        self.gain1 = float(scene.torque_limits["u1"]) / float(p["J"])
        self.gain2 = float(scene.torque_limits["u2"]) / (float(p["I"]) + float(p["m"]) * self.R ** 2)
        self.park = task.kind == "park"
        self.vtol = float(task.speed_tolerance) if self.park else 0.1  # [m/s] speed unit of the features
        st = getattr(task, "spin_tolerance", None)
        self.wtol = float(st) if st is not None else math.inf
        self.tol = float(task.tolerance)
        self.max_steps = int(task.max_episode_steps)
        self.n_act = int(env.single_action_space.shape[0])
        # the agent's heads, one per actuated control (the scene's published actuation)
        self.heads = {"both": ("steer", "drive"), "steer": ("steer",), "drive": ("drive",)}[scene.actuation]


def atanh(x):
    return torch.atanh(x.clamp(-0.999999, 0.999999))


def wrap(a):
    return torch.remainder(a + math.pi, 2 * math.pi) - math.pi


def decode(obs, k: Consts):
    """(rolling speed R theta_dot / vtol, theta_dot, phi_dot, dx/L, dy/L, d/L) from the observation."""
    W = atanh(obs[:, 6]) * k.s_theta
    w = atanh(obs[:, 7]) * k.s_phi
    dx, dy = obs[:, 8], obs[:, 9]
    if k.plane:
        dx, dy = atanh(dx), atanh(dy)
    return k.R * W / k.vtol, W, w, dx, dy, torch.sqrt(dx * dx + dy * dy)


FEATURES_DIM = 19


def features(obs, mem, k: Consts):
    """The agent's inputs: invertible functions of the observation, plus its own counters mem (N, 2): impacts
    seen in this episode (from info["impacts"]) and steps taken (its clock)."""
    impacts = mem[:, 0]
    v, _, w, dx, dy, d = decode(obs, k)
    c, s = obs[:, 4], obs[:, 5]
    along, across = dx * c + dy * s, -dx * s + dy * c  # the target in the body frame
    sg = torch.where(v < 0, -1.0, 1.0)
    return torch.stack([
        obs[:, 0], obs[:, 1], c, s, obs[:, 6] * 10, obs[:, 7],
        (v / 3).clamp(-3, 3), (v.abs() < 1).float(), (w / 5).clamp(-3, 3),
        dx, dy, d, along * sg, across * sg,
        torch.log1p(impacts) / 2, (impacts > 0).float(), obs[:, 2], obs[:, 3], mem[:, 1] / k.max_steps], dim=1)


def park_potential(obs, k: Consts, v_flat: float):
    v, _, w, _, _, d = decode(obs, k)
    va = v.abs()
    slow = va < 1.0
    one = torch.ones_like(d)
    phi_v = (va - v_flat).clamp(min=0.0, max=5.0 - v_flat) / (5.0 - v_flat)
    phi_d = torch.where(slow, d.clamp(max=1.0), one)
    phi_w = (torch.where(slow, (w.abs() / k.wtol).clamp(max=20.0) / 20.0, one) if math.isfinite(k.wtol)
             else torch.zeros_like(d))
    return -(phi_v + 2.0 * phi_d + 0.5 * phi_w)


def reach_potential(obs, k: Consts):
    return -2.0 * decode(obs, k)[5].clamp(max=1.0)


def potential(obs, k: Consts, v_flat: float):
    return park_potential(obs, k, v_flat) if k.park else reach_potential(obs, k)


# -- the agent ---------------------------------------------------------------------------------------------
def layer(i, o, std=np.sqrt(2)):
    lin = nn.Linear(i, o)
    nn.init.orthogonal_(lin.weight, std)
    nn.init.zeros_(lin.bias)
    return lin


class Agent(nn.Module):
    """Actor: features -> [heading 2-vector (steer)] + [speed request (drive)]; its action (what PPO samples and
    scores) is [heading angle psi] + [a], one noise std per action. Critic: features -> value."""

    def __init__(self, heads, hidden: int, std_init: float, std_min: float, std_max: float):
        super().__init__()
        self.heads = tuple(heads)
        self.steer = "steer" in self.heads
        n_out = 2 * self.steer + ("drive" in self.heads)
        self.n_act = len(self.heads)
        self.critic = nn.Sequential(layer(FEATURES_DIM, hidden), nn.Tanh(), layer(hidden, hidden), nn.Tanh(),
                                    layer(hidden, 1, 1.0))
        self.actor = nn.Sequential(layer(FEATURES_DIM, hidden), nn.Tanh(), layer(hidden, hidden), nn.Tanh(),
                                   layer(hidden, n_out, 0.01))
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
            diff = torch.cat([wrap(diff[:, :1]), diff[:, 1:]], 1)
        log_std = self.log_std.clamp(*self.log_std_range)
        return (-0.5 * (diff / log_std.exp()) ** 2 - log_std - 0.5 * math.log(2 * math.pi)).sum(-1)

    def entropy(self):
        return (0.5 + 0.5 * math.log(2 * math.pi) + self.log_std.clamp(*self.log_std_range)).sum()


def env_action(obs, act, k: Consts, heads):
    """The env's actions from the agent's (heading angle and/or speed request): the agent's servo laws."""
    cols, j = [], 0
    if "steer" in heads:
        phi = torch.atan2(obs[:, 5], obs[:, 4])
        w = atanh(obs[:, 7]) * k.s_phi
        cols.append(((KP * wrap(act[:, j] - phi) - KD * w) / k.gain1).clamp(-1, 1))
        j += 1
    if "drive" in heads:
        W = atanh(obs[:, 6]) * k.s_theta
        v = V_MAX * act[:, j].clamp(-1, 1)
        cols.append((KW * (v / k.R - W) / k.gain2).clamp(-1, 1))
    return torch.stack(cols, 1)


class HeadingPolicy:
    """The deterministic policy of training/protocol.py: mean heading / speed request through the agent's servo
    laws, with the agent's own clock and impact counter (a frozen copy of the actor)."""

    def __init__(self, agent: Agent, k: Consts):
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
        mean, _ = self.agent.mean(features(o, self.mem, self.k))
        return env_action(o, mean, self.k, self.agent.heads).numpy().astype(np.float64)


# -- training -----------------------------------------------------------------------------------------------
def training_kwargs(args: Args) -> dict:
    """The training env's fields: the cell's overrides and the fair reward's (those the task has)."""
    return {**args.env_kwargs, **fair_reward_kwargs(args.env_id, args.env_kwargs)}


def make_env(env_id, num_envs, kwargs):
    import gymnasium as gym
    import penny_env  # noqa: F401
    return gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", **kwargs).unwrapped


def train(args: Args, checkpoints=(), on_checkpoint=None, log=print) -> dict:
    """Train for args.total_timesteps env steps (training/protocol.py); returns the results dict."""
    if args.quick:
        args = quick_args(args)
    torch.set_num_threads(args.torch_threads)
    torch.manual_seed(args.seed)
    out = Path(args.out) if args.out else None
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        (out / "config.json").write_text(json.dumps(dataclasses.asdict(args), indent=2))
    N, T = args.num_envs, args.num_steps
    env = make_env(args.env_id, N, training_kwargs(args))
    k = Consts(env)
    agent = Agent(k.heads, args.hidden, args.std_init, args.std_min, args.std_max)
    opt = torch.optim.Adam(agent.parameters(), lr=args.learning_rate, eps=1e-5)
    A_ = agent.n_act
    X = torch.zeros(T, N, FEATURES_DIM)
    A = torch.zeros(T, N, A_)
    LP, Rw, V, TERM, DONE, VALID = (torch.zeros(T, N) for _ in range(6))

    obs_np, _ = env.reset(seed=TRAIN_SEED + 100_000 * args.seed)
    if args.desync:  # env i restarts (the task's own start draw) at a random step of one time limit
        when = np.random.default_rng(args.seed).integers(0, k.max_steps, N)
        zero = np.zeros((N, k.n_act), np.float32)
        for step in range(k.max_steps):
            env.step(zero)
            obs_np, _ = env.reset(options={"reset_mask": when == step})
    obs = torch.as_tensor(obs_np)
    phi = potential(obs, k, args.v_flat)
    mem = torch.zeros(N, 2)  # the agent's impact counter and clock
    autoreset = torch.zeros(N)

    checkpoints = sorted(int(c) for c in checkpoints)
    passed, called_at = set(), set()  # checkpoints reached; env-step counts at which on_checkpoint ran
    iterations = max(1, -(-int(args.total_timesteps) // (N * T)))
    val_next = args.val_every if args.val_every else None
    curve, ep_window = [], []
    t0 = time.perf_counter()
    t_env = t_upd = t_aside = 0.0
    global_step = 0
    stats = {}
    progress = open(out / "progress.csv", "w") if out is not None else None
    if progress:
        progress.write("global_step,wall_s,train_success,val_success,steps_per_s,std,approx_kl,minibatches\n")

    best = {"val": -1.0, "agent": None}  # keep_best: the best-validated snapshot so far

    def policy():
        """The current policy, or with keep_best the best-validated one so far (a snapshot: training goes on)."""
        return HeadingPolicy(best["agent"] if args.keep_best and best["agent"] is not None else agent, k)

    for it in range(1, iterations + 1):
        if args.anneal_lr:
            opt.param_groups[0]["lr"] = args.learning_rate * (1.0 - (it - 1) / iterations)
        succ = ends = 0
        with torch.no_grad():
            for t in range(T):
                x = features(obs, mem, k)
                X[t] = x
                VALID[t] = 1.0 - autoreset
                mean, _ = agent.mean(x)
                act = mean + agent.std() * torch.randn_like(mean)
                A[t] = act
                LP[t] = agent.log_prob(mean, act)
                V[t] = agent.value(x)
                te = time.perf_counter()
                nobs, r, term, trunc, info = env.step(env_action(obs, act, k, agent.heads).numpy())
                t_env += time.perf_counter() - te
                nobs = torch.as_tensor(nobs)
                term_t = torch.as_tensor(term, dtype=torch.float32)
                done_t = torch.maximum(term_t, torch.as_tensor(trunc, dtype=torch.float32))
                phi_next = potential(nobs, k, args.v_flat)
                shaped = torch.as_tensor(r, dtype=torch.float32) + args.gamma * phi_next * (1 - term_t) - phi
                Rw[t] = shaped * args.reward_scale * VALID[t]
                TERM[t], DONE[t] = term_t, done_t
                ended = (done_t * VALID[t]).bool()
                if ended.any():
                    succ += int(np.asarray(info["is_success"])[ended.numpy()].sum())
                    ends += int(ended.sum())
                mem[:, 0] = (mem[:, 0] + torch.as_tensor(np.asarray(info["impacts"]), dtype=torch.float32)) \
                    * (1 - autoreset)
                mem[:, 1] = (mem[:, 1] + 1) * (1 - autoreset)
                autoreset = done_t  # (NEXT_STEP: the next step resets these envs, and the agent's counters)
                obs, phi = nobs, phi_next
            ep_window = (ep_window + [(succ, ends)])[-(k.max_steps // T + 1):]
            tu = time.perf_counter()
            next_v = agent.value(features(obs, mem, k))
            adv = torch.zeros(T, N)
            last = torch.zeros(N)
            for t in reversed(range(T)):
                nv = next_v if t == T - 1 else V[t + 1]
                delta = Rw[t] + args.gamma * nv * (1 - TERM[t]) - V[t]
                last = (delta + args.gamma * args.gae_lambda * (1 - DONE[t]) * last) * VALID[t]
                adv[t] = last
            ret = adv + V
        keep = VALID.reshape(-1).bool()
        bx, ba, blp = X.reshape(-1, FEATURES_DIM)[keep], A.reshape(-1, A_)[keep], LP.reshape(-1)[keep]
        badv, bret, bval = adv.reshape(-1)[keep], ret.reshape(-1)[keep], V.reshape(-1)[keep]
        n = bx.shape[0]
        n_mb, stop = 0, False
        for _ in range(args.update_epochs):
            perm = torch.randperm(n)
            for s0 in range(0, n, args.minibatch_size):
                mb = perm[s0:s0 + args.minibatch_size]
                mean, norm = agent.mean(bx[mb])
                logratio = agent.log_prob(mean, ba[mb]) - blp[mb]
                ratio = logratio.exp()
                with torch.no_grad():
                    approx_kl = ((ratio - 1) - logratio).mean()
                ma = badv[mb]
                ma = (ma - ma.mean()) / (ma.std() + 1e-8)
                pg = torch.max(-ma * ratio, -ma * ratio.clamp(1 - args.clip_coef, 1 + args.clip_coef)).mean()
                v_new = agent.value(bx[mb])
                vl = (v_new - bret[mb]) ** 2
                if args.clip_vloss:
                    v_clip = bval[mb] + (v_new - bval[mb]).clamp(-args.clip_coef, args.clip_coef)
                    vl = torch.max(vl, (v_clip - bret[mb]) ** 2)
                loss = pg + args.vf_coef * vl.mean() - args.ent_coef * agent.entropy()
                if norm is not None:
                    loss = loss + args.norm_coef * ((norm - 1.0) ** 2).mean()
                opt.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_(agent.parameters(), args.max_grad_norm)
                opt.step()
                n_mb += 1
                if args.target_kl and approx_kl > args.target_kl:
                    stop = True
                    break
            if stop:
                break
        stats = {"approx_kl": float(approx_kl), "minibatches": n_mb, "std": float(agent.std().mean().detach())}
        t_upd += time.perf_counter() - tu
        global_step = it * N * T
        wall = time.perf_counter() - t0 - t_aside
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
            curve.append((global_step, val))
            if val >= best["val"]:  # (ties: the later, longer-trained policy)
                best.update(val=val, agent=copy.deepcopy(agent))
            if log:
                log(f"[ppo_heading] {global_step:,} steps, {global_step / wall:,.0f} steps/s, train success "
                    f"{train_success:.3f}, validation {val:.3f}, std {stats['std']:.3f}, kl {stats['approx_kl']:.4f}, "
                    f"{n_mb} minibatches (env {t_env:.0f} s, update {t_upd:.0f} s, wall {wall:.0f} s)")
        for c in checkpoints:
            if global_step >= c and c not in passed:
                passed.add(c)
                if on_checkpoint is not None and global_step not in called_at:
                    called_at.add(global_step)
                    on_checkpoint(global_step, policy())
        t_aside += time.perf_counter() - ta
        if progress:
            progress.write(f"{global_step},{wall:.1f},{train_success:.4f},{val},{global_step / wall:.0f},"
                           f"{stats['std']:.4f},{stats['approx_kl']:.5f},{n_mb}\n")
            progress.flush()
    wall = time.perf_counter() - t0 - t_aside
    env.close()
    if progress:
        progress.close()
    if on_checkpoint is not None and global_step not in called_at:
        on_checkpoint(global_step, policy())
    results = {"env_id": args.env_id, "env_kwargs": args.env_kwargs, "seed": args.seed, "env_steps": global_step,
               "wall_time_s": wall, "steps_per_s": global_step / wall, "env_time_s": t_env, "update_time_s": t_upd,
               "train_success": train_success, "val_curve": curve, "heads": list(k.heads),
               "best_val": best["val"] if best["agent"] is not None else None, **stats}
    if out is not None:
        torch.save(agent.state_dict(), out / "model.pt")
        if best["agent"] is not None:
            torch.save(best["agent"].state_dict(), out / "best_model.pt")
        (out / "results.json").write_text(json.dumps(results, indent=2))
    if log:
        log(f"[ppo_heading] {global_step:,} steps in {wall:.0f} s ({global_step / wall:,.0f} steps/s; env {t_env:.0f} s,"
            f" update {t_upd:.0f} s), train success {train_success:.3f}")
    results["policy"] = policy()
    return results


def main(argv=None):
    """The command line every ladder agent shares (training.protocol.cli)."""
    from training.protocol import cli
    return cli("training.ppo_heading", Args, train, argv, quick_args)


if __name__ == "__main__":
    main()
