"""her: goal-conditioned SAC with hindsight experience replay (Andrychowicz et al., NeurIPS 2017) at the env's speed,
in FastTD3's style (Seo et al. 2025, arXiv 2505.22642: thousands of parallel envs, large batches, LayerNorm critics,
one gradient step per vector step), over penny_env's native vector env, in one torch file.

    python -m training.her_sac --env-id PennyProbeSteer-Stadium-Elastic-v0 --total-timesteps 2e7 [--seed 0]
                               [--set FIELD=VALUE ...] [--hp NAME=VALUE ...] [--quick] [--eval]
                               [--out DIR | --resume DIR]

**What it may use (no privileged information).** The env's observation, its terminated/truncated flags and
``info["impacts"]``, and the cell's published constants (training/agent_side.TaskConsts: R, the tolerances, L, the
observation scales, the torque gains, the time limit) to decode the observation. Not the env's reward (it computes
its own goal reward below, from the observation), never the env's state or target arrays, never a reset to a
chosen state. It trains from the task's own starts (training seeds from 10,000,000).

**The goal task.** The probes become goal tasks with goals in physical units:

* reach (drive-only probe): achieved goal = the contact point (x, y) [m], decoded from obs 0, 1; desired goal =
  the target (contact point + obs 8, 9 scaled by L); success(achieved, goal) = |achieved - goal| < tolerance.
* park (steer-only probe): coming to rest is part of the goal. Achieved goal = (x, y, v, w): the contact point, the
  signed rolling speed v = R theta_dot [m/s] (decoded obs 6) and the turning rate w = phi_dot [rad/s] (decoded obs
  7); desired goal = (target x, target y, 0, 0); success(achieved, goal) = |position - goal position| <
  tolerance and |v - goal v| < speed_tolerance and |w - goal w| < spin_tolerance, the published tolerances of the
  task (0.02 m, 0.01 m/s, 0.5 rad/s on the probes). For the desired goal (v = w = 0) this is the env's own success
  test (d < tolerance, |R theta_dot| < speed_tolerance, |phi_dot| < spin_tolerance), recomputed from the decoded
  observation; a relabelled goal asks for the position and the speeds the penny actually had at a later step.

Reward: 0 on a step whose next achieved goal meets the goal, else -1; such a step is terminal for that goal (no
bootstrap; the env itself terminates on the real goal's success). Relabelling ("future", k = 4): a sampled
transition keeps its episode's goal with probability 1 / (1 + k), else takes the achieved goal of a uniformly drawn
later step of the same episode (the step itself included).

**The agent.** SAC (Haarnoja et al. 2018, automatic entropy temperature), two Q nets with Polyak targets, 256-256
ReLU MLPs, tanh-squashed Gaussian actions. Inputs: training/agent_side.features with the goal's position as the
target (19) plus, for park, the goal speeds' offsets (goal v - v) / speed_tolerance and (goal w - w) /
spin_tolerance (clipped); the agent's own clock and impact counter are features. Action head ("pd", default): the
actor outputs a heading (cos, sin) turned into the steering torque by the agent's PD law (steer), or a rolling speed
turned into the rolling torque by its P law (drive), as in training/agent_side.to_env; "torque": the env's actions.

**Scale** (the defaults): 2048 envs, batches of 8192, one gradient step per vector step (4 samples per
transition), a replay of 1024 steps per env (2M transitions), 256-256 networks with LayerNorm in the critics, gamma
0.98, lr 3e-4; 2e7 env steps per seed on the CPU (about 10k gradient steps). FastTD3's distributional critic is not
used: its returns here are bounded by the goal reward's -1 / (1 - gamma).

Command line and checkpoints: training/agent_cli.py (``checkpoint.pt`` holds the networks, the optimisers, the
temperature and the step count; a resumed run starts a new replay memory, which refills from its own policy).
"""
from __future__ import annotations

import copy
import dataclasses
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F

from training import agent_side as A
from training.agent_cli import Interrupted, non_negative, one_of, positive, unit_interval


