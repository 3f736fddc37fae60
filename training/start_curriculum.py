"""curriculum (PRIVILEGED): a start-state curriculum from demonstrations (Salimans & Chen, "Learning Montezuma's
Revenge from a Single Demonstration", 2018) on a PPO learner, over penny_env's native vector env.

    python -m training.start_curriculum --env-id PennyProbeSteer-Ellipse-Elastic-v0 --demos DEMOS.npz
                                        [--total-timesteps 5e6] [--seed 0] [--set FIELD=VALUE ...]
                                        [--hp NAME=VALUE ...] [--quick] [--eval] [--out DIR]

**Privileged, in training only.** Training episodes start at states of demonstrations (``Args.demos``: an .npz of
training.protocol.save_demos, e.g. certified witness episodes of training seeds >= 100,000, made by
studies/witness_demos.py): the env is reset to the chosen state and target (``PennyVectorEnv.reset(options={"state",
"target", "reset_mask"})``). Nothing else is privileged: the policy sees the observation, ``info["impacts"]`` (its
own impact counter) and its own clock; the evaluation starts from the task's own starts. Every table labels it
PRIVILEGED.

**The curriculum.** Per demonstration j (length T_j steps, impacts counted by replaying its actions) a start step
k_j, first ``T_j - back`` (``back`` = max(1, time limit // 50): 8 steps on the steer probes' 400, 4 on the drive
probes' 200). An episode started for demonstration j begins at its state k_j - u (u uniform in [0, back), never
below 0), with the agent's clock set to that step and its impact counter to the demonstration's impacts before it,
and the agent truncates it when its clock reaches the time limit (the real episode's remaining time). Once at least
``min_episodes`` episodes from demonstration j's current start have ended and at least ``threshold`` (20 %) of them
succeeded, k_j moves back by ``back`` steps (``back`` times the number of whole thresholds the success rate holds, at
most ``max_moves`` = 4 times: 80 % moves back 4 x ``back``; the budget of 5e6 env steps holds about 250 episodes per
demonstration, too few for 30 single moves); when a demonstration succeeds from k_j = 0 (the real episode's start)
it is done. Many demonstrations run at once: each episode that ends picks its next start, with probability
``p_own`` plus the share of finished demonstrations from the task's own start distribution (training seeds from
10,000,000), else at a uniformly drawn unfinished demonstration. When every demonstration is done, every episode
starts at the task's own starts (reverse curriculum generation, Florensa et al. 2017, moves starts back likewise
but by random walks from the goal; here the demonstrations give the path).

**The learner.** PPO (CleanRL's continuous-action PPO), 1024 envs x 32 steps, minibatches of 4096, 4 epochs with a
KL stop (0.03), Adam 3e-4, gamma 0.999, GAE lambda 0.95, clip 0.2, no entropy bonus, separate 64-64 tanh MLPs,
state-independent log-std (init -0.5), advantages normalised per minibatch; the env's fair reward (success bonus 10
only) plus the agent's potential-based shaping from the success test (training/agent_side.potential, v_flat 0.5;
it keeps the optimal policies, Ng et al. 1999); agent-side features (training/agent_side.features, with the agent's
clock and impact counter); action head "pd": the policy outputs a heading (steer: the agent's PD law turns it into
the steering torque) or a rolling speed (drive: its P law turns it into the rolling torque); "torque": the env's
actions. Reset transitions of the NEXT_STEP autoreset are masked out, as in training/ppo_torch.py.

**Recommended.** 5e6 env steps per seed (the issue's budget for privileged agents on the CPU), the defaults above;
demonstrations: the certified witness episodes of 200 training seeds (>= 100,000) of the same cell.
"""
from __future__ import annotations

import copy
import dataclasses
import time
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn as nn

from . import agent_side as A
from .protocol import fair_reward_kwargs, load_demos


