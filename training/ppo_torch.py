"""A compact PPO in torch (CleanRL's ppo_continuous_action, one file) over penny_env's native vector env.

    python -m training.ppo_torch [--env-id PennyReach-Ellipse-v0] [--num-envs 32] [--total-timesteps 1000000]
                                 [--seed 0] [--device auto|cpu|cuda] [--env-backend cuda] [--set FIELD=VALUE ...]
                                 [--quick] [--out DIR]

The environment and the policy stay on one device: the vector env is
``gymnasium.make_vec(env_id, num_envs, vectorization_mode="vector_entry_point")`` (PennyVectorEnv), whose
outputs go through :func:`to_tensor` (numpy today: one ``torch.as_tensor`` per array; a backend whose
outputs are torch tensors on the device passes them through without a copy) and whose actions are handed
back in the env's own array type (:func:`env_actions`). ``--device auto`` is CUDA when torch sees a GPU.

The hyperparameters default to those of configs/train/ppo_reach_ellipse.yaml and to SB3's PPO defaults
(``--config`` reads such a training config): 32 envs x 128 steps per rollout, 10 epochs of minibatches of
1024, Adam 3e-4 (eps 1e-5), gamma 0.99, GAE lambda 0.95, clip 0.2, no value clipping, entropy 0, value
coefficient 0.5, gradient norm 0.5, advantages normalised per minibatch, separate 64-64 tanh MLPs for the
actor mean and the critic with orthogonal initialisation, and a state-independent log-std starting at 0.

**The ladder's configuration** (``ladder_args()``, ``--ladder``): the fast configuration on a CPU
(``FAST_CPU``, ``--fast``: 4096 envs x 32 steps, 2 epochs of minibatches of 16384: 16 gradient steps per rollout
of 131,072 transitions; the update's cost is samples x epochs, so this halves the 4-epoch setting's), gamma 0.999,
the fair reward (training/protocol.py's FAIR_REWARD, ``fair_reward``: the success bonus only, on top of env_kwargs, in the
training env) and training envs seeded from ``env_seed_base`` = 1e7 (never the evaluation's pair seeds).
``devtools/ppo_speed.py`` measures it end to end beside SB3's PPO. torch.compile of the loss was measured on this
CPU (one thread, minibatch 16384, 64-64 MLPs, 2026-11-27, load ~6): 119 ms per gradient step against 110 ms eager
(and 131 ms under bf16 autocast), so it is not used.

**The protocol** (training/protocol.py, the ladder's): :func:`train` takes ``(args, checkpoints, on_checkpoint,
log)``, calls ``on_checkpoint(env_steps, TorchPolicy)`` the first time the env-step count reaches each
checkpoint and at the end, and returns a dict (``env_steps``, ``wall_time_s``, ``steps_per_s``, ``policy``);
:class:`TorchPolicy` is the deterministic policy (the actor's mean, clipped). :func:`train_agent` is the
command's entry (returns ``(agent, results)``, with this module's own final evaluation).

Env fields: a config's ``env_kwargs`` and ``--set FIELD=VALUE`` (YAML values, e.g. ``--set law=plastic
"table={kind: circle, radius: 0.12}" progress_weight=0``) override any scene or task field of the id, as
``gymnasium.make(id, **kwargs)`` does; the evaluation uses the same fields.

On CUDA with the env's state on the device (``--env-backend cuda``, torch outputs), a whole rollout (the
policy's forward pass, the sampling, the env's step and the rollout buffer's writes, ``num_steps`` times) is
captured once in a CUDA graph and replayed at every iteration with ``--cuda-graph on``: the host launches one
graph per rollout instead of a few hundred kernels. It is off by default: on an H200 (2026-11-26) the capture
of the whole rollout failed inside torch while the env's step alone captured and replayed bitwise
(backends/cuda_env.CudaGraphStep, tests/backends/test_cuda.py); eager rollouts trained 30M steps in 14 s there
(docs/ppo_torch_gpu.md). The env's outputs stay valid until the
step after the next (penny_env's device step uses two output sets in turn), which is all a rollout needs.

Autoreset: the vector env runs in NEXT_STEP mode. The step that ends an episode returns the episode's last
observation (the true next state: bootstrapping a truncated episode uses its value) and the *next* step
resets that env, returning its reset observation with reward 0 and no termination: that step's transition
(last obs, action, reset obs) is no transition of any episode. It is kept in the rollout buffer (fixed
shapes, no host sync) but masked out: zero advantage, left out of every minibatch and of the episode
statistics. SB3's adapter (penny_env/sb3.py) instead runs the env in SAME_STEP mode and reads the final
observation from the info; both give the same transitions to learn from.

Output folder (``--out``; default runs/ppo_torch/<env_id>_<seed>; --quick without --out: a new temporary
directory): progress.csv (one row per update: global_step, wall_time_s, success_rate over the last
--success-window finished training episodes, mean_return over them, episodes, the losses, steps_per_s, and
the host seconds so far in env.step and in the updates),
TensorBoard events (``tensorboard --logdir DIR``), model.pt (the agent's state_dict), config.json and
results.json (the final deterministic evaluation on held-out seeds). The folder is printed at the end.
"""
from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import sys
import tempfile
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import torch.nn as nn
from torch.distributions.normal import Normal
from training.protocol import FAIR_REWARD, fair_reward_kwargs  # noqa: F401 (FAIR_REWARD: the reward it trains on)

