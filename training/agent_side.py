"""What the ladder's agents (ppo_heading, her_sac, the witness-guided runs) compute on their own side of the env:
the task's published constants, the observation decoded into physical units, agent-side features, the agents' own
action heads (a heading PD law for the steering torque, a rolling-speed P law for the rolling torque) and a
protocol :class:`~training.protocol.Policy` around a deterministic actor.

Nothing here reads the env's state or target arrays or resets to chosen states: the constants are the task's
definition (R, the tolerances, the length scale L, the observation scales, the torque gains, the time limit), the
same for every episode of the cell; everything else comes from the observation and ``info["impacts"]``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn as nn

KP, KD = 25.0, 10.0  # heading PD law [1/s^2, 1/s] (critically damped at 5 rad/s)
KW = 40.0            # rolling-speed P law [1/s]
V_MAX = 0.3          # [m/s] the drive head's largest commanded rolling speed
FEATURES_DIM = 19


def make_vec(env_id: str, num_envs: int, env_kwargs: dict | None = None, **kw):
    """The native vector env (PennyVectorEnv, NEXT_STEP autoreset unless ``autoreset_mode`` is given), unwrapped."""
    import gymnasium as gym

    import penny_env  # noqa: F401
    return gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point",
                        **{**dict(env_kwargs or {}), **kw}).unwrapped


@dataclass(frozen=True)
class TaskConsts:
    """The cell's published constants (its config, never an episode's state)."""

    R: float
    L: float
    plane: bool
    s_theta: float
    s_phi: float
    tol: float
    vtol: float           # park's speed_tolerance (inf for reach: not part of the test)
    wtol: float           # park's spin_tolerance (inf where not set)
    park: bool
    gain1: float          # [rad/s^2] phi_ddot per unit steering action (0: not actuated)
    gain2: float          # [rad/s^2] theta_ddot per unit rolling action (0: not actuated)
    max_steps: int
    probe: str            # "Steer", "Drive" or "Both"

    @classmethod
    def of(cls, vec, max_steps: int | None = None):
        core = vec._core
        task = core.task
        park = task.kind == "park"
        st = getattr(task, "spin_tolerance", None)
        probe = {(0,): "Steer", (1,): "Drive"}.get(tuple(core.controls), "Both")
        return cls(float(core.R), float(core.L), core.table is None, float(core.scene.obs_scale["theta_dot"]),
                   float(core.scene.obs_scale["phi_dot"]), float(task.tolerance),
                   float(task.speed_tolerance) if park else math.inf, float(st) if (park and st is not None) else math.inf,
                   park, float(core.gain1), float(core.gain2), int(max_steps or task.max_episode_steps), probe)


def atanh(x):
    return torch.atanh(x.clamp(-0.999999, 0.999999))


def decode(obs: torch.Tensor, k: TaskConsts):
    """(px, py, v, w, tx, ty) in physical units from the observation: contact point [m], rolling speed R theta_dot
    [m/s], phi_dot [rad/s], target [m]."""
    if k.plane:
        px, py = atanh(obs[:, 0]) * k.L, atanh(obs[:, 1]) * k.L
        dx, dy = atanh(obs[:, 8]) * k.L, atanh(obs[:, 9]) * k.L
    else:
        px, py = obs[:, 0] * k.L, obs[:, 1] * k.L
        dx, dy = obs[:, 8] * k.L, obs[:, 9] * k.L
    v = atanh(obs[:, 6]) * k.s_theta * k.R
    w = atanh(obs[:, 7]) * k.s_phi
    return px, py, v, w, px + dx, py + dy


def speed_unit(k: TaskConsts) -> float:
    """[m/s] the features' unit of rolling speed: park's speed tolerance; 0.1 m/s for reach (the drive head's speeds
    are up to V_MAX)."""
    return k.vtol if math.isfinite(k.vtol) else 0.1


def features(obs: torch.Tensor, mem: torch.Tensor, k: TaskConsts, target: torch.Tensor | None = None):
    """(N, FEATURES_DIM) agent-side features from the observation, the agent's counters mem (N, 2) = (impacts seen in
    this episode, its clock in steps) and a target (N, 2) [m] (default: the observation's own)."""
    px, py, v, w, tx, ty = decode(obs, k)
    if target is not None:
        tx, ty = target[:, 0], target[:, 1]
    vn = v / speed_unit(k)
    dx, dy = (tx - px) / k.L, (ty - py) / k.L
    d = torch.sqrt(dx * dx + dy * dy)
    c, s = obs[:, 4], obs[:, 5]
    along, across = dx * c + dy * s, -dx * s + dy * c  # the target in the body frame
    sg = torch.where(vn < 0, -1.0, 1.0)
    impacts = mem[:, 0]
    return torch.stack([
        px / k.L, py / k.L, c, s, obs[:, 6] * 10, obs[:, 7],
        (vn / 3).clamp(-3, 3), (vn.abs() < 1).float(), (w / 5).clamp(-3, 3),
        dx, dy, d, along * sg, across * sg,
        torch.log1p(impacts) / 2, (impacts > 0).float(), obs[:, 2], obs[:, 3], mem[:, 1] / k.max_steps], dim=1)


def potential(obs: torch.Tensor, k: TaskConsts, v_flat: float = 0.5) -> torch.Tensor:
    """Phi <= 0 from the success test's quantities, for potential-based shaping (Ng et al. 1999). Park: rolling
    speed (only impacts change it under steering alone), then distance and spin counted only while slow (while fast
    they count as their worst); speeds under v_flat x speed_tolerance count as 0. Reach: distance / L."""
    px, py, v, w, tx, ty = decode(obs, k)
    d = torch.sqrt((tx - px) ** 2 + (ty - py) ** 2) / k.L
    if not k.park:
        return -2.0 * d.clamp(max=1.0)
    va = v.abs() / k.vtol
    slow = va < 1.0
    phi_v = (va - v_flat).clamp(min=0.0, max=5.0 - v_flat) / (5.0 - v_flat)
    phi_d = torch.where(slow, d.clamp(max=1.0), torch.ones_like(d))
    phi_w = (torch.where(slow, (w.abs() / k.wtol).clamp(max=20.0) / 20.0, torch.ones_like(d))
             if math.isfinite(k.wtol) else 0.0 * d)
    return -(phi_v + 2.0 * phi_d + 0.5 * phi_w)


def head_dim(k: TaskConsts, head: str) -> int:
    """Outputs of the policy for an action head: "pd" (steer: a heading (cos, sin); drive: a rolling speed) or
    "torque" (the env's own actions)."""
    if head == "torque":
        return {"Steer": 1, "Drive": 1}.get(k.probe, 2)
    return {"Steer": 2, "Drive": 1}[k.probe]


def to_env(obs: torch.Tensor, y: torch.Tensor, k: TaskConsts, head: str) -> torch.Tensor:
    """The env's actions (N, n_act) in [-1, 1] from the policy's outputs y. "torque": y clipped. "pd", steer: y a
    world-frame heading request (cos, sin) (any length), the torque the agent's PD law on the observed heading (obs
    4, 5) and phi_dot (decoded obs 7); drive: y in [-1, 1] (clipped) a rolling speed y V_MAX, the torque the agent's
    P law on the decoded rolling speed (obs 6)."""
    if head == "torque":
        return y.clamp(-1, 1)
    if k.probe == "Steer":
        return servo(obs, torch.atan2(y[:, 1], y[:, 0])[:, None], k)
    return servo(obs, y[:, :1], k)


def servo(obs: torch.Tensor, act: torch.Tensor, k: TaskConsts) -> torch.Tensor:
    """The env's actions (N, n_act) from the agent's requests ``act``: one column per actuated control, in the
    env's order (steering, then rolling): a world-frame heading psi [rad] that the agent's PD law on the observed
    heading (obs 4, 5) and phi_dot (decoded obs 7) steers to; a rolling-speed request a (clipped to [-1, 1]) that
    its P law on the decoded rolling speed (obs 6) drives to, a V_MAX [m/s]."""
    cols, j = [], 0
    if k.gain1:
        phi = torch.atan2(obs[:, 5], obs[:, 4])
        err = torch.remainder(act[:, j] - phi + math.pi, 2 * math.pi) - math.pi
        w = atanh(obs[:, 7]) * k.s_phi
        cols.append(((KP * err - KD * w) / k.gain1).clamp(-1, 1))
        j += 1
    if k.gain2:
        W = atanh(obs[:, 6]) * k.s_theta
        v_cmd = act[:, j].clamp(-1, 1) * V_MAX
        cols.append((KW * (v_cmd / k.R - W) / k.gain2).clamp(-1, 1))
    return torch.stack(cols, 1)


def layer(i, o, std=math.sqrt(2)):
    lin = nn.Linear(i, o)
    nn.init.orthogonal_(lin.weight, std)
    nn.init.zeros_(lin.bias)
    return lin


def mlp(n_in, n_out, hidden, out_std=1.0, act=nn.Tanh):
    return nn.Sequential(layer(n_in, hidden), act(), layer(hidden, hidden), act(), layer(hidden, n_out, out_std))


class ActorPolicy:
    """A protocol Policy (training/protocol.py) around a deterministic actor: ``actor(x) -> y`` on
    ``features(obs, (impacts, clock))`` (or ``feature_fn(obs, mem)``), turned into the env's actions by the head.
    The clock counts the steps of this episode, the impact counter adds ``info["impacts"]`` of every step."""

    def __init__(self, actor, k: TaskConsts, head: str, feature_fn=None):
        self.actor, self.k, self.head = actor, k, head
        self.feature_fn = feature_fn or (lambda o, m: features(o, m, k))
        self.imp = self.clock = None

    def reset(self, num_envs: int) -> None:
        self.imp = torch.zeros(num_envs)
        self.clock = torch.zeros(num_envs)

    @torch.no_grad()
    def __call__(self, obs, info) -> np.ndarray:
        if self.imp is None or len(self.imp) != len(obs):
            self.reset(len(obs))
        self.imp += torch.as_tensor(np.asarray(info["impacts"]), dtype=torch.float32)
        o = torch.as_tensor(np.asarray(obs, dtype=np.float32))
        y = self.actor(self.feature_fn(o, torch.stack([self.imp, self.clock], 1)))
        self.clock += 1
        return to_env(o, y, self.k, self.head).numpy().astype(np.float64)


def validate(policy, env_id, env_kwargs, episodes=200, seed=50_000) -> float:
    """Success rate of the deterministic policy on validation seeds (never the evaluation's 0..199)."""
    from .protocol import evaluate
    if seed < 50_000:
        raise ValueError(f"validation seeds start at 50,000 (0..199 are the evaluation's), got {seed}")
    r = evaluate(policy, env_id, env_kwargs, seeds=range(seed, seed + episodes))
    return r["successes"] / r["episodes"]
