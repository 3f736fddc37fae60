"""PennyEnv: the controlled bouncing penny as a Gymnasium environment."""
from __future__ import annotations

import math
from collections import deque

import numpy as np
import gymnasium as gym
from gymnasium import spaces
from gymnasium.error import ResetNeeded

from ..physics import advance_pennies as _advance_batch
from ..physics.validation import as_state, check_inside
from .core import Core, seed_keys
from .scene import resolve
from ..physics.kernels import SCALAR
from .tasks import on_arc, step_reward


class PennyEnv(gym.Env):
    r"""The vertical rolling disk (the "penny") on a table with walls, driven by two torques.

    The penny rolls without slipping; its contact point (x, y) moves along its heading phi at
    the speed R theta_dot. The controls are the torques of the paper's section "Conclusions,
    Control and Future Work": ``J phi'' = u1`` (steering about the vertical) and
    ``(I + m R^2) theta'' = u2`` (rolling). When an end of the penny (the points at +-R along
    its heading) reaches the wall, the scene's impact law maps the velocities (the physics in
    :mod:`penny_env.physics` is exact and event driven: every impact inside a control period is
    found and processed). The open plane (table kind "none") is the non-hybrid penny.

    **Configuration.** ``PennyEnv(scene="ellipse", task="reach", render_mode=None, backend="auto",
    **overrides)``: scene and task are preset names (``penny_env/presets/scenes/*.yaml``,
    ``penny_env/presets/tasks/*.yaml``), YAML paths, dicts or :class:`~penny_env.envs.scene.Scene` / ``Task``
    objects; keyword overrides set any field of either (see their docstrings); an unknown or
    invalid field raises a ``ConfigError`` (a ``ValueError``) naming it. backend: "numba" runs the
    physics' scalar event loop compiled (the optional numba, ``pip install "penny_env[fast]"``),
    "numpy" runs it as plain Python floats; "auto" (default) takes numba where it is installed
    and the table compiles (the built-in tables). Both give bitwise the same episodes (tested).

    **Action space** ``Box(-1, 1, (k,), float32)``, one entry per actuated control, held
    constant over ``control_dt`` seconds; entries are clipped to [-1, 1], then scaled to the
    torque limits. Non-finite entries or a wrong shape raise ``ValueError``.

    =========  ========================  =======================================
    actuation  action                    torques
    =========  ========================  =======================================
    both       (a1, a2)                  u1 = a1 * torque_limits.u1, u2 = a2 * torque_limits.u2
    steer      (a1,)                     u1 = a1 * torque_limits.u1, u2 = 0
    drive      (a2,)                     u1 = 0, u2 = a2 * torque_limits.u2
    =========  ========================  =======================================

    **Observation space** ``Box(low, high, (10,) or (11,), float32)``; L is the table's size
    (largest |coordinate| of its extent) or the scene's ``arena`` on the open plane:

    =====  ========================================  ==========================
    index  observation                               bounds
    =====  ========================================  ==========================
    0, 1   x / L, y / L (open plane: tanh of them)   [-1, 1]
    2, 3   cos theta, sin theta (rolling angle)      [-1, 1]
    4, 5   cos phi, sin phi (heading)                [-1, 1]
    6      tanh(theta_dot / obs_scale.theta_dot)     [-1, 1]
    7      tanh(phi_dot / obs_scale.phi_dot)         [-1, 1]
    8, 9   (target - contact point) / L              [-2, 2] (open plane: tanh, [-1, 1])
    10     impacts task only: min(count / goal, 1)   [0, 1]
    =====  ========================================  ==========================

    For the impacts task the "target" is the wall point at the centre of the marked arc.

    **Rewards** (d: distance from the contact point to the target, d_prev: before the step,
    v = |R theta_dot|, ctrl = mean(a^2), n_arc: impacts of the step on the marked arc):

    * reach:   ``progress_weight (d_prev - d) / L - ctrl_cost ctrl + success_bonus [d < tolerance]``
    * park:    ``progress_weight (d_prev - d) / L - speed_cost v / (R obs_scale.theta_dot) [d < 2 tolerance]
      - ctrl_cost ctrl + success_bonus [success]``, success: d < tolerance and v < speed_tolerance
    * impacts: ``impact_reward n_arc - ctrl_cost ctrl + success_bonus [count >= impacts_goal]``;
      an impact is on the arc when its impact point is within arc_half_width (polar angle about
      the table's centre) of the arc's centre direction, drawn each episode.

    **Episode end.** Terminated on success (the conditions above). Truncated after the task's
    ``max_episode_steps`` (the env truncates itself; the registered ids also carry it as
    ``max_episode_steps``). ``info["is_success"]`` is set on the last step of an episode.

    **Starting state.** The contact point is uniform in ``init.spawn_fraction`` times the table's
    spawn ellipse (the ellipse itself, the circle, or the stadium's inscribed ellipse), theta,
    phi, theta_dot and phi_dot uniform in their ``init`` ranges; targets are uniform in
    ``target_fraction (1 - R / inradius)`` times the spawn ellipse (reachable by the contact
    point). ``reset(options={"state": (x, y, theta, phi, theta_dot, phi_dot), "target": (tx, ty)})``
    sets them explicitly.

    **info** of every step: ``impacts`` (count inside the step), ``impact_times`` (tuple of times
    since the step's start [s]), ``impact_ends`` (tuple of +1 front / -1 back; tuples so that
    gymnasium's SyncVectorEnv can batch infos of different lengths), ``kinetic_energy`` [J], ``time`` (simulated
    time since reset [s]), ``distance`` [m]; impacts task: ``arc_impacts`` (running count).

    **Determinism.** ``reset(seed=k)`` then the same actions give bitwise the same episode;
    later ``reset()`` calls draw the next episodes of the same seed (see core.py). The env pickles.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 20}

    def __init__(self, scene="ellipse", task="reach", render_mode: str | None = None, backend="auto", **overrides):
        self.scene, self.task = resolve(scene, task, **overrides)
        self.backend = backend
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']} or None, got {render_mode!r}")
        self.render_mode = render_mode
        self.metadata = dict(self.metadata, render_fps=max(1, int(round(1.0 / self.scene.control_dt))))
        self._setup()

    def _setup(self):
        core = self._core = Core(self.scene, self.task, backend=self.backend)
        self.action_space = spaces.Box(-1.0, 1.0, (core.n_act,), np.float32)
        lo, hi = core.obs_bounds()
        self.observation_space = spaces.Box(lo, hi, dtype=np.float32)
        self._key = None
        self._episode = 0
        self._s = None
        self._done = True
        self._renderer = None
        self._trail = deque(maxlen=200)
        self._hud = {}  # what the frame's text line and impact flashes show (rendering.Renderer.draw)

    def __getstate__(self):
        state = self.__dict__.copy()
        state["_renderer"] = None
        state.pop("_core")
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)
        self._core = Core(self.scene, self.task, backend=self.backend)

    # ------------------------------------------------------------------------------------
    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        core = self._core
        if seed is not None:
            self._key = seed_keys([seed])
            self._episode = 0
        elif self._key is None:
            self._key = seed_keys([int(self.np_random.integers(0, 2**63))])
            self._episode = 0
        else:
            self._episode += 1
        S, target, arc = core.sample(self._key, np.array([self._episode], dtype=np.uint64))
        if options:
            S, target = self._apply_options(options, S, target)
        self._s = tuple(S[:, 0].tolist())
        self._target = (float(target[0, 0]), float(target[1, 0]))
        self._arc = (float(arc[0, 0]), float(arc[1, 0]))
        self._steps = 0
        self._count = 0
        self._t = 0.0
        self._done = False
        x, y = self._s[0], self._s[1]
        dx, dy = self._target[0] - x, self._target[1] - y
        self._d = math.sqrt(dx * dx + dy * dy)
        self._trail.clear()
        self._trail.append((x, y))
        self._hud = {"time": 0.0, "impact_count": 0, "impacts": deque(maxlen=32)}
        info = {"kinetic_energy": self._energy(), "time": 0.0, "distance": self._d}
        if self.render_mode == "human":
            self.render()
        return self._obs(), info

    def _apply_options(self, options, S, target):
        unknown = sorted(set(options) - {"state", "target"})
        if unknown:
            raise ValueError(f"reset options: unknown key(s) {unknown}; allowed: ['state', 'target']")
        if "state" in options:
            s = as_state(options["state"], "options['state']")[:, None]
            check_inside(s, self._core.params, self._core.table, "options['state']")
            S = s
        if "target" in options:
            t = np.array(options["target"], dtype=float).reshape(-1)
            if t.shape != (2,) or not np.all(np.isfinite(t)):
                raise ValueError(f"options['target'] must be a finite (x, y) pair, got {options['target']!r}")
            target = t[:, None]
        return S, target

    def _energy(self):
        s = self._s
        return 0.5 * (self._core.Itot * s[4] ** 2 + self._core.J * s[5] ** 2)

    def _obs(self):
        c = self._core
        x, y, th, ph, W, w = self._s
        inv = c.inv_L
        ox, oy = x * inv, y * inv
        rx, ry = (self._target[0] - x) * inv, (self._target[1] - y) * inv
        if c.plane:
            ox, oy, rx, ry = math.tanh(ox), math.tanh(oy), math.tanh(rx), math.tanh(ry)
        vals = [ox, oy, math.cos(th), math.sin(th), math.cos(ph), math.sin(ph),
                math.tanh(W * c.s_W), math.tanh(w * c.s_w), rx, ry]
        if c.impacts:
            vals.append(min(self._count / c.k.goal, 1.0))
        return np.array(vals, dtype=np.float32)

    def _action(self, action):
        c = self._core
        try:
            arr = np.asarray(action, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"action must be an array of {c.n_act} floats, got {action!r}") from None
        if arr.shape != (c.n_act,):
            raise ValueError(f"action must have shape ({c.n_act},) for actuation {self.scene.actuation!r}, got shape {arr.shape}")
        vals = arr.tolist()
        for v in vals:
            if not math.isfinite(v):
                raise ValueError(f"action has a non-finite entry: {vals}")
        return [-1.0 if v < -1.0 else (1.0 if v > 1.0 else v) for v in vals]

    def step(self, action):
        if self._s is None:
            raise ResetNeeded("PennyEnv.step() called before reset()")
        if self._done:
            raise ResetNeeded("PennyEnv.step() called after the episode ended; call reset()")
        c = self._core
        a = self._action(action)
        if c.n_act == 2:
            acc1, acc2 = a[0] * c.gain1, a[1] * c.gain2
            ctrl = (a[0] * a[0] + a[1] * a[1]) / 2
        else:
            acc1, acc2 = (a[0] * c.gain1, 0.0) if c.controls == (0,) else (0.0, a[0] * c.gain2)
            ctrl = (a[0] * a[0]) / 1
        if c.fast is not None:
            s, events, _ = c.fast.advance(self._s, acc1, acc2, c.dt)
        else:
            s, events = self._advance_slow(acc1, acc2)
        self._s = s
        n_imp = len(events)
        n_arc = 0
        if n_imp:
            R, k = c.R, c.k
            cb, sb = self._arc
            for _, end, post in events:
                sR = end * R
                if on_arc(post[0] + sR * math.cos(post[3]), post[1] + sR * math.sin(post[3]), cb, sb, k, SCALAR):
                    n_arc += 1
            times = tuple(e[0] for e in events)
            ends = tuple(e[1] for e in events)
        else:
            times = ends = ()
        self._count += n_arc
        x, y = s[0], s[1]
        dx, dy = self._target[0] - x, self._target[1] - y
        d = math.sqrt(dx * dx + dy * dy)
        reward, success = step_reward(c.k, self._d, d, s[4], ctrl, n_arc, self._count, SCALAR)
        self._d = d
        self._steps += 1
        self._t += c.dt
        terminated = bool(success)
        truncated = self._steps >= c.max_steps
        info = {"impacts": n_imp, "impact_times": times, "impact_ends": ends,
                "kinetic_energy": self._energy(), "time": self._t, "distance": d}
        if c.impacts:
            info["arc_impacts"] = self._count
        if terminated or truncated:
            self._done = True
            info["is_success"] = terminated
        if self.render_mode is not None:
            self._trail.append((x, y))
            t0 = self._t - c.dt
            self._hud["impacts"].extend((t0 + t, e, st) for t, e, st in events)
            self._hud.update(time=self._t, reward=float(reward), impact_count=self._hud["impact_count"] + n_imp)
            if self.render_mode == "human":
                self.render()
        return self._obs(), float(reward), terminated, truncated, info

    def _advance_slow(self, acc1, acc2):
        c = self._core
        S = np.array(self._s)[:, None]
        S, log, _ = _advance_batch(S, acc1, acc2, c.dt, c.params, c.table, c.law, c.settings)
        events = [(float(t), int(e), tuple(st.tolist())) for t, e, st in zip(log.time, log.end, log.state)]
        return tuple(S[:, 0].tolist()), events

    # -- state access (analysis, tests) -----------------------------------------------------------
    @property
    def state(self) -> np.ndarray:
        """The penny's state (x, y, theta, phi, theta_dot, phi_dot) as a float64 copy."""
        if self._s is None:
            raise ResetNeeded("PennyEnv.state: call reset() first")
        return np.array(self._s)

    @property
    def target(self) -> np.ndarray:
        if self._s is None:
            raise ResetNeeded("PennyEnv.target: call reset() first")
        return np.array(self._target)

    # -- rendering ------------------------------------------------------------------------------
    def render(self):
        if self.render_mode is None:
            gym.logger.warn("PennyEnv.render() called without a render_mode; pass render_mode='rgb_array' or 'human'")
            return None
        if self._s is None:
            raise ResetNeeded("PennyEnv.render() called before reset()")
        from .rendering import Renderer
        if self._renderer is None:
            self._renderer = Renderer(self._core, self.render_mode, self.metadata["render_fps"])
        return self._renderer.draw(self._s, self._target, list(self._trail), self._arc, self._hud)

    def close(self):
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