DEVICES = ("auto", "cpu", "cuda")
ROOT = Path(__file__).resolve().parents[1]  # the checkout (configs/ lives there)


@dataclass
class Args:
    env_id: str = "PennyReach-Ellipse-v0"
    num_envs: int = 32
    total_timesteps: int = 1_000_000
    seed: int = 0
    device: str = "auto"  # auto: cuda if torch.cuda.is_available(), else cpu
    env_backend: str | None = None  # passed to the vector env as backend= when given (e.g. "cuda")
    env_kwargs: dict = dataclasses.field(default_factory=dict)  # scene/task field overrides of the id
    cuda_graph: bool | None = None  # capture each rollout in a CUDA graph (opt-in; None and False: eager)
    curve_points: int = 0  # deterministic evaluations during training, at log-spaced steps (results["curve"])
    num_steps: int = 128  # steps per env per rollout (SB3's n_steps)
    minibatch_size: int = 1024  # SB3's batch_size
    update_epochs: int = 10
    learning_rate: float = 3e-4
    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip_coef: float = 0.2
    ent_coef: float = 0.0
    vf_coef: float = 0.5
    max_grad_norm: float = 0.5
    norm_adv: bool = True
    hidden: tuple = (64, 64)
    log_std_init: float = 0.0
    eval_episodes: int = 100
    success_window: int = 100  # finished training episodes behind the success_rate column (SB3's 100)
    torch_threads: int = 1
    quick: bool = False
    out: str | None = None
    fair_reward: bool = False  # train on FAIR_REWARD (the success bonus only), on top of env_kwargs
    env_seed_base: int | None = None  # training envs reset with seed env_seed_base + 100_000 seed (None: seed)


# the fast configuration on a CPU: few, large minibatches over many envs (the update's cost is samples x epochs)
FAST_CPU = {"num_envs": 4096, "num_steps": 32, "minibatch_size": 16384, "update_epochs": 2, "device": "cpu"}
# the ladder's plain PPO ("ppo"): the fast configuration, gamma 0.999, the fair reward, training seeds >= 1e7
LADDER = {**FAST_CPU, "gamma": 0.999, "gae_lambda": 0.95, "fair_reward": True, "env_seed_base": 10_000_000}


def ladder_args(**changes) -> Args:
    """The ladder's configuration (LADDER) with ``changes`` (env_id, env_kwargs, seed, total_timesteps, ...)."""
    return dataclasses.replace(Args(), **{**LADDER, **changes})


def quick_args(args: Args) -> Args:
    """--quick: a few thousand steps, seconds on a CPU (checks the pipeline, learns little)."""
    return dataclasses.replace(args, total_timesteps=min(args.total_timesteps, 4096), num_steps=32,
                               num_envs=min(args.num_envs, 64), minibatch_size=256, update_epochs=2,
                               eval_episodes=min(args.eval_episodes, 8))


def args_from_config(cfg: dict, **changes) -> Args:
    """Args from a training config (training.train.load_config's dict: SB3's PPO keys) plus changes."""
    kw = cfg.get("algo_kwargs", {})
    names = {"n_steps": "num_steps", "batch_size": "minibatch_size", "n_epochs": "update_epochs",
             "learning_rate": "learning_rate", "gamma": "gamma", "gae_lambda": "gae_lambda", "clip_range": "clip_coef",
             "ent_coef": "ent_coef", "vf_coef": "vf_coef", "max_grad_norm": "max_grad_norm",
             "normalize_advantage": "norm_adv"}
    unknown = sorted(set(kw) - set(names))
    if unknown:
        raise ValueError(f"algo_kwargs: {unknown} have no counterpart in training.ppo_torch; known: {sorted(names)}")
    fields = {names[k]: v for k, v in kw.items()}
    arch = cfg.get("policy_kwargs", {}).get("net_arch")
    if arch is not None:
        fields["hidden"] = tuple(arch)
    for key in ("env_id", "num_envs", "total_timesteps", "seed", "eval_episodes", "env_kwargs"):
        if key in cfg:
            fields[key] = cfg[key]
    return dataclasses.replace(Args(), **{**fields, **changes})


