"""PPO with a Random Network Distillation bonus (Burda, Edwards, Storkey & Klimov 2018, "Exploration by Random
Network Distillation", arXiv 1810.12894): the ladder's "ppo_rnd", one file in CleanRL's style (after CleanRL's
ppo_rnd_envpool) over penny_env's native vector env.

    python -m training.ppo_rnd [--env-id PennyProbeSteer-Stadium-Elastic-v0] [--total-timesteps 2e7] [--seed 0]
                               [--set FIELD=VALUE ...] [--hp NAME=VALUE ...] [--eval] [--quick] [--out DIR]

**What it may use** (no privileged information): the env's observation (the policy's and the critic's input,
as is), its reward (the *fair* reward: the success bonus only; progress, speed and control costs 0 in the
training env), terminated/truncated and ``info["is_success"]`` (training statistics only). Its actions are the
env's torques (a Gaussian policy, clipped to [-1, 1] by the env), as the plain PPO's. It never reads the env's
state or target arrays and never resets an env to a chosen state: its only resets are the task's own start
draws (``reset(seed=...)``, and once before training ``reset(options={"reset_mask": ...})`` to spread the
episodes' phases over the time limit).

**The bonus** (as in the paper): a fixed, randomly initialised target network f and a predictor network g
trained to match it on the observations the agent visits; the intrinsic reward of a transition is
||g(o') - f(o')||^2 on the next observation o', normalised (both networks see o' whitened by running
statistics and clipped to [-5, 5]) and divided by a running standard deviation of the intrinsic returns. Novel
observations (say: slow after an impact, near the target) are predicted badly and pay. Two value heads: the
extrinsic one (gamma 0.999, episodic) and the intrinsic one (gamma_int 0.99, non-episodic: it bootstraps
through the episode ends); the advantage is ``EXT_COEF A_ext + INT_COEF A_int`` (the paper's 2 and 1). The
predictor learns on a random UPDATE_PROPORTION of each minibatch.

PPO otherwise as training/ppo_torch.py's ladder configuration: 4096 envs x 32 steps, 2 epochs of minibatches of
16384, Adam 3e-4, GAE lambda 0.95, clip 0.2, NEXT_STEP autoreset with the reset transitions masked.

Protocol (training/protocol.py): ``Args``, ``train(args, checkpoints, on_checkpoint, log)`` and
:class:`RNDPolicy` (deterministic: the actor's mean, clipped; stateless). Seeds: training envs
``TRAIN_SEED + 100_000 seed`` (+ sub-env index), validation ``VAL_SEED`` ..; never the evaluation's 0..199.
"""
from __future__ import annotations

import copy
import dataclasses
import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
import torch.nn as nn
from torch.distributions.normal import Normal
from training.ppo_torch import compute_gae  # (the one GAE over a NEXT_STEP rollout)
from training.protocol import fair_reward_kwargs

# -- hyperparameters ------------------------------------------------------------------------------------
TRAIN_SEED, VAL_SEED = 10_000_000, 50_000


@dataclass
class Args:
    env_id: str = "PennyProbeSteer-Stadium-Elastic-v0"
    env_kwargs: dict = field(default_factory=dict)  # the cell's field overrides (the fair reward goes on top)
    seed: int = 0
    total_timesteps: int = 20_000_000
    torch_threads: int = 1
    out: str | None = None
    num_envs: int = 4096
    num_steps: int = 32
    minibatch_size: int = 16384
    update_epochs: int = 2
    learning_rate: float = 3e-4
    gamma: float = 0.999  # extrinsic (episodic)
    gamma_int: float = 0.99  # intrinsic (non-episodic)
    gae_lambda: float = 0.95
    clip_coef: float = 0.2
    vf_coef: float = 0.5
    ent_coef: float = 0.0
    max_grad_norm: float = 0.5
    ext_coef: float = 2.0
    int_coef: float = 1.0
    reward_scale: float = 0.1  # the success bonus 10 -> 1
    update_proportion: float = 0.25  # share of each minibatch the predictor learns on
    hidden: int = 64
    rnd_hidden: int = 128
    rnd_out: int = 64
    log_std_init: float = 0.0
    desync: bool = True
    val_every: int = 0  # env steps between validation evaluations (0: none)
    val_episodes: int = 200
    quick: bool = False


def quick_args(args: Args) -> Args:
    """--quick: a few thousand steps on 64 envs (seconds; checks the pipeline, learns nothing)."""
    return dataclasses.replace(args, num_envs=64, num_steps=32, minibatch_size=1024,
                               total_timesteps=min(args.total_timesteps, 64 * 32 * 4), val_episodes=16)