@dataclass
class Args:
    env_id: str = "PennyProbeSteer-Stadium-Elastic-v0"
    env_kwargs: dict = dataclasses.field(default_factory=dict)
    seed: int = 0
    total_timesteps: int = 5_000_000
    torch_threads: int = 1
    out: str | None = None
    demos: str | None = None        # .npz of training.protocol.save_demos (PRIVILEGED)
    num_envs: int = 1024
    num_steps: int = 32
    minibatch: int = 4096
    epochs: int = 4
    target_kl: float = 0.03         # stop the epochs of an update once the approximate KL passes it (0: never)
    lr: float = 3e-4
    gamma: float = 0.999
    gae_lambda: float = 0.95
    clip: float = 0.2
    ent_coef: float = 0.0
    vf_coef: float = 0.5
    max_grad_norm: float = 0.5
    hidden: int = 64
    log_std_init: float = -0.5
    head: str = "pd"
    shaping: bool = True            # the agent's potential-based shaping (agent_side.potential)
    v_flat: float = 0.5
    fair_reward: bool = True        # the env's reward reduced to the success bonus (training.protocol.FAIR_REWARD)
    threshold: float = 0.2          # Salimans & Chen's 20 %
    min_episodes: int = 8           # episodes from a start before it may move back
    back: int = 0                   # steps per move back (0: max(1, time limit // 50))
    max_moves: int = 4              # a start with success rate r moves back min(max_moves, r // threshold) x back
    p_own: float = 0.1              # share of episodes from the task's own starts while demonstrations remain
    train_seed: int = 10_000_000
    val_every: int = 0              # env steps between validation evaluations (0: none)
    val_episodes: int = 200
    val_seed: int = 50_000


class Agent(nn.Module):
    def __init__(self, n_in, n_out, h, log_std_init):
        super().__init__()
        self.critic = A.mlp(n_in, 1, h, 1.0)
        self.actor = A.mlp(n_in, n_out, h, 0.01)
        self.log_std = nn.Parameter(torch.full((1, n_out), float(log_std_init)))

    def dist(self, x):
        mu = self.actor(x)
        return torch.distributions.Normal(mu, self.log_std.expand_as(mu).exp())


def make_policy(agent: Agent, k: A.TaskConsts, head: str) -> A.ActorPolicy:
    return A.ActorPolicy(copy.deepcopy(agent.actor).eval(), k, head)


def demo_episodes(demos: dict):
    """[(states (T+1, 6), target (2,), actions (T, n_act))] from save_demos' arrays."""
    out = []
    for j, T in enumerate(demos["length"]):
        rows = np.flatnonzero(demos["episode"] == j)
        rows = rows[np.argsort(demos["step"][rows])]
        first_action = int(np.sum(demos["length"][:j]))
        out.append((demos["states"][rows], demos["targets"][rows[0]], demos["actions"][first_action:first_action + T]))
    return out


def replay_impacts(env_id, env_kwargs, episodes, seed=10_000_000):
    """Per demonstration, the impacts before each of its states (T+1,) and whether the replay of its actions from its
    first state (a reset to it) reproduced its states bitwise."""
    D = len(episodes)
    vec = A.make_vec(env_id, D, env_kwargs)
    S0 = np.stack([s[0] for s, _, _ in episodes])
    G = np.stack([np.asarray(g, float) for _, g, _ in episodes])
    vec.reset(seed=seed, options={"state": S0, "target": G})  # (a training seed: its draws are overwritten)
    Tmax = max(len(a) for _, _, a in episodes)
    n_act = vec.single_action_space.shape[0]
    imp = [np.zeros(len(s), np.int64) for s, _, _ in episodes]
    exact = np.ones(D, bool)
    alive = np.ones(D, bool)
    for t in range(Tmax):
        act = np.zeros((D, n_act))
        for j, (_, _, a) in enumerate(episodes):
            if t < len(a):
                act[j] = a[t]
        _, _, term, trunc, info = vec.step(act)
        S = vec.states
        for j, (s, _, a) in enumerate(episodes):
            if alive[j] and t < len(a):
                imp[j][t + 1] = imp[j][t] + int(info["impacts"][j])
                exact[j] &= bool(np.array_equal(S[j], s[t + 1]))
        alive &= ~(np.asarray(term) | np.asarray(trunc))
    vec.close()
    return imp, exact