def check_args(args: Args) -> None:
    """ValueError naming the field of any invalid setting."""
    def positive_int(name):
        v = getattr(args, name)
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise ValueError(f"{name} must be a positive integer, got {v!r}")

    for name in ("num_envs", "total_timesteps", "num_steps", "minibatch_size", "update_epochs", "eval_episodes",
                 "success_window", "torch_threads"):
        positive_int(name)
    if isinstance(args.seed, bool) or not isinstance(args.seed, (int, np.integer)) or args.seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {args.seed!r}")
    if args.device not in DEVICES:
        raise ValueError(f"device must be one of {DEVICES}, got {args.device!r}")
    if args.device == "cuda" and not torch.cuda.is_available():
        raise ValueError("device 'cuda' asked for, but torch.cuda.is_available() is False (use --device cpu or auto)")
    for name in ("learning_rate", "clip_coef", "max_grad_norm"):
        if not getattr(args, name) > 0:
            raise ValueError(f"{name} must be positive, got {getattr(args, name)!r}")
    for name in ("gamma", "gae_lambda"):
        if not 0 <= getattr(args, name) <= 1:
            raise ValueError(f"{name} must be in [0, 1], got {getattr(args, name)!r}")
    if not args.hidden or any(isinstance(h, bool) or not isinstance(h, int) or h < 1 for h in args.hidden):
        raise ValueError(f"hidden must be a list of positive layer widths, got {args.hidden!r}")
    import gymnasium as gym
    import penny_env  # noqa: F401  (registers the ids)
    from penny_env.envs.registration import env_ids
    if args.env_id not in gym.registry or args.env_id not in env_ids():
        raise ValueError(f"env_id {args.env_id!r} is not a registered penny_env id; known: {env_ids()}")
    if not isinstance(args.env_kwargs, dict):
        raise ValueError(f"env_kwargs must be a mapping of scene/task fields, got {args.env_kwargs!r}")
    if args.env_kwargs:  # the fields, checked by the env's own resolver (an unknown or bad field is named)
        from penny_env.envs.scene import env_presets, resolve
        fields = {**env_presets()[args.env_id], **args.env_kwargs}  # (env_kwargs may replace the scene itself)
        try:
            resolve(fields.pop("scene"), fields.pop("task"), **fields)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"env_kwargs: {exc}") from None
    if isinstance(args.curve_points, bool) or not isinstance(args.curve_points, int) or args.curve_points < 0:
        raise ValueError(f"curve_points must be a non-negative integer, got {args.curve_points!r}")


def resolve_device(name: str) -> torch.device:
    return torch.device("cuda" if name == "auto" and torch.cuda.is_available() else "cpu" if name == "auto" else name)


# -- the env <-> torch boundary ----------------------------------------------------------------
def env_outputs_torch(env) -> bool:
    """Whether the vector env's outputs (and the actions it takes) are torch tensors on the device.
    A backend that keeps its state on the GPU says so with ``array_namespace == "torch"`` on the
    unwrapped env; the numpy backends (no such attribute) take and give numpy arrays."""
    return getattr(env.unwrapped, "array_namespace", "numpy") == "torch"


def to_tensor(x, device, dtype=torch.float32) -> torch.Tensor:
    """x as a tensor on `device`: a tensor already there (and of that dtype) passes through without a copy,
    numpy arrays go through torch.as_tensor."""
    if torch.is_tensor(x):
        return x.to(device=device, dtype=dtype)
    return torch.as_tensor(np.asarray(x), dtype=dtype, device=device)


def env_actions(actions: torch.Tensor, on_torch: bool):
    """The actions in the env's own array type: the tensor itself, or a float32 numpy array."""
    return actions if on_torch else actions.detach().cpu().numpy()


def reward_kwargs(args: Args) -> dict:
    """FAIR_REWARD's fields that the env's task has (fair_reward), else none."""
    if not args.fair_reward:
        return {}
    return fair_reward_kwargs(args.env_id, args.env_kwargs)


def make_env(args: Args, num_envs: int | None = None):
    import gymnasium as gym
    import penny_env  # noqa: F401
    kwargs = {**args.env_kwargs, **reward_kwargs(args)}
    if args.env_backend is not None:
        kwargs["backend"] = args.env_backend
    return gym.make_vec(args.env_id, num_envs=num_envs or args.num_envs, vectorization_mode="vector_entry_point",
                        **kwargs)


def curve_steps(total: int, points: int, first: int) -> list:
    """``points`` evaluation thresholds, log-spaced from ``first`` (one rollout) to ``total`` env steps."""
    if points <= 0:
        return []
    if points == 1:
        return [total]
    return sorted({int(round(v)) for v in np.geomspace(first, total, points)})