def layer(i, o, std=np.sqrt(2)):
    lin = nn.Linear(i, o)
    nn.init.orthogonal_(lin.weight, std)
    nn.init.zeros_(lin.bias)
    return lin


def mlp(n_in, widths, n_out, out_std, act=nn.Tanh):
    layers, k = [], n_in
    for h in widths:
        layers += [layer(k, h), act()]
        k = h
    return nn.Sequential(*layers, layer(k, n_out, out_std))


class Agent(nn.Module):
    """Actor (Gaussian, state-independent log-std) and a critic with two heads (extrinsic, intrinsic)."""

    def __init__(self, obs_dim, act_dim, hidden, log_std_init):
        super().__init__()
        self.actor_mean = mlp(obs_dim, (hidden, hidden), act_dim, 0.01)
        self.actor_logstd = nn.Parameter(torch.full((1, act_dim), float(log_std_init)))
        self.critic = mlp(obs_dim, (hidden, hidden), 2, 1.0)  # (V_ext, V_int)

    def dist(self, x):
        mean = self.actor_mean(x)
        return Normal(mean, self.actor_logstd.expand_as(mean).exp())


class RND(nn.Module):
    """Target f (fixed, random) and predictor g (trained) on whitened observations."""

    def __init__(self, obs_dim, hidden, out):
        super().__init__()
        self.target = mlp(obs_dim, (hidden, hidden), out, np.sqrt(2), nn.LeakyReLU)
        self.predictor = mlp(obs_dim, (hidden, hidden, hidden), out, np.sqrt(2), nn.LeakyReLU)
        for p in self.target.parameters():
            p.requires_grad_(False)

    def error(self, x):
        return ((self.predictor(x) - self.target(x)) ** 2).mean(-1)


class RunningMeanStd:
    """Running mean and variance (Chan et al.'s parallel update), as the paper's normalisers."""

    def __init__(self, shape=()):
        self.mean, self.var, self.count = torch.zeros(shape), torch.ones(shape), 1e-4

    def update(self, x):
        m, v, n = x.mean(0), x.var(0, unbiased=False), x.shape[0]
        delta, tot = m - self.mean, self.count + n
        self.mean = self.mean + delta * n / tot
        self.var = (self.var * self.count + v * n + delta ** 2 * self.count * n / tot) / tot
        self.count = tot


class RNDPolicy:
    """The deterministic policy of training/protocol.py: the actor's mean, clipped (a frozen copy; stateless)."""

    def __init__(self, agent: Agent):
        self.actor = copy.deepcopy(agent.actor_mean).eval()

    def reset(self, num_envs: int) -> None:
        pass

    @torch.no_grad()
    def __call__(self, obs, info) -> np.ndarray:
        x = torch.as_tensor(np.asarray(obs), dtype=torch.float32)
        return self.actor(x).clamp(-1.0, 1.0).numpy().astype(np.float64)


def training_kwargs(args: Args) -> dict:
    """The training env's fields: the cell's overrides and the fair reward's (those the task has)."""
    return {**args.env_kwargs, **fair_reward_kwargs(args.env_id, args.env_kwargs)}