@dataclass
class Args:
    env_id: str = "PennyProbeSteer-Stadium-Elastic-v0"
    env_kwargs: dict = dataclasses.field(default_factory=dict)
    seed: int = 0
    total_timesteps: int = 1_000_000
    torch_threads: int = 1
    out: str | None = None
    num_envs: int = 2048
    batch_size: int = 8192
    updates_per_step: float = 1.0   # gradient steps per vector step (of num_envs env steps)
    buffer_per_env: int = 1024      # ring buffer length per env
    learning_starts: int = 200_000  # env steps of random actions before the first update
    gamma: float = 0.98
    tau: float = 0.005
    lr: float = 3e-4
    hidden: int = 256
    her_k: int = 4                  # relabelled : original goals
    alpha_init: float = 1.0         # the entropy temperature's start (tuned automatically to entropy -n_act)
    head: str = "pd"                # "pd" (heading / rolling-speed law) or "torque"
    train_seed: int = 10_000_000
    val_every: int = 0              # env steps between validation evaluations (0: none)
    val_episodes: int = 200
    val_seed: int = 50_000
    save_every: int = 2_000_000     # env steps between checkpoint.pt saves (with out)
    quick: bool = False


CHECKS = {"num_envs": positive, "batch_size": positive, "updates_per_step": non_negative, "buffer_per_env": positive,
          "learning_starts": non_negative, "gamma": unit_interval, "tau": unit_interval, "lr": positive,
          "hidden": positive, "her_k": non_negative, "alpha_init": positive, "head": one_of("pd", "torque"),
          "train_seed": non_negative, "val_every": non_negative, "val_episodes": positive, "val_seed": non_negative,
          "save_every": positive}


# -- goals ---------------------------------------------------------------------------------------------
def achieved(obs: torch.Tensor, k: A.TaskConsts) -> torch.Tensor:
    """The achieved goal of an observation: (x, y) for reach, (x, y, v, w) for park (module docstring)."""
    px, py, v, w, _, _ = A.decode(obs, k)
    return torch.stack([px, py, v, w] if k.park else [px, py], 1)


def desired(obs: torch.Tensor, k: A.TaskConsts) -> torch.Tensor:
    """The episode's goal from its observation: the target, and at rest for park."""
    _, _, _, _, tx, ty = A.decode(obs, k)
    z = torch.zeros_like(tx)
    return torch.stack([tx, ty, z, z] if k.park else [tx, ty], 1)


def success(ag: torch.Tensor, g: torch.Tensor, k: A.TaskConsts) -> torch.Tensor:
    """The task's success test between an achieved goal and a goal, from the published tolerances."""
    ok = torch.hypot(ag[:, 0] - g[:, 0], ag[:, 1] - g[:, 1]) < k.tol
    if k.park:
        ok = ok & ((ag[:, 2] - g[:, 2]).abs() < k.vtol) & ((ag[:, 3] - g[:, 3]).abs() < k.wtol)
    return ok


def goal_features(obs, mem, g, k: A.TaskConsts) -> torch.Tensor:
    x = A.features(obs, mem, k, target=g[:, :2])
    if not k.park:
        return x
    _, _, v, w, _, _ = A.decode(obs, k)
    wt = k.wtol if math.isfinite(k.wtol) else 1.0
    return torch.cat([x, ((g[:, 2] - v) / k.vtol / 3).clamp(-3, 3)[:, None],
                      ((g[:, 3] - w) / wt / 3).clamp(-3, 3)[:, None]], 1)


def n_features(k: A.TaskConsts) -> int:
    return A.FEATURES_DIM + (2 if k.park else 0)


# -- networks ------------------------------------------------------------------------------------------
class Actor(nn.Module):
    def __init__(self, n_in, n_act, h):
        super().__init__()
        self.body = nn.Sequential(nn.Linear(n_in, h), nn.ReLU(), nn.Linear(h, h), nn.ReLU())
        self.mu, self.log_std = nn.Linear(h, n_act), nn.Linear(h, n_act)

    def forward(self, x):
        """(tanh-squashed sample, its log-prob, the deterministic action)."""
        z = self.body(x)
        mu, log_std = self.mu(z), self.log_std(z).clamp(-5, 2)
        std = log_std.exp()
        u = mu + std * torch.randn_like(mu)
        a = torch.tanh(u)
        lp = (-0.5 * ((u - mu) / std) ** 2 - log_std - 0.5 * math.log(2 * math.pi)).sum(1)
        lp = lp - (2 * (math.log(2) - u - F.softplus(-2 * u))).sum(1)
        return a, lp, torch.tanh(mu)