# -- the agent ---------------------------------------------------------------------------------
def layer_init(layer, std=np.sqrt(2), bias_const=0.0):
    torch.nn.init.orthogonal_(layer.weight, std)
    torch.nn.init.constant_(layer.bias, bias_const)
    return layer


def mlp(n_in, hidden, n_out, out_std):
    layers, k = [], n_in
    for h in hidden:
        layers += [layer_init(nn.Linear(k, h)), nn.Tanh()]
        k = h
    return nn.Sequential(*layers, layer_init(nn.Linear(k, n_out), std=out_std))


class Agent(nn.Module):
    def __init__(self, obs_dim: int, act_dim: int, hidden=(64, 64), log_std_init: float = 0.0):
        super().__init__()
        self.critic = mlp(obs_dim, hidden, 1, out_std=1.0)
        self.actor_mean = mlp(obs_dim, hidden, act_dim, out_std=0.01)
        self.actor_logstd = nn.Parameter(torch.full((1, act_dim), float(log_std_init)))

    def get_value(self, x):
        return self.critic(x).squeeze(-1)

    def get_action_and_value(self, x, action=None):
        mean = self.actor_mean(x)
        probs = Normal(mean, self.actor_logstd.expand_as(mean).exp())
        if action is None:
            action = probs.sample()
        return action, probs.log_prob(action).sum(-1), probs.entropy().sum(-1), self.get_value(x)

    def act(self, x):
        """Deterministic actions (the mean), clipped to the action box."""
        return self.actor_mean(x).clamp(-1.0, 1.0)


# -- advantages ----------------------------------------------------------------------------------
def compute_gae(rewards, values, terminations, dones, valid, next_value, gamma, gae_lambda):
    """GAE over a NEXT_STEP rollout; all inputs (T, N) tensors (bools as float), next_value (N,).

    values[t + 1] is the value of the observation step t returned: after an episode's last step that is
    its last observation (bootstrapped unless terminated); the step after it (valid 0) is the env's reset,
    whose advantage is 0. Returns (advantages, returns)."""
    T = rewards.shape[0]
    advantages = torch.zeros_like(rewards)
    lastgaelam = torch.zeros_like(next_value)
    for t in reversed(range(T)):
        nextvalues = next_value if t == T - 1 else values[t + 1]
        delta = rewards[t] + gamma * nextvalues * (1.0 - terminations[t]) - values[t]
        lastgaelam = (delta + gamma * gae_lambda * (1.0 - dones[t]) * lastgaelam) * valid[t]
        advantages[t] = lastgaelam
    return advantages, advantages + values


def ppo_update(agent, optimizer, b_obs, b_actions, b_logprobs, b_advantages, b_returns, args: Args, generator=None):
    """Epochs of clipped-objective minibatch updates on the (valid) transitions; returns the last losses."""
    n = b_obs.shape[0]
    stats = {}
    for _ in range(args.update_epochs):
        perm = torch.randperm(n, device=b_obs.device, generator=generator)
        for start in range(0, n, args.minibatch_size):
            mb = perm[start:start + args.minibatch_size]
            _, newlogprob, entropy, newvalue = agent.get_action_and_value(b_obs[mb], b_actions[mb])
            logratio = newlogprob - b_logprobs[mb]
            ratio = logratio.exp()
            with torch.no_grad():
                approx_kl = ((ratio - 1) - logratio).mean()
                clipfrac = ((ratio - 1.0).abs() > args.clip_coef).float().mean()
            mb_adv = b_advantages[mb]
            if args.norm_adv and len(mb) > 1:
                mb_adv = (mb_adv - mb_adv.mean()) / (mb_adv.std() + 1e-8)
            pg_loss = torch.max(-mb_adv * ratio, -mb_adv * ratio.clamp(1 - args.clip_coef, 1 + args.clip_coef)).mean()
            v_loss = ((newvalue - b_returns[mb]) ** 2).mean()  # SB3's MSE (CleanRL halves it)
            entropy_loss = entropy.mean()
            loss = pg_loss - args.ent_coef * entropy_loss + args.vf_coef * v_loss
            optimizer.zero_grad()
            loss.backward()
            nn.utils.clip_grad_norm_(agent.parameters(), args.max_grad_norm)
            optimizer.step()
            stats = {"policy_loss": pg_loss, "value_loss": v_loss, "entropy": entropy_loss,
                     "approx_kl": approx_kl, "clipfrac": clipfrac}
    return {k: float(v.detach()) for k, v in stats.items()}


# -- training --------------------------------------------------------------------------------------
CSV_COLUMNS = ["global_step", "wall_time_s", "success_rate", "mean_return", "episodes", "policy_loss", "value_loss",
               "entropy", "approx_kl", "clipfrac", "steps_per_s", "env_time_s", "update_time_s", "rollout_time_s"]


