"""PennyEnv: the controlled bouncing penny as a Gymnasium environment."""
from __future__ import annotations

import math
from collections import deque

import numpy as np
import gymnasium as gym
from gymnasium import spaces
from gymnasium.error import ResetNeeded

from ..backends import stepping
from ..physics.scalar import impact_buffers
from .core import Core, check_seed, render_fps, seed_keys, warn_limits
from ..step.functional import LIMIT_ACTION, LIMIT_LAW_NONFINITE, check_actions, kinetic_energy
from .limits import check_int64, check_memory, single_env_bytes
from .scene import resolve

IMPACTS_BUFFER = 16  # impact times kept per step before a rerun with a larger buffer (PennyEnv)
MAX_IMPACTS_IN_INFO = 8  # width of info["impact_times"] / ["impact_ends"] (as PennyVectorEnv's rows)


def _action_list(action, n_act):
    """The action as a list of n_act floats (check_actions' checks; its common case, a float
    array of the right shape with finite entries, without its array passes)."""
    if type(action) is np.ndarray and action.dtype.kind == "f" and action.shape == (n_act,):
        vals = action.tolist()
        if all(math.isfinite(v) for v in vals):
            return vals
    return check_actions(action, (n_act,), "action").tolist()


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
    truncate=True, **overrides)``: scene and task are preset names (``penny_env/presets/scenes/*.yaml``,
    ``penny_env/presets/tasks/*.yaml``), YAML paths, dicts or :class:`~penny_env.envs.scene.Scene` /
    ``Task`` objects; keyword overrides set any field of either (see their docstrings); an unknown
    keyword raises ``UnknownFieldError`` (a ``ConfigError`` and a ``TypeError``), an invalid value a
    ``ConfigError`` (a ``ValueError``), naming the field. The step is step/functional.py's
    ``env_step`` (the one PennyVectorEnv runs for each of its envs). backend: "numba" runs it
    compiled, "python" as plain Python (debugging; bitwise the same episodes, tested); "auto"
    (default) takes numba unless the table does not compile. truncate: False leaves truncation to a
    wrapper (the registered ids: gymnasium's TimeLimit, so ``gymnasium.make(id, max_episode_steps=N)``
    is honoured both ways).

    **Action space** ``Box(-1, 1, (k,), float32)``, one entry per actuated control, held
    constant over ``control_dt`` seconds; entries are clipped to [-1, 1], then scaled to the
    torque limits. A wrong type (strings, None, bools, complex numbers) raises ``TypeError``,
    non-finite entries or a wrong shape ``ValueError``.

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
      (and |phi_dot| < spin_tolerance where the task sets one: the probes' "both speeds at rest")
    * impacts: ``impact_reward n_arc - ctrl_cost ctrl + success_bonus [count >= impacts_goal]``;
      an impact is on the arc when its impact point is within arc_half_width (polar angle about
      the table's centre) of the arc's centre direction, drawn each episode.

    **Episode end.** Terminated on success (the conditions above). Truncated after the task's
    ``max_episode_steps`` (``truncate=True``, direct construction) or by gymnasium's TimeLimit
    (the registered ids; ``gymnasium.make(id, max_episode_steps=N)``). ``info["is_success"]`` is in
    every step's info (True on the step that succeeds), so every episode end carries it.

    **Starting state.** The contact point is uniform in ``init.spawn_fraction`` times the table's
    spawn ellipse (the ellipse itself, the circle, or the stadium's inscribed ellipse), theta,
    phi, theta_dot and phi_dot uniform in their ``init`` ranges; targets are uniform in
    ``target_fraction (1 - R / inradius)`` times the spawn ellipse (reachable by the contact
    point). ``reset(options={"state": (x, y, theta, phi, theta_dot, phi_dot), "target": (tx, ty)})``
    sets them explicitly, checked as the scene's fields: the state finite with both ends of the
    penny inside the table, the target finite and where some heading fits the penny (the region
    its contact point can reach); the impacts task's target (the arc) cannot be set.

    **info** of every step:

    ==================  ==========================================================================
    key                 value
    ==================  ==========================================================================
    ``impacts``         count of impacts inside the step (exact)
    ``impact_times``    (max_impacts_in_info,) float64: the first impacts' times since the step's
                        start [s], then 0.0 (a fixed shape, so that TorchRL and gymnasium's vector
                        envs can batch it; padded with 0, not NaN as the vector env's rows, because
                        gymnasium's check_env compares infos with allclose)
    ``impact_ends``     (max_impacts_in_info,) int8: +1 (front end) / -1 (back end), then 0: the
                        first min(impacts, max_impacts_in_info) entries are the impacts
    ``kinetic_energy``  [J] after the step
    ``time``            simulated time since reset [s]
    ``distance``        contact point to target [m]
    ``is_success``      the task's success condition on this step (terminates the episode)
    ``arc_impacts``     impacts task: running count of impacts on the marked arc
    ``limit``           0, or the documented limit that ended the episode (truncated): 1 "speed"
                        (|theta_dot| or |phi_dot| past Scene.step_speed_limits(): one more step
                        could pass MAX_ANGULAR_SPEED), 2 "impacts" (the step needed more than
                        SolverSettings.max_events_per_interval impacts: the state and ``time`` are
                        those right after the last one, inside the period); 3 "law_nonfinite",
                        4 "law_energy" (the impact law returned a non-finite velocity or added
                        kinetic energy at an impact), 5 "outside_wall" (an end was found outside the
                        wall: the table's bounds are false): the event loop's run-time guard
                        stopped the step at that impact, with a RuntimeWarning naming the law or
                        the table (docs/envs.md#limits); names in
                        ``penny_env.step.functional.LIMIT_NAMES``
    ==================  ==========================================================================

    **Bounded work.** Every step does bounded work whatever the actions: the scene's initial
    speeds are checked at construction, and the limits above end the episode before a step could
    need more (docs/envs.md#limits). The motion is never altered.

    **Interrupted steps and resets.** A step or a reset interrupted by an exception (KeyboardInterrupt)
    may leave its bookkeeping half done; the next step() then raises ResetNeeded until reset() is called.
    A reset whose seed or options are refused changes nothing.

    ``reset`` returns the same keys (no impacts, ``is_success`` False). ``max_impacts_in_info``
    (default 8) sets the width of the impact arrays; a larger one keeps more of a step's impacts.

    **Determinism.** ``reset(seed=k)`` then the same actions give bitwise the same episode;
    later ``reset()`` calls draw the next episodes of the same seed (see core.py). The env pickles.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 20}

    def __init__(self, scene="ellipse", task="reach", render_mode: str | None = None, backend="auto",
                 truncate: bool = True, max_impacts_in_info: int = MAX_IMPACTS_IN_INFO, **overrides):
        self.scene, self.task = resolve(scene, task, **overrides)
        if not isinstance(truncate, bool):
            raise TypeError(f"truncate must be a bool, got {type(truncate).__name__}")
        if isinstance(max_impacts_in_info, bool) or not isinstance(max_impacts_in_info, (int, np.integer)):
            raise TypeError(f"max_impacts_in_info must be an integer, got {type(max_impacts_in_info).__name__}")
        if max_impacts_in_info < 0:
            raise ValueError(f"max_impacts_in_info must be >= 0, got {max_impacts_in_info}")
        check_int64("max_impacts_in_info", max_impacts_in_info)
        check_memory("max_impacts_in_info", max_impacts_in_info, single_env_bytes(int(max_impacts_in_info)),
                     "PennyEnv's impact buffers")
        self.max_impacts_in_info = int(max_impacts_in_info)
        self.backend = backend
        self.truncate = truncate
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']} or None, got {render_mode!r}")
        self.render_mode = render_mode
        self.metadata = dict(self.metadata, render_fps=render_fps(self.scene.control_dt))
        self._setup()

    def _setup(self):
        self._make_core()
        core = self._core
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
        self._in_step = False

    def _make_core(self):
        core = self._core = Core(self.scene, self.task, backend=self.backend)
        # truncate=False: never (a wrapper, gymnasium's TimeLimit, ends the episodes). The step compiled (or loaded)
        # now, not in the first step (backends/stepping.make_single)
        spec = stepping.make_single(core, None if self.truncate else np.iinfo(np.int64).max)
        self._p, self._m, self._fns, self._consts = spec.p, spec.m, spec.fns, spec.consts
        self._buffers(max(IMPACTS_BUFFER, self.max_impacts_in_info))

    def _buffers(self, capacity):
        """The step's impact buffers (scalar.ImpactBuffers, one penny with ``capacity`` slots), and the plain
        tuple of them the compiled step takes."""
        self._buf = impact_buffers(1, capacity)
        self._buf_args = tuple(self._buf)
        self._capacity = capacity

    def __getstate__(self):
        state = self.__dict__.copy()
        state["_renderer"] = None
        for key in ("_core", "_fns", "_p", "_m", "_consts", "_buf", "_buf_args", "_capacity"):
            state.pop(key)
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)
        self._make_core()

    # ------------------------------------------------------------------------------------
    def reset(self, *, seed=None, options=None):
        # The seed and the options are checked first: a bad one raises and changes nothing. The new episode is
        # then drawn into locals and stored; from the first change on, _in_step is set, so that a reset
        # interrupted there (Ctrl-C) makes the next step() raise ResetNeeded, as an interrupted step does.
        if seed is not None:
            seed = check_seed(seed)
        core = self._core
        state = tgt = None
        if options is not None:
            state, tgt = core.check_options(options, 1)
        self._in_step = True
        super().reset(seed=seed)
        if seed is not None:
            key, episode = seed_keys([seed])[0], 0
        elif self._key is None:
            key, episode = seed_keys([int(self.np_random.integers(0, 2**63))])[0], 0
        else:
            key, episode = self._key, self._episode + 1
        obs = np.empty((1, core.obs_dim), dtype=np.float32)
        s, trig, target, arc, d = self._fns.initial_state(key, episode, self._consts, obs)
        if state is not None or tgt is not None:
            s = tuple(state[0].tolist()) if state is not None else s
            target = (float(tgt[0, 0]), float(tgt[0, 1])) if tgt is not None else target
            trig, d = self._fns.observe_state((s, trig, target, arc, 0, d, 0, 0.0), self._consts, obs)
        self._key, self._episode = key, episode
        self._s, self._trig, self._target, self._arc, self._d = s, trig, target, arc, d
        self._steps = 0
        self._count = 0
        self._t = 0.0
        self._trail.clear()
        self._trail.append((s[0], s[1]))
        self._hud = {"time": 0.0, "impact_count": 0, "impacts": deque(maxlen=32)}
        self._done = False
        info = self._info(0, (), (), kinetic_energy(self._s, self._p), False)
        self._in_step = False  # (last: the episode is whole and its first observation and info made)
        if self.render_mode == "human":
            self.render()
        return obs[0], info

    def step(self, action):
        if self._s is None:
            raise ResetNeeded("PennyEnv.step() called before reset()")
        if self._done:
            raise ResetNeeded("PennyEnv.step() called after the episode ended; call reset()")
        if self._in_step:
            raise ResetNeeded("PennyEnv.step(): the previous step() or reset() was interrupted (an exception such as "
                              "KeyboardInterrupt inside it) and its bookkeeping may be half done; call reset()")
        c = self._core
        a = _action_list(action, c.n_act)
        a1 = a[1] if c.n_act == 2 else 0.0
        obs = np.empty((1, c.obs_dim), dtype=np.float32)
        st = (self._s, self._trig, self._target, self._arc, self._count, self._d, self._steps, self._t)
        self._in_step = True  # cleared once the step's results are all stored (see step's docstring)
        try:
            out = self._fns.env_step(st, a[0], a1, self._consts, obs, self._buf_args)
            n_imp = out[6]
            if n_imp > self._capacity:  # more impacts than the buffer holds: the same pure step, a larger buffer
                self._buffers(n_imp)
                out = self._fns.env_step(st, a[0], a1, self._consts, obs, self._buf_args)
        except Exception as exc:  # a user's law or table raising in the plain-Python step: named, reset needed
            named = c.named_failure(exc, f"PennyEnv.step at t = {self._t:.6g} s")
            if named is None:
                raise
            raise named from exc
        if out[6] and c.audit is not None:  # a user's registered shape: its formulas at a sample of the impacts
            n = out[6]
            c.audit.check(self._buf.post[:n, :, 0], self._buf.end[:n, 0], f"PennyEnv.step at t = {self._t:.6g} s")
        s, self._trig, self._count, d, self._steps, t, n_imp, reward, terminated, truncated, energy, limit = out
        t_prev = self._t
        self._s = s
        self._d = d
        self._t = t
        if n_imp:
            times, ends = tuple(self._buf.time[:n_imp, 0].tolist()), tuple(self._buf.end[:n_imp, 0].tolist())
        else:
            times = ends = ()
        info = self._info(n_imp, times, ends, energy, terminated, limit)
        if terminated or truncated:
            self._done = True
        self._in_step = False
        if self.render_mode is not None:
            self._trail.append((s[0], s[1]))
            if n_imp:  # the step's own post-impact states (its buffer), for the renderer's flashes
                self._hud["impacts"].extend((t_prev + ti, end, tuple(self._buf.post[j, :, 0].tolist()))
                                            for j, (ti, end) in enumerate(zip(times, ends)))
            self._hud.update(time=self._t, reward=float(reward), impact_count=self._hud["impact_count"] + n_imp)
            if self.render_mode == "human":
                self.render()
        if limit >= LIMIT_LAW_NONFINITE and limit != LIMIT_ACTION:  # a guard ended the episode (core.warn_limits)
            warn_limits(c, (limit,), (obs[0], d))
        return obs[0], float(reward), terminated, truncated, info

    def _info(self, n_imp, times, ends, energy, success, limit=0):
        """The step's info: every key on every step and reset, fixed shapes (see the class docstring)."""
        k = self.max_impacts_in_info
        impact_times, impact_ends = np.zeros(k), np.zeros(k, dtype=np.int8)
        if n_imp:  # (most steps have none: the slice assignments cost as much as the compiled step)
            impact_times[:min(n_imp, k)] = times[:k]
            impact_ends[:min(n_imp, k)] = ends[:k]
        info = {"impacts": n_imp, "impact_times": impact_times, "impact_ends": impact_ends,
                "kinetic_energy": energy, "time": self._t, "distance": self._d, "is_success": success,
                "limit": limit}
        if self._core.counts_arc:
            info["arc_impacts"] = self._count
        return info

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