class Critic(nn.Module):
    def __init__(self, n_in, n_act, h):
        super().__init__()

        def q():
            return nn.Sequential(nn.Linear(n_in + n_act, h), nn.LayerNorm(h), nn.ReLU(), nn.Linear(h, h),
                                 nn.LayerNorm(h), nn.ReLU(), nn.Linear(h, 1))
        self.q1, self.q2 = q(), q()

    def forward(self, x, a):
        xa = torch.cat([x, a], 1)
        return self.q1(xa).squeeze(-1), self.q2(xa).squeeze(-1)


class _Deterministic(nn.Module):
    def __init__(self, actor):
        super().__init__()
        self.actor = actor

    def forward(self, x):
        return self.actor(x)[2]


def make_policy(actor, k: A.TaskConsts, head: str) -> A.ActorPolicy:
    """The protocol Policy: the deterministic actor (tanh of the mean) on the episode's own goal."""
    det = _Deterministic(copy.deepcopy(actor)).eval()
    return A.ActorPolicy(det, k, head, feature_fn=lambda o, m: goal_features(o, m, desired(o, k), k))


# -- replay with hindsight ----------------------------------------------------------------------------
class HerBuffer:
    """Per-env ring buffers of transitions (obs, counters, action, next obs, next counters, the episode's goal,
    the next achieved goal) with the last step of each transition's episode, for "future" relabelling."""

    def __init__(self, E, C, obs_dim, n_act, gdim):
        self.E, self.C = E, C
        z = lambda *s, dt=torch.float32: torch.zeros(E, C, *s, dtype=dt)  # noqa: E731
        self.obs, self.nobs = z(obs_dim), z(obs_dim)
        self.mem, self.nmem = z(2), z(2)
        self.act = z(n_act)
        self.goal, self.ag = z(gdim), z(gdim)
        self.end = torch.full((E, C), -1, dtype=torch.int64)  # absolute index of the episode's last step, -1: open
        self.written = torch.zeros(E, dtype=torch.int64)       # absolute steps written per env
        self.start = torch.zeros(E, dtype=torch.int64)          # absolute index of the open episode's first step

    def add(self, rows, obs, mem, act, nobs, nmem, goal, ag, ended):
        """One step of the envs `rows` (a LongTensor); ended: their episode ended at this step."""
        pos = self.written[rows] % self.C
        for buf, val in ((self.obs, obs), (self.mem, mem), (self.act, act), (self.nobs, nobs), (self.nmem, nmem),
                         (self.goal, goal), (self.ag, ag)):
            buf[rows, pos] = val
        self.end[rows, pos] = -1
        for e in rows[ended].tolist():  # close the episode: every step of it learns its last step
            w = int(self.written[e])
            lo = max(int(self.start[e]), w - self.C + 1)
            idx = torch.arange(lo, w + 1) % self.C
            self.end[e, idx] = w
            self.start[e] = w + 1
        self.written[rows] += 1

    def size(self) -> int:
        return int(torch.clamp(self.written, max=self.C).sum())

    def sample(self, B, her_k, k: A.TaskConsts):
        e = torch.randint(0, self.E, (B,))
        w = self.written[e]
        n_valid = torch.clamp(w, max=self.C)
        t = w - n_valid + (torch.rand(B) * n_valid).long().clamp(max=n_valid - 1)
        p = t % self.C
        end = self.end[e, p]
        end = torch.where(end < 0, w - 1, end)
        f = t + (torch.rand(B) * (end - t + 1).float()).long().clamp(max=end - t)
        relabel = torch.rand(B) < her_k / (her_k + 1.0)
        g = torch.where(relabel[:, None], self.ag[e, f % self.C], self.goal[e, p])
        ag = self.ag[e, p]
        r_succ = success(ag, g, k)
        return self.obs[e, p], self.mem[e, p], self.act[e, p], self.nobs[e, p], self.nmem[e, p], g, r_succ