def default_out(args: Args) -> Path:
    if args.out:
        return Path(args.out)
    if args.quick:  # a quick run checks the pipeline: it never writes over a real run
        return Path(tempfile.mkdtemp(prefix="penny_env-ppo-quick-"))
    return Path("runs") / "ppo_torch" / f"{args.env_id}_{args.seed}"


class TorchPolicy:
    """The deterministic policy of training/protocol.py: the actor's mean, clipped to the action box (a frozen
    copy on the CPU; stateless)."""

    def __init__(self, agent: Agent):
        import copy
        self.actor = copy.deepcopy(agent.actor_mean).cpu().eval()

    def reset(self, num_envs: int) -> None:
        pass

    @torch.no_grad()
    def __call__(self, obs, info) -> np.ndarray:
        x = torch.as_tensor(np.asarray(obs), dtype=torch.float32)
        return self.actor(x).clamp(-1.0, 1.0).numpy().astype(np.float64)


def train(args: Args, checkpoints=(), on_checkpoint=None, log=print) -> dict:
    """training/protocol.py's entry: train for args.total_timesteps env steps (the ladder's configuration is
    :func:`ladder_args`); calls on_checkpoint(env_steps, TorchPolicy) the first time the env-step count reaches
    each of ``checkpoints`` and at the end. Writes into args.out (None: a new temporary directory); no final
    evaluation of its own. Returns the results dict with ``env_steps``, ``wall_time_s``, ``steps_per_s`` and
    ``policy`` (the final TorchPolicy)."""
    if args.out is None:
        args = dataclasses.replace(args, out=tempfile.mkdtemp(prefix="penny_env-ppo-"))
    agent, res = train_agent(args, log=log, checkpoints=checkpoints, on_checkpoint=on_checkpoint, final_eval=False)
    return {**res, "env_steps": res["timesteps"], "wall_time_s": res["train_seconds"], "policy": TorchPolicy(agent)}


def train_agent(args: Args, env=None, log=print, on_update=None, checkpoints=(), on_checkpoint=None,
                final_eval=True):
    """Train into args.out (see the module docstring); returns (agent, results dict).
    env: a vector env to use instead of make_env(args) (tests); on_update(row): called after each update;
    on_checkpoint(env_steps, TorchPolicy): see :func:`train`; final_eval: the deterministic evaluation on
    eval_episodes held-out seeds at the end (results["eval"]).
    The folder's lock is held meanwhile (training.run_folder.run_lock): a second run into it is refused at once."""
    from training.run_folder import run_lock
    out = default_out(args).resolve()
    with run_lock(out):
        return _train(dataclasses.replace(args, out=str(out)), env, log, on_update, checkpoints, on_checkpoint,
                      final_eval)