def train(args: Args, checkpoints=(), on_checkpoint=None, log=print) -> dict:
    """Train for args.total_timesteps env steps (training/protocol.py); returns the results dict."""
    import gymnasium as gym

    import penny_env  # noqa: F401
    from training.protocol import evaluate
    if args.quick:
        args = quick_args(args)
    torch.set_num_threads(args.torch_threads)
    torch.manual_seed(args.seed)
    out = Path(args.out) if args.out else None
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        (out / "config.json").write_text(json.dumps(dataclasses.asdict(args), indent=2))
    N, T = args.num_envs, args.num_steps
    env = gym.make_vec(args.env_id, num_envs=N, vectorization_mode="vector_entry_point",
                       **training_kwargs(args)).unwrapped
    obs_dim, act_dim = env.single_observation_space.shape[0], env.single_action_space.shape[0]
    max_steps = int(env.task.max_episode_steps)
    agent = Agent(obs_dim, act_dim, args.hidden, args.log_std_init)
    rnd = RND(obs_dim, args.rnd_hidden, args.rnd_out)
    opt = torch.optim.Adam(list(agent.parameters()) + list(rnd.predictor.parameters()), lr=args.learning_rate,
                           eps=1e-5)
    obs_rms, ret_rms = RunningMeanStd((obs_dim,)), RunningMeanStd()
    int_filter = torch.zeros(N)  # the discounted intrinsic return whose std scales the bonus

    O = torch.zeros(T, N, obs_dim)
    A = torch.zeros(T, N, act_dim)
    LP, RE, RI, VE, VI, TERM, DONE, VALID = (torch.zeros(T, N) for _ in range(8))
    NO = torch.zeros(T, N, obs_dim)  # next observations (the bonus's input)

    obs_np, _ = env.reset(seed=TRAIN_SEED + 100_000 * args.seed)
    seen = [torch.as_tensor(obs_np)]
    if args.desync:  # env i restarts (the task's own start draw) at a random step of one time limit
        when = np.random.default_rng(args.seed).integers(0, max_steps, N)
        zero = np.zeros((N, act_dim), np.float32)
        for step in range(max_steps):
            o, *_ = env.step(zero)
            obs_np, _ = env.reset(options={"reset_mask": when == step})
            if step % 20 == 0:
                seen.append(torch.as_tensor(o))
    obs_rms.update(torch.cat(seen))  # (the paper initialises the normaliser from steps of a random agent)
    obs = torch.as_tensor(obs_np)
    autoreset = torch.zeros(N)

    def whiten(x):
        return ((x - obs_rms.mean) / obs_rms.var.sqrt().clamp(min=1e-6)).clamp(-5, 5)

    checkpoints = sorted(int(c) for c in checkpoints)
    passed, called_at = set(), set()
    iterations = max(1, -(-int(args.total_timesteps) // (N * T)))
    val_next = args.val_every if args.val_every else None
    curve, ep_window = [], []
    t0 = time.perf_counter()
    t_env = t_upd = t_aside = 0.0
    global_step, stats = 0, {}
    progress = open(out / "progress.csv", "w") if out is not None else None
    if progress:
        progress.write("global_step,wall_s,train_success,val_success,steps_per_s,r_int_mean\n")

    for it in range(1, iterations + 1):
        succ = ends = 0
        with torch.no_grad():
            for t in range(T):
                O[t] = obs
                VALID[t] = 1.0 - autoreset
                d = agent.dist(obs)
                act = d.sample()
                A[t], LP[t] = act, d.log_prob(act).sum(-1)
                v = agent.critic(obs)
                VE[t], VI[t] = v[:, 0], v[:, 1]
                te = time.perf_counter()
                nobs, r, term, trunc, info = env.step(act.numpy())
                t_env += time.perf_counter() - te
                nobs = torch.as_tensor(nobs)
                term_t = torch.as_tensor(term, dtype=torch.float32)
                done_t = torch.maximum(term_t, torch.as_tensor(trunc, dtype=torch.float32))
                NO[t] = nobs
                RE[t] = torch.as_tensor(r, dtype=torch.float32) * args.reward_scale * VALID[t]
                TERM[t], DONE[t] = term_t, done_t
                ended = (done_t * VALID[t]).bool()
                if ended.any():
                    succ += int(np.asarray(info["is_success"])[ended.numpy()].sum())
                    ends += int(ended.sum())
                autoreset = done_t
                obs = nobs
            ep_window = (ep_window + [(succ, ends)])[-(max_steps // T + 1):]
            tu = time.perf_counter()
            # the bonus of every transition, then its scale from the running std of the intrinsic returns
            r_int = rnd.error(whiten(NO.reshape(-1, obs_dim))).reshape(T, N) * VALID
            for t in range(T):
                int_filter = int_filter * args.gamma_int + r_int[t]
                if VALID[t].any():
                    ret_rms.update(int_filter[VALID[t].bool()])
            RI.copy_(r_int / ret_rms.var.sqrt().clamp(min=1e-8))
            obs_rms.update(NO.reshape(-1, obs_dim)[VALID.reshape(-1).bool()])
            nv = agent.critic(obs)
            adv_e, ret_e = compute_gae(RE, VE, TERM, DONE, VALID, nv[:, 0], args.gamma, args.gae_lambda)
            zeros = torch.zeros_like(TERM)  # intrinsic: non-episodic (bootstraps through the ends)
            adv_i, ret_i = compute_gae(RI, VI, zeros, DONE, VALID, nv[:, 1], args.gamma_int, args.gae_lambda)
        keep = VALID.reshape(-1).bool()
        bo, ba, blp = O.reshape(-1, obs_dim)[keep], A.reshape(-1, act_dim)[keep], LP.reshape(-1)[keep]
        bno = whiten(NO.reshape(-1, obs_dim)[keep])
        badv = (args.ext_coef * adv_e + args.int_coef * adv_i).reshape(-1)[keep]
        bret_e, bret_i = ret_e.reshape(-1)[keep], ret_i.reshape(-1)[keep]
        n = bo.shape[0]
        for _ in range(args.update_epochs):
            perm = torch.randperm(n)
            for s0 in range(0, n, args.minibatch_size):
                mb = perm[s0:s0 + args.minibatch_size]
                d = agent.dist(bo[mb])
                logratio = d.log_prob(ba[mb]).sum(-1) - blp[mb]
                ratio = logratio.exp()
                with torch.no_grad():
                    approx_kl = ((ratio - 1) - logratio).mean()
                ma = badv[mb]
                ma = (ma - ma.mean()) / (ma.std() + 1e-8)
                pg = torch.max(-ma * ratio, -ma * ratio.clamp(1 - args.clip_coef, 1 + args.clip_coef)).mean()
                v = agent.critic(bo[mb])
                vl = ((v[:, 0] - bret_e[mb]) ** 2).mean() + ((v[:, 1] - bret_i[mb]) ** 2).mean()
                sub = mb[torch.rand(len(mb)) < args.update_proportion]
                sub = sub if len(sub) else mb[:1]
                fwd = rnd.error(bno[sub]).mean()
                loss = pg + args.vf_coef * vl - args.ent_coef * d.entropy().sum(-1).mean() + fwd
                opt.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_(list(agent.parameters()) + list(rnd.predictor.parameters()),
                                         args.max_grad_norm)
                opt.step()
        t_upd += time.perf_counter() - tu
        stats = {"approx_kl": float(approx_kl), "rnd_loss": float(fwd.detach()), "r_int_mean": float(RI.mean())}
        global_step = it * N * T
        wall = time.perf_counter() - t0 - t_aside
        sc, ec = map(sum, zip(*ep_window))
        train_success = sc / ec if ec else float("nan")
        ta = time.perf_counter()
        val = float("nan")
        if val_next is not None and (global_step >= val_next or it == iterations):
            while val_next <= global_step:
                val_next += args.val_every
            ev = evaluate(RNDPolicy(agent), args.env_id, args.env_kwargs,
                          range(VAL_SEED, VAL_SEED + args.val_episodes))
            val = ev["successes"] / ev["episodes"]
            curve.append((global_step, val))
            if log:
                log(f"[ppo_rnd] {global_step:,} steps, {global_step / wall:,.0f} steps/s, train success "
                    f"{train_success:.3f}, validation {val:.3f}, r_int {stats['r_int_mean']:.3f}, rnd loss "
                    f"{stats['rnd_loss']:.4f} (env {t_env:.0f} s, update {t_upd:.0f} s, wall {wall:.0f} s)")
        for c in checkpoints:
            if global_step >= c and c not in passed:
                passed.add(c)
                if on_checkpoint is not None and global_step not in called_at:
                    called_at.add(global_step)
                    on_checkpoint(global_step, RNDPolicy(agent))
        t_aside += time.perf_counter() - ta
        if progress:
            progress.write(f"{global_step},{wall:.1f},{train_success:.4f},{val},{global_step / wall:.0f},"
                           f"{stats['r_int_mean']:.4f}\n")
            progress.flush()
    wall = time.perf_counter() - t0 - t_aside
    env.close()
    if progress:
        progress.close()
    if on_checkpoint is not None and global_step not in called_at:
        on_checkpoint(global_step, RNDPolicy(agent))
    results = {"env_id": args.env_id, "env_kwargs": args.env_kwargs, "seed": args.seed, "env_steps": global_step,
               "wall_time_s": wall, "steps_per_s": global_step / wall, "env_time_s": t_env, "update_time_s": t_upd,
               "train_success": train_success, "val_curve": curve, **stats}
    if out is not None:
        torch.save({"agent": agent.state_dict(), "rnd": rnd.state_dict()}, out / "model.pt")
        (out / "results.json").write_text(json.dumps(results, indent=2))
    if log:
        log(f"[ppo_rnd] {global_step:,} steps in {wall:.0f} s ({global_step / wall:,.0f} steps/s; env {t_env:.0f} s, "
            f"update {t_upd:.0f} s), train success {train_success:.3f}")
    results["policy"] = RNDPolicy(agent)
    return results


def main(argv=None):
    """The command line every ladder agent shares (training.protocol.cli)."""
    from training.protocol import cli
    return cli("training.ppo_rnd", Args, train, argv, quick_args)


if __name__ == "__main__":
    main()