# -- training ------------------------------------------------------------------------------------------
def train(args: Args, checkpoints=(), on_checkpoint=None, log=print, resume=None) -> dict:
    """Trains for args.total_timesteps env steps (training/protocol.py): on_checkpoint(env_steps, policy) the first
    time the env-step count reaches each of ``checkpoints`` and at the end; ``resume``: a checkpoint.pt of this run
    (training/agent_cli.py)."""
    if args.quick:
        args = quick_args(args)
    torch.set_num_threads(args.torch_threads)
    torch.manual_seed(args.seed)
    E = args.num_envs
    vec = A.make_vec(args.env_id, E, args.env_kwargs)
    k = A.TaskConsts.of(vec)
    n_out = A.head_dim(k, args.head)
    n_in = n_features(k)
    gdim = 4 if k.park else 2
    actor = Actor(n_in, n_out, args.hidden)
    critic = Critic(n_in, n_out, args.hidden)
    critic_t = copy.deepcopy(critic).requires_grad_(False)
    log_alpha = torch.full((1,), math.log(args.alpha_init), requires_grad=True)
    target_entropy = -float(n_out)
    opt_a = torch.optim.Adam(actor.parameters(), lr=args.lr)
    opt_c = torch.optim.Adam(critic.parameters(), lr=args.lr)
    opt_al = torch.optim.Adam([log_alpha], lr=args.lr)
    buf = HerBuffer(E, args.buffer_per_env, vec.single_observation_space.shape[0], n_out, gdim)
    out = Path(args.out) if args.out else None
    nets = {"actor": actor, "critic": critic, "critic_t": critic_t, "opt_a": opt_a, "opt_c": opt_c, "opt_al": opt_al}
    steps = updates = 0
    started_at = 0
    if resume is not None:
        saved = torch.load(resume, weights_only=False)
        for name, obj in nets.items():
            obj.load_state_dict(saved[name])
        with torch.no_grad():
            log_alpha.copy_(saved["log_alpha"])
        steps, updates, started_at = saved["steps"], saved["updates"], saved["steps"]
        torch.set_rng_state(saved["torch_rng"])
        log(f"[her_sac] resumed from {resume} at {steps:,} env steps (a new replay memory)")

    def save(path):
        tmp = Path(str(path) + ".tmp")
        torch.save({**{name: obj.state_dict() for name, obj in nets.items()}, "log_alpha": log_alpha.detach().clone(),
                    "steps": steps, "updates": updates, "torch_rng": torch.get_rng_state()}, tmp)
        tmp.replace(path)
        return Path(path)

    obs_np, info = vec.reset(seed=args.train_seed + 1_000_000 * args.seed + 1000 * (steps // E))
    obs = torch.tensor(obs_np)
    imp, clock = torch.zeros(E), torch.zeros(E)
    resetting = torch.zeros(E, dtype=torch.bool)  # NEXT_STEP: this step resets these envs (no transition)
    pending = [c for c in sorted(int(c) for c in checkpoints) if c > steps]
    save_next = (steps // args.save_every + 1) * args.save_every
    ep_succ, ep_n, recent = 0, 0, []
    curve = []
    t0 = time.perf_counter()
    t_upd = t_env = 0.0
    all_rows = torch.arange(E)
    next_val = (steps // args.val_every + 1) * args.val_every if args.val_every else None
    # the first learning_starts env steps are random actions, then one update per vector step: a resumed run learns
    # from its first new step (its replay memory refills from the policy)
    learn_from = args.learning_starts if resume is None else steps
    owed_from = updates - (steps - learn_from) * args.updates_per_step / E

    called = []

    def checkpoint(n):
        if on_checkpoint is not None and (not called or called[-1] != n):
            on_checkpoint(n, make_policy(actor, k, args.head))
        called.append(n)

    try:
        while steps < args.total_timesteps:
            mem = torch.stack([imp, clock], 1)
            g = desired(obs, k)
            with torch.no_grad():
                if steps < learn_from:
                    y = torch.rand(E, n_out) * 2 - 1
                else:
                    y = actor(goal_features(obs, mem, g, k))[0]
            te = time.perf_counter()
            nobs_np, _, term, trunc, info = vec.step(A.to_env(obs, y, k, args.head).numpy())
            t_env += time.perf_counter() - te
            nobs = torch.tensor(nobs_np)
            term_t, trunc_t = torch.as_tensor(term), torch.as_tensor(trunc)
            nimp = imp + torch.as_tensor(np.asarray(info["impacts"]), dtype=torch.float32)
            nmem = torch.stack([nimp, clock + 1], 1)
            live = ~resetting
            ended = (term_t | trunc_t) & live
            rows = all_rows[live]
            buf.add(rows, obs[live], mem[live], y[live], nobs[live], nmem[live], g[live], achieved(nobs, k)[live],
                    ended[live])
            n_live = int(live.sum())
            if ended.any():
                s = np.asarray(info["is_success"], bool)[ended.numpy()]
                recent.extend(s.tolist())
                ep_succ += int(s.sum())
                ep_n += int(ended.sum())
                recent = recent[-1000:]
            imp = torch.where(ended | resetting, torch.zeros(E), nimp)
            clock = torch.where(ended | resetting, torch.zeros(E), clock + 1)
            resetting = ended.clone()
            obs = nobs
            steps += n_live
            # gradient steps
            if steps >= learn_from and buf.size() >= args.batch_size and buf.written.min() > 0:
                tu = time.perf_counter()
                owed = owed_from + args.updates_per_step * (steps - learn_from) / E
                n_up = max(0, int(owed) - updates)
                for _ in range(n_up):
                    o, m, a, no, nm, gg, done = buf.sample(args.batch_size, args.her_k, k)
                    x, nx = goal_features(o, m, gg, k), goal_features(no, nm, gg, k)
                    r = done.float() - 1.0
                    alpha = log_alpha.exp().detach()
                    with torch.no_grad():
                        na, nlp, _ = actor(nx)
                        q1t, q2t = critic_t(nx, na)
                        target = r + args.gamma * (1 - done.float()) * (torch.min(q1t, q2t) - alpha * nlp)
                        target = target.clamp(-1.0 / (1 - args.gamma), 0.0)
                    q1, q2 = critic(x, a)
                    lc = F.mse_loss(q1, target) + F.mse_loss(q2, target)
                    opt_c.zero_grad()
                    lc.backward()
                    opt_c.step()
                    pa, lp, _ = actor(x)
                    q1p, q2p = critic(x, pa)
                    la = (alpha * lp - torch.min(q1p, q2p)).mean()
                    opt_a.zero_grad()
                    la.backward()
                    opt_a.step()
                    lal = -(log_alpha * (lp.detach() + target_entropy)).mean()
                    opt_al.zero_grad()
                    lal.backward()
                    opt_al.step()
                    with torch.no_grad():
                        for p_, pt in zip(critic.parameters(), critic_t.parameters()):
                            pt.mul_(1 - args.tau).add_(args.tau * p_)
                    updates += 1
                t_upd += time.perf_counter() - tu
            if pending and steps >= pending[0]:
                while pending and steps >= pending[0]:
                    pending.pop(0)
                checkpoint(steps)
            if next_val is not None and steps >= next_val:
                next_val += args.val_every
                val = A.validate(make_policy(actor, k, args.head), args.env_id, args.env_kwargs, args.val_episodes,
                                 args.val_seed)
                wall = time.perf_counter() - t0
                curve.append((steps, val))
                log(f"her {args.env_id} seed {args.seed}: {steps:,} steps, {wall:.0f} s, "
                    f"{(steps - started_at) / wall:,.0f} steps/s, train success (last 1000 episodes) "
                    f"{np.mean(recent) if recent else 0:.3f}, validation {val:.3f}, alpha {log_alpha.exp().item():.3g}, "
                    f"updates {updates}")
            if out is not None and steps >= save_next:
                while save_next <= steps:
                    save_next += args.save_every
                save(out / "checkpoint.pt")
    except KeyboardInterrupt:
        vec.close()
        raise Interrupted(steps, save(out / "checkpoint.pt") if out is not None and steps > started_at else None) \
            from None
    vec.close()
    wall = time.perf_counter() - t0
    checkpoint(steps)
    if out is not None:
        save(out / "checkpoint.pt")
    return {"env_steps": steps, "wall_time_s": wall, "steps_per_s": (steps - started_at) / wall, "updates": updates,
            "env_s": t_env, "update_s": t_upd, "train_episodes": ep_n, "train_successes": ep_succ,
            "validation_curve": curve}


def quick_args(args: Args) -> Args:
    """--quick: seconds on a few envs (checks the pipeline, learns nothing)."""
    return dataclasses.replace(args, num_envs=16, batch_size=64, hidden=32, learning_starts=256, buffer_per_env=64,
                               total_timesteps=min(args.total_timesteps, 2048), quick=True)


def main(argv=None):
    """The command line every ladder agent shares (training/agent_cli.py)."""
    from training.agent_cli import cli
    return cli("training.her_sac", Args, train, argv, quick_args, CHECKS)


if __name__ == "__main__":
    main()