def _train(args: Args, env=None, log=print, on_update=None, checkpoints=(), on_checkpoint=None, final_eval=True):
    if args.quick:
        args = quick_args(args)
    made_env = env is None
    if made_env:
        check_args(args)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(args.torch_threads)
    device = resolve_device(args.device)
    torch.manual_seed(args.seed)
    np.random.seed(args.seed)
    env = make_env(args) if env is None else env
    on_torch = env_outputs_torch(env)
    N, T = env.num_envs, args.num_steps
    obs_dim = env.single_observation_space.shape[0]
    act_dim = env.single_action_space.shape[0]
    agent = Agent(obs_dim, act_dim, args.hidden, args.log_std_init).to(device)
    optimizer = torch.optim.Adam(agent.parameters(), lr=args.learning_rate, eps=1e-5)
    (out / "config.json").write_text(json.dumps({**dataclasses.asdict(args), "out": str(out),
                                                 "device_used": str(device)}, indent=2))
    from torch.utils.tensorboard import SummaryWriter
    writer = SummaryWriter(str(out))

    # rollout storage, on the device
    shape = (T, N)
    obs = torch.zeros(shape + (obs_dim,), device=device)
    actions = torch.zeros(shape + (act_dim,), device=device)
    logprobs, rewards, values = (torch.zeros(shape, device=device) for _ in range(3))
    terminations, dones, valid = (torch.zeros(shape, device=device) for _ in range(3))
    ep_ends, ep_success, ep_return_at_end = (torch.zeros(shape, device=device) for _ in range(3))
    successes, returns = deque(maxlen=args.success_window), deque(maxlen=args.success_window)
    episodes = 0

    t0 = time.perf_counter()
    first_obs, _ = env.reset(seed=args.seed if args.env_seed_base is None else args.env_seed_base + 100_000 * args.seed)
    cur_obs = to_tensor(first_obs, device).clone()  # the observation the next step acts on (updated in place)
    autoreset = torch.zeros(N, device=device)  # 1 where the env resets at the next step (NEXT_STEP mode)
    ep_ret = torch.zeros(N, device=device)
    timing = {"env": 0.0}  # host seconds in env.step (eager rollouts only: a graph's are not separable)

    def rollout():
        """num_steps steps of every env into the rollout buffers, in place (so that a CUDA graph can hold it)."""
        for step in range(T):
            obs[step].copy_(cur_obs)
            valid[step].copy_(1.0 - autoreset)
            with torch.no_grad():
                action, logprob, _, value = agent.get_action_and_value(cur_obs)
            actions[step].copy_(action)
            logprobs[step].copy_(logprob)
            values[step].copy_(value)
            t_env = time.perf_counter()
            next_obs, reward, term, trunc, info = env.step(env_actions(action, on_torch))
            timing["env"] += time.perf_counter() - t_env
            reward, term = to_tensor(reward, device), to_tensor(term, device)
            done = torch.maximum(term, to_tensor(trunc, device))
            rewards[step].copy_(reward)
            terminations[step].copy_(term)
            dones[step].copy_(done)
            # episode statistics of the valid steps (a reset step has reward 0 and is never done)
            ep_ret.add_(reward)
            ep_ends[step].copy_(done * valid[step])
            ep_success[step].copy_(to_tensor(info["is_success"], device) * done)
            ep_return_at_end[step].copy_(ep_ret)
            ep_ret.mul_(1.0 - done)
            autoreset.copy_(done)
            cur_obs.copy_(to_tensor(next_obs, device))

    use_graph = bool(args.cuda_graph)  # (opt-in: see the module's docstring)
    if use_graph and not (device.type == "cuda" and on_torch):
        raise ValueError("cuda_graph needs device cuda and an env whose outputs are torch tensors on it "
                         "(--env-backend cuda)")
    graph = None
    global_step, iterations = 0, max(1, -(-args.total_timesteps // (N * T)))
    pending, called_at = sorted(int(c) for c in checkpoints), set()  # checkpoints to come; steps called at
    eval_at = curve_steps(iterations * N * T, args.curve_points, N * T)
    curve = []
    update_time = rollout_time = 0.0  # host seconds in the updates (GAE included) and in the rollouts
    f = open(out / "progress.csv", "w", newline="")
    rows = csv.writer(f)
    rows.writerow(CSV_COLUMNS)
    row = None
    for iteration in range(1, iterations + 1):
        t_roll = time.perf_counter()
        if not use_graph:
            rollout()
        elif graph is None:  # the first rollout runs eagerly on a side stream (warm-up), then one is captured
            side = torch.cuda.Stream(device=device)
            side.wait_stream(torch.cuda.current_stream(device))
            with torch.cuda.stream(side):
                rollout()
            torch.cuda.current_stream(device).wait_stream(side)
            graph = torch.cuda.CUDAGraph()
            from penny_env.backends.cuda_env import capture_guard
            try:
                with capture_guard(), torch.cuda.graph(graph, stream=side):
                    rollout()  # (recorded, not run: the next iterations replay it)
            except RuntimeError as exc:  # (torch's AcceleratorError too; its generators stay in capture mode)
                raise RuntimeError(f"ppo_torch: the rollout's CUDA graph capture failed: {exc}\n(run with "
                                   "--cuda-graph off for eager rollouts)") from exc
        else:
            graph.replay()
        global_step += N * T
        rollout_time += time.perf_counter() - t_roll

        # one host sync per rollout for the episode statistics
        ended = ep_ends.bool().cpu().numpy()
        if ended.any():
            successes.extend(ep_success.cpu().numpy()[ended].tolist())
            returns.extend(ep_return_at_end.cpu().numpy()[ended].tolist())
            episodes += int(ended.sum())

        t_update = time.perf_counter()
        with torch.no_grad():
            next_value = agent.get_value(cur_obs)
            advantages, returns_ = compute_gae(rewards, values, terminations, dones, valid, next_value,
                                               args.gamma, args.gae_lambda)
        keep = valid.reshape(-1).bool()  # the reset steps of NEXT_STEP autoreset are no transitions
        b_obs = obs.reshape(-1, obs_dim)[keep]
        b_actions = actions.reshape(-1, act_dim)[keep]
        stats = ppo_update(agent, optimizer, b_obs, b_actions, logprobs.reshape(-1)[keep],
                           advantages.reshape(-1)[keep], returns_.reshape(-1)[keep], args)
        update_time += time.perf_counter() - t_update

        wall = time.perf_counter() - t0
        row = {"global_step": global_step, "wall_time_s": wall,
               "success_rate": float(np.mean(successes)) if successes else float("nan"),
               "mean_return": float(np.mean(returns)) if returns else float("nan"), "episodes": episodes,
               **stats, "steps_per_s": global_step / wall,
               "env_time_s": float("nan") if use_graph else timing["env"], "update_time_s": update_time,
               "rollout_time_s": rollout_time}
        rows.writerow([row[c] for c in CSV_COLUMNS])
        f.flush()
        for key, value in row.items():
            if key not in ("global_step", "wall_time_s"):
                writer.add_scalar(("losses/" if key in stats else "charts/") + key, value, global_step)
        if eval_at and global_step >= eval_at[0]:
            while eval_at and global_step >= eval_at[0]:
                eval_at.pop(0)
            t_eval = time.perf_counter()
            ev = evaluate(agent, args, args.eval_episodes, eval_seed(args.seed), device)
            curve.append({"global_step": global_step, "wall_time_s": wall, **ev})
            t0 += time.perf_counter() - t_eval  # (evaluations are not training time)
        if checkpoints or on_checkpoint is not None:
            t_ck = time.perf_counter()
            while pending and global_step >= pending[0]:
                pending.pop(0)
                if on_checkpoint is not None and global_step not in called_at:
                    called_at.add(global_step)
                    on_checkpoint(global_step, TorchPolicy(agent))
            t0 += time.perf_counter() - t_ck  # (the caller's evaluations are not training time)
        if on_update is not None:
            on_update(row)
        if log is not None and (iteration % 10 == 0 or iteration == iterations):
            log(f"[ppo_torch] {global_step:,}/{iterations * N * T:,} steps, {row['steps_per_s']:,.0f} steps/s, "
                f"success {row['success_rate']:.2f} over the last {len(successes)} episodes, "
                f"return {row['mean_return']:.2f}, {wall:.0f} s")
    f.close()
    train_seconds = time.perf_counter() - t0
    if on_checkpoint is not None and global_step not in called_at:
        on_checkpoint(global_step, TorchPolicy(agent))
    env.close()
    torch.save(agent.state_dict(), out / "model.pt")
    writer.close()

    results = {"env_id": args.env_id, "env_kwargs": args.env_kwargs, "timesteps": global_step,
               "train_seconds": train_seconds, "steps_per_s": global_step / train_seconds, "device": str(device),
               "cuda_graph": bool(use_graph), "env_on_device": bool(on_torch),
               "env_seconds": float("nan") if use_graph else timing["env"],
               "rollout_seconds": rollout_time, "update_seconds": update_time, "curve": curve,
               "train_success_rate": row["success_rate"], "train_mean_return": row["mean_return"]}
    # a stand-in env passed by a caller (tests) has no registered id to evaluate on
    results["eval"] = (evaluate(agent, args, args.eval_episodes, eval_seed(args.seed), device)
                       if made_env and final_eval else None)
    (out / "results.json").write_text(json.dumps(results, indent=2))
    if log is not None:
        ev = results.get("eval")
        if ev:
            log(f"[ppo_torch] evaluation: success {ev['success_rate']:.3f} over {ev['episodes']} deterministic "
                f"episodes (seeds from {ev['seed']}), mean return {ev['mean_return']:.2f}")
        log(f"[ppo_torch] {global_step:,} steps in {train_seconds:.1f} s ({results['steps_per_s']:,.0f} steps/s "
            f"on {device}); output folder: {out} (tensorboard --logdir {out})")
    return agent, results


def eval_seed(seed: int) -> int:
    """First seed of the evaluation episodes (training.runner's: disjoint from the training seeds)."""
    return 1_000_000 + 10_000 * int(seed)


def evaluate(agent, args: Args, episodes: int, seed: int, device=None) -> dict:
    """One deterministic episode in each of `episodes` sub-envs seeded seed, seed + 1, ...: success rate
    (info["is_success"] at the episode's end) and mean return."""
    device = next(agent.parameters()).device if device is None else device
    env = make_env(args, episodes)
    on_torch = env_outputs_torch(env)
    obs, _ = env.reset(seed=seed)
    alive = torch.ones(episodes, dtype=torch.bool, device=device)
    success = torch.zeros(episodes, device=device)
    ret = torch.zeros(episodes, device=device)
    while bool(alive.any()):
        with torch.no_grad():
            action = agent.act(to_tensor(obs, device))
        obs, reward, term, trunc, info = env.step(env_actions(action, on_torch))
        ret += to_tensor(reward, device) * alive
        ended = alive & (to_tensor(term, device, torch.bool) | to_tensor(trunc, device, torch.bool))
        success = torch.where(ended, to_tensor(info["is_success"], device), success)
        alive &= ~ended
    env.close()
    return {"success_rate": float(success.mean()), "mean_return": float(ret.mean()), "episodes": episodes,
            "seed": seed}


def load_agent(run_dir, device="cpu") -> Agent:
    """The trained agent of a run folder (config.json + model.pt)."""
    run_dir = Path(run_dir)
    cfg = json.loads((run_dir / "config.json").read_text())
    state = torch.load(run_dir / "model.pt", map_location=device)
    obs_dim = state["critic.0.weight"].shape[1]
    act_dim = state["actor_logstd"].shape[1]
    agent = Agent(obs_dim, act_dim, tuple(cfg["hidden"]))
    agent.load_state_dict(state)
    return agent.to(device)


def parse_args(argv=None, ap=None) -> Args:
    """The run's Args from the command line (training.train's config files, flags, --set); ``ap``: a parser to
    add these arguments to (a study's, with arguments of its own: read them from ``ap.last``)."""
    ap = ap or argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    d = Args()
    ap.add_argument("--config", default=None, help="a training config (YAML, e.g. configs/train/ppo_reach_ellipse.yaml) "
                                                   "whose env, budget and SB3 PPO hyperparameters to use")
    ap.add_argument("--ladder", action="store_true", help="the ladder's configuration (LADDER: 4096 envs x 32 steps, "
                    "minibatches of 16384, 2 epochs, gamma 0.999, the fair reward, training seeds from 1e7)")
    ap.add_argument("--fast", action="store_true", help="the fast CPU configuration (FAST_CPU) without the ladder's "
                    "reward and discount")
    ap.add_argument("--env-id", default=None, help=f"a registered penny_env id (default {d.env_id})")
    ap.add_argument("--num-envs", type=int, default=None, help=f"envs of the vector env (default {d.num_envs})")
    ap.add_argument("--total-timesteps", type=int, default=None, help=f"env steps (default {d.total_timesteps:,})")
    ap.add_argument("--seed", type=int, default=None, help="seed of the envs (env i: seed + i) and of torch (default 0)")
    ap.add_argument("--device", default="auto", help="auto (cuda if torch.cuda.is_available()), cpu or cuda")
    ap.add_argument("--env-backend", default=None, help="the vector env's backend= (default: the env's own)")
    ap.add_argument("--set", nargs="*", default=[], metavar="FIELD=VALUE",
                    help="scene/task field overrides of the env id (YAML values), as gymnasium.make(id, **kwargs)")
    ap.add_argument("--cuda-graph", default=None, choices=["on", "off"],
                    help="capture each rollout in a CUDA graph (default off: eager rollouts; on needs --env-backend cuda)")
    ap.add_argument("--curve-points", type=int, default=None, help="deterministic evaluations during training")
    ap.add_argument("--num-steps", type=int, default=None, help=f"steps per env per rollout (default {d.num_steps})")
    ap.add_argument("--eval-episodes", type=int, default=None, help=f"final evaluation (default {d.eval_episodes})")
    ap.add_argument("--torch-threads", type=int, default=1, help="torch.set_num_threads (default 1)")
    ap.add_argument("--quick", action="store_true", help="a few thousand steps (< 60 s on a CPU): checks the pipeline")
    ap.add_argument("--out", default=None, help="output folder (default runs/ppo_torch/<env_id>_<seed>; "
                                                "--quick: a new temporary directory)")
    a = ap.last = ap.parse_args(argv)
    try:
        if a.config:
            from training.train import load_config
            args = args_from_config(load_config(a.config))
        else:
            args = Args()
        if a.ladder or a.fast:
            args = dataclasses.replace(args, **(LADDER if a.ladder else FAST_CPU))
        changes = {"env_id": a.env_id, "num_envs": a.num_envs, "total_timesteps": a.total_timesteps, "seed": a.seed,
                   "num_steps": a.num_steps, "eval_episodes": a.eval_episodes, "curve_points": a.curve_points,
                   "cuda_graph": None if a.cuda_graph is None else a.cuda_graph == "on"}
        if a.set:
            changes["env_kwargs"] = {**args.env_kwargs, **parse_sets(a.set)}
        args = dataclasses.replace(args, device=a.device, env_backend=a.env_backend, torch_threads=a.torch_threads,
                                   quick=a.quick, out=a.out, **{k: v for k, v in changes.items() if v is not None})
        check_args(quick_args(args) if args.quick else args)
    except ValueError as exc:
        ap.error(str(exc))
    return args


def parse_sets(items) -> dict:
    """{field: value} from FIELD=VALUE strings, values read as YAML 1.2 ("0.5" a float, "{kind: circle}" a dict): the
    agents' one parser (training/agent_cli.parse_pairs)."""
    from training.agent_cli import parse_pairs
    return parse_pairs(items, "--set")


def main(argv=None):
    from training.run_folder import RunFolderError, check_new_folder
    args = parse_args(list(sys.argv[1:] if argv is None else argv))
    try:
        if args.out:  # (a new run: never over another run's files; the study commands pick their own folders)
            check_new_folder(args.out)
        return train_agent(args)
    except RunFolderError as exc:  # another run's folder: a usage error, as argparse reports one (exit status 2)
        print(f"ppo_torch: error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None


if __name__ == "__main__":
    main()