class Curriculum:
    """The per-demonstration start steps and their success counts (module docstring)."""

    def __init__(self, lengths, back, threshold, min_episodes, rng, max_moves=1):
        self.T = np.asarray(lengths, np.int64)
        self.back, self.threshold, self.min_episodes, self.rng = back, threshold, min_episodes, rng
        self.max_moves = max_moves
        self.k = np.maximum(self.T - back, 0)
        self.stage = np.zeros(len(self.T), np.int64)  # bumped when k moves: outcomes of older starts are ignored
        self.wins = np.zeros(len(self.T), np.int64)
        self.n = np.zeros(len(self.T), np.int64)
        self.done = np.zeros(len(self.T), bool)

    def draw(self, m):
        """(demo, start step, stage) of m episodes, demos uniform among the unfinished."""
        open_ = np.flatnonzero(~self.done)
        j = open_[self.rng.integers(0, len(open_), m)]
        start = np.maximum(self.k[j] - self.rng.integers(0, self.back, m), 0)
        return j, start, self.stage[j].copy()

    def record(self, j, stage, won):
        """Outcomes of episodes started for demos j at their stages."""
        cur = stage == self.stage[j]
        np.add.at(self.n, j[cur], 1)
        np.add.at(self.wins, j[cur], won[cur].astype(np.int64))
        for d in np.unique(j[cur]):
            if self.done[d] or self.n[d] < self.min_episodes or self.wins[d] < self.threshold * self.n[d]:
                continue
            if self.k[d] == 0:
                self.done[d] = True
            else:  # back by `back` steps per multiple of the threshold reached, at most max_moves times
                moves = min(self.max_moves, max(1, int(self.wins[d] / (self.threshold * self.n[d]))))
                self.k[d] = max(self.k[d] - moves * self.back, 0)
                self.stage[d] += 1
                self.wins[d] = self.n[d] = 0

    def progress(self) -> float:
        """Mean share of each demonstration learnt from its start (1: every demonstration done)."""
        return float(np.mean(np.where(self.done, 1.0, 1.0 - self.k / np.maximum(self.T, 1))))


