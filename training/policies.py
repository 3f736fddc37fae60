"""Reference policies: zero actions, uniformly random actions, and a hand-written
feedback controller for the both-controls tasks. Each is ``policy(obs (N, obs_dim)) -> actions (N, k)``."""
from __future__ import annotations

import numpy as np

REFERENCE_AGENTS = ("zero", "random", "feedback")


def zero_policy(n_act: int):
    return lambda obs: np.zeros((len(obs), n_act), np.float32)


def random_policy(n_act: int, seed: int):
    rng = np.random.default_rng(seed)
    return lambda obs: rng.uniform(-1.0, 1.0, (len(obs), n_act)).astype(np.float32)


class FeedbackPolicy:
    """Steer towards the target (or away from it, rolling backwards, whichever needs less turning)
    with a PD law on the heading error, and roll at a speed that shrinks with the distance to the
    target, down to rest on it. Reads only the observation (layout in PennyEnv's docstring) and
    the scene's constants; needs both controls.

    Why it works without impacts: the contact point moves along (cos phi, sin phi) at R theta_dot,
    so once the heading points at the target a rolling speed proportional to the distance is a
    stable first-order approach, and both torques are bounded accelerations the PD laws respect.
    """

    def __init__(self, core, v_max=0.05, k_v=0.6, k_h=25.0, d_h=10.0, k_w=40.0):
        if core.n_act != 2:
            raise ValueError(f"the feedback controller needs actuation 'both', got {core.scene.actuation!r}")
        self.L, self.plane, self.R = core.L, core.plane, core.R
        self.sW, self.sw = core.scene.obs_scale["theta_dot"], core.scene.obs_scale["phi_dot"]
        self.gain1, self.gain2 = core.gain1, core.gain2  # max angular accelerations [rad/s^2]
        self.v_max, self.k_v, self.k_h, self.d_h, self.k_w = v_max, k_v, k_h, d_h, k_w

    def __call__(self, obs):
        o = np.asarray(obs, np.float64)
        rel = o[:, 8:10]
        if self.plane:
            rel = np.arctanh(np.clip(rel, -0.999999, 0.999999))
        rx, ry = rel[:, 0] * self.L, rel[:, 1] * self.L
        d = np.hypot(rx, ry)
        phi = np.arctan2(o[:, 5], o[:, 4])
        W = np.arctanh(np.clip(o[:, 6], -0.999999, 0.999999)) * self.sW
        w = np.arctanh(np.clip(o[:, 7], -0.999999, 0.999999)) * self.sw
        err = np.angle(np.exp(1j * (np.arctan2(ry, rx) - phi)))
        back = np.abs(err) > np.pi / 2
        err = np.where(back, np.angle(np.exp(1j * (err - np.pi))), err)
        sign = np.where(back, -1.0, 1.0)
        far = d > 0.005  # close in, hold the heading: the target direction is ill defined
        u1 = np.where(far, self.k_h * err, 0.0) - self.d_h * w
        v_des = sign * np.minimum(self.v_max, self.k_v * d) * np.clip(np.cos(err), 0.0, 1.0) ** 4
        u2 = self.k_w * (v_des / self.R - W)
        a = np.stack([u1 / self.gain1, u2 / self.gain2], axis=1)
        return np.clip(a, -1.0, 1.0).astype(np.float32)


def reference_policy(agent: str, core, seed: int):
    if agent == "zero":
        return zero_policy(core.n_act)
    if agent == "random":
        return random_policy(core.n_act, seed)
    if agent == "feedback":
        return FeedbackPolicy(core)
    raise ValueError(f"unknown reference agent {agent!r}; known: {list(REFERENCE_AGENTS)}")