def train(args: Args, checkpoints=(), on_checkpoint=None, log=print, demos=None, step_offset: int = 0) -> dict:
    """Trains for args.total_timesteps env steps (training/protocol.py). demos: save_demos' arrays (a dict) instead of
    args.demos; step_offset: env steps already spent by a caller (go_explore): the checkpoints count them too."""
    torch.set_num_threads(args.torch_threads)
    torch.manual_seed(args.seed)
    rng = np.random.default_rng(args.seed)
    if demos is None:
        if args.demos is None:
            raise ValueError("start_curriculum needs demonstrations: Args.demos (an .npz of protocol.save_demos)")
        demos = load_demos(args.demos)
    episodes = demo_episodes(demos)
    env_kwargs = {**(fair_reward_kwargs(args.env_id, args.env_kwargs) if args.fair_reward else {}), **args.env_kwargs}
    N, T = args.num_envs, args.num_steps
    vec = A.make_vec(args.env_id, N, env_kwargs)
    k = A.TaskConsts.of(vec)
    back = args.back or max(1, k.max_steps // 50)
    imp_demo, exact = replay_impacts(args.env_id, env_kwargs, episodes, args.train_seed) if episodes else ([], np.zeros(0, bool))
    cur = Curriculum([len(a) for _, _, a in episodes], back, args.threshold, args.min_episodes, rng,
                     args.max_moves)
    if not episodes:
        cur.done = np.ones(0, bool)
    n_out = A.head_dim(k, args.head)
    agent = Agent(A.FEATURES_DIM, n_out, args.hidden, args.log_std_init)
    opt = torch.optim.Adam(agent.parameters(), lr=args.lr, eps=1e-5)
    feat = lambda o, m: A.features(o, m, k)  # noqa: E731
    pot = lambda o: A.potential(o, k, args.v_flat)  # noqa: E731

    X = torch.zeros(T, N, A.FEATURES_DIM)
    ACT = torch.zeros(T, N, n_out)
    LP, RW, V, TERM, DONE, VALID, NV = (torch.zeros(T, N) for _ in range(7))
    obs = torch.tensor(vec.reset(seed=args.train_seed + 1_000_000 * args.seed)[0])
    imp, clock = torch.zeros(N), torch.zeros(N)
    # per env: the demo of its episode (-1: the task's own start), its stage; resetting: this step is a reset step
    demo_of = np.full(N, -1)
    stage_of = np.zeros(N, np.int64)
    resetting = np.zeros(N, bool)
    agent_only = np.zeros(N, bool)  # envs whose episode the agent (not the env) ended at the last step
    spare = episodes[0][0][0] if episodes else None  # a valid state for the rows outside a reset mask

    def restart(rows, stepped_on):
        """Choose the next start of the envs `rows` after their reset step and put them there; stepped_on: the rows
        the env did not reset itself (the agent truncated their episode), which a task's own start must reset."""
        nonlocal obs
        own = np.ones(len(rows), bool)
        if len(cur.done) and not cur.done.all():
            own = rng.random(len(rows)) < args.p_own + cur.done.mean()
        demo_of[rows], stage_of[rows] = -1, 0
        imp[rows], clock[rows] = 0.0, 0.0
        use = rows[~own]
        mask = np.zeros(N, bool)
        mask[rows[own & stepped_on]] = True
        if mask.any():  # the task's own start (the env's next episode of its seed)
            o, _ = vec.reset(options={"reset_mask": mask})
            obs[mask] = torch.as_tensor(o[mask])
        if len(use):
            j, start, stage = cur.draw(len(use))
            S = np.tile(spare, (N, 1))
            G = np.tile(episodes[0][1], (N, 1))
            S[use] = np.stack([episodes[d][0][s] for d, s in zip(j, start)])
            G[use] = np.stack([episodes[d][1] for d in j])
            mask = np.zeros(N, bool)
            mask[use] = True
            o, _ = vec.reset(options={"state": S, "target": G, "reset_mask": mask})
            obs[use] = torch.as_tensor(o[use])
            demo_of[use], stage_of[use] = j, stage
            clock[use] = torch.as_tensor(start, dtype=torch.float32)
            imp[use] = torch.as_tensor(np.array([imp_demo[d][s] for d, s in zip(j, start)]), dtype=torch.float32)

    restart(np.arange(N), np.zeros(N, bool))
    pending = sorted(int(c) for c in checkpoints)
    steps, it = 0, 0
    own_wins, own_n = [], []
    cur_wins = cur_n = 0
    curve = []
    t0 = time.perf_counter()
    t_env = t_upd = t_val = 0.0
    next_val = args.val_every if args.val_every else None

    called = []

    def checkpoint(n):
        if on_checkpoint is not None and (not called or called[-1] != n):
            on_checkpoint(n, make_policy(agent, k, args.head))
        called.append(n)

    while pending and step_offset >= pending[0]:  # (passed by a caller's own phase: the initial policy was the agent's)
        checkpoint(pending.pop(0))

    while steps < args.total_timesteps:
        it += 1
        ow = on = 0
        for t in range(T):
            x = feat(obs, torch.stack([imp, clock], 1))
            X[t] = x
            VALID[t] = torch.as_tensor(~resetting, dtype=torch.float32)
            with torch.no_grad():
                d = agent.dist(x)
                a = d.sample()
                LP[t] = d.log_prob(a).sum(-1)
                V[t] = agent.critic(x).squeeze(-1)
            ACT[t] = a
            te = time.perf_counter()
            nobs_np, r, term, trunc, info = vec.step(A.to_env(obs, a, k, args.head).numpy())
            t_env += time.perf_counter() - te
            nobs = torch.tensor(nobs_np)
            term = np.asarray(term, bool)
            valid = ~resetting
            agent_trunc = valid & (demo_of >= 0) & ~term & (clock.numpy() + 1 >= k.max_steps)
            done = valid & (term | np.asarray(trunc, bool) | agent_trunc)
            term_t = torch.as_tensor(term & valid, dtype=torch.float32)
            r_t = torch.as_tensor(r, dtype=torch.float32)
            if args.shaping:
                r_t = r_t + args.gamma * pot(nobs) * (1 - term_t) - pot(obs)
            RW[t] = r_t * VALID[t]
            TERM[t], DONE[t] = term_t, torch.as_tensor(done, dtype=torch.float32)
            NV[t] = 0.0
            if done.any():
                won = np.asarray(info["is_success"], bool) & done
                own = done & (demo_of < 0)
                ow += int(won[own].sum())
                on += int(own.sum())
                dem = done & (demo_of >= 0)
                if dem.any():
                    cur.record(demo_of[dem], stage_of[dem], won[dem])
                    cur_wins += int(won[dem].sum())
                    cur_n += int(dem.sum())
            imp = imp + torch.as_tensor(np.asarray(info["impacts"]), dtype=torch.float32)
            clock = clock + 1
            obs = nobs
            if resetting.any():  # this step was their reset step (the env's autoreset, or the agent's truncation)
                rows = np.flatnonzero(resetting)
                restart(rows, agent_only[rows])
            resetting = done
            agent_only = agent_trunc & ~(term | np.asarray(trunc, bool))
            steps += N
        own_wins.append(ow)
        own_n.append(on)
        # GAE (reset steps masked), then the PPO update
        tu = time.perf_counter()
        with torch.no_grad():
            next_v = agent.critic(feat(obs, torch.stack([imp, clock], 1))).squeeze(-1)
            adv = torch.zeros(T, N)
            last = torch.zeros(N)
            for t in reversed(range(T)):
                nv = next_v if t == T - 1 else V[t + 1]
                delta = RW[t] + args.gamma * nv * (1 - TERM[t]) - V[t]
                last = (delta + args.gamma * args.gae_lambda * (1 - DONE[t]) * last) * VALID[t]
                adv[t] = last
            ret = adv + V
        keep = VALID.reshape(-1).bool()
        bx, ba, blp = X.reshape(-1, A.FEATURES_DIM)[keep], ACT.reshape(-1, n_out)[keep], LP.reshape(-1)[keep]
        badv, bret = adv.reshape(-1)[keep], ret.reshape(-1)[keep]
        n = bx.shape[0]
        stop = False
        for _ in range(args.epochs):
            perm = torch.randperm(n)
            for s0 in range(0, n, args.minibatch):
                mb = perm[s0:s0 + args.minibatch]
                d = agent.dist(bx[mb])
                lp = d.log_prob(ba[mb]).sum(-1)
                logratio = lp - blp[mb]
                ratio = logratio.exp()
                ma = badv[mb]
                ma = (ma - ma.mean()) / (ma.std() + 1e-8)
                pg = torch.max(-ma * ratio, -ma * ratio.clamp(1 - args.clip, 1 + args.clip)).mean()
                vl = ((agent.critic(bx[mb]).squeeze(-1) - bret[mb]) ** 2).mean()
                loss = pg + args.vf_coef * vl - args.ent_coef * d.entropy().sum(-1).mean()
                opt.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_(agent.parameters(), args.max_grad_norm)
                opt.step()
                with torch.no_grad():
                    kl = ((ratio - 1) - logratio).mean().item()
                if args.target_kl and kl > args.target_kl:
                    stop = True
                    break
            if stop:
                break
        t_upd += time.perf_counter() - tu
        total = step_offset + steps
        if pending and total >= pending[0]:
            while pending and total >= pending[0]:
                pending.pop(0)
            checkpoint(total)
        if next_val is not None and steps >= next_val:
            next_val += args.val_every
            tv = time.perf_counter()
            val = A.validate(make_policy(agent, k, args.head), args.env_id, args.env_kwargs, args.val_episodes,
                             args.val_seed)
            t_val += time.perf_counter() - tv
            wall = time.perf_counter() - t0 - t_val
            curve.append((total, val))
            ow_, on_ = sum(own_wins[-20:]), sum(own_n[-20:])
            log(f"curriculum {args.env_id} seed {args.seed}: {total:,} steps, {wall:.0f} s, {steps / wall:,.0f} "
                f"steps/s, curriculum progress {cur.progress():.3f}, demos done {int(cur.done.sum())}/{len(cur.done)}, "
                f"success from demo starts {cur_wins / max(cur_n, 1):.3f}, from own starts {ow_ / max(on_, 1):.3f} "
                f"({on_} episodes), validation {val:.3f}, std {agent.log_std.exp().mean().item():.3f}")
            cur_wins = cur_n = 0
    vec.close()
    wall = time.perf_counter() - t0 - t_val
    checkpoint(step_offset + steps)
    return {"env_steps": step_offset + steps, "wall_time_s": wall, "steps_per_s": steps / wall, "env_s": t_env,
            "update_s": t_upd, "validation_curve": curve, "curriculum_progress": cur.progress(),
            "demos_done": int(cur.done.sum()), "demos": len(episodes), "demos_replayed_exactly": int(exact.sum()),
            "agent": agent.state_dict()}


def quick_args(args: Args) -> Args:
    """--quick: seconds on a few envs (checks the pipeline, learns nothing)."""
    return dataclasses.replace(args, num_envs=16, num_steps=8, minibatch=64, epochs=1, total_timesteps=2048)


def main(argv=None):
    """The command line every ladder agent shares (training.protocol.cli)."""
    from training.protocol import cli
    return cli("training.start_curriculum", Args, train, argv, quick_args)


if __name__ == "__main__":
    main()
