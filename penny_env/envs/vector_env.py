"""PennyVectorEnv: N pennies advanced together by array operations (CartPoleVectorEnv style)."""
from __future__ import annotations

import numpy as np
import gymnasium as gym
from gymnasium import spaces
from gymnasium.error import ResetNeeded
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from ..physics import kinetic_energy
from .core import Core, seed_keys, X, Y, PHI, THETA_DOT
from .scene import resolve
from .tasks import on_arc, step_reward


class PennyVectorEnv(VectorEnv):
    """``num_envs`` copies of :class:`~penny_env.envs.penny_env.PennyEnv` stepped as one batch.

    Same scenes, tasks, spaces, rewards and episode logic as PennyEnv (the spaces, rewards and
    observation layout are tabled in its docstring); ``single_action_space`` and
    ``single_observation_space`` are PennyEnv's, the batched spaces add a leading num_envs axis.
    States live in one (6, num_envs) array; no step loops over envs in Python. With the numba
    backend the whole step (actions, physics, rewards, observations) is one compiled call, parallel
    over the envs (envs/compiled_step.py); with the numpy backend the pennies whose certified first
    search step excludes an impact are flowed directly and the others go through
    ``physics.advance`` (masks over arrays).

    Equivalence: sub-env i seeded with seed + i follows the trajectory of PennyEnv seeded with
    seed + i under the same actions, episode after episode: bitwise with the numba backend;
    with the numpy backend states and rewards too, observations within a float32 rounding (tested).

    ``PennyVectorEnv(num_envs, scene="ellipse", task="reach", max_episode_steps=None,
    autoreset_mode=AutoresetMode.NEXT_STEP, render_mode=None, backend="auto", **overrides)``.

    backend: "numba" runs PennyEnv's step, the physics' own scalar event loop included, compiled
    and in parallel over the envs (envs/compiled_step.py; needs the optional numba,
    ``pip install "penny_env[fast]"``), "numpy" the array event loop (physics.advance) and array
    code; "auto" (default) takes numba where it is installed and the table compiles (ellipse,
    circle, stadium, open plane). Both give the single env's trajectories (tested). The first
    numba step of a fresh install compiles for a few seconds; later processes load the machine
    code from numba's cache.

    Autoreset: NEXT_STEP (default) - the step after an env's episode ended resets it (its
    obs is the reset obs, reward 0, terminated = truncated = False); SAME_STEP - the ending step
    returns the reset obs and puts the last obs in ``info["final_obs"]`` (and its info in
    ``info["final_info"]``), masked by ``info["_final_obs"]``.

    info (arrays over envs, each with its ``_key`` mask): ``impacts`` (count in the step),
    ``impact_times`` (num_envs, K) [s] and ``impact_ends`` (num_envs, K) (+1/-1) padded with NaN / 0
    (K = the largest count of the step), ``kinetic_energy``, ``time``, ``distance``,
    ``arc_impacts`` (impacts task) and ``is_success`` (only where an episode ended).

    Bad input: a wrong action shape or a non-finite action in any sub-env raises ValueError
    naming the sub-env(s); no state changes.
    """

    metadata = {"render_modes": ["rgb_array"], "autoreset_mode": AutoresetMode.NEXT_STEP, "render_fps": 20}

    def __init__(self, num_envs: int = 1, scene="ellipse", task="reach", max_episode_steps=None,
                 autoreset_mode=AutoresetMode.NEXT_STEP, render_mode=None, backend="auto", **overrides):
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ValueError(f"num_envs must be a positive integer, got {num_envs!r}")
        if max_episode_steps is not None:
            overrides["max_episode_steps"] = max_episode_steps
        self.scene, self.task = resolve(scene, task, **overrides)
        autoreset_mode = AutoresetMode(autoreset_mode)
        if autoreset_mode not in (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP):
            raise ValueError(f"autoreset_mode must be NEXT_STEP or SAME_STEP, got {autoreset_mode}")
        if render_mode is not None and render_mode != "rgb_array":
            raise ValueError(f"PennyVectorEnv render_mode must be None or 'rgb_array', got {render_mode!r}")
        self.num_envs = int(num_envs)
        self.backend = backend
        self.render_mode = render_mode
        self.autoreset_mode = autoreset_mode
        self.metadata = dict(self.metadata, autoreset_mode=autoreset_mode,
                             render_fps=max(1, int(round(1.0 / self.scene.control_dt))))
        self._setup()

    def _setup(self):
        c = self._core = self._make_core()
        n = self.num_envs
        self.single_action_space = spaces.Box(-1.0, 1.0, (c.n_act,), np.float32)
        lo, hi = c.obs_bounds()
        self.single_observation_space = spaces.Box(lo, hi, dtype=np.float32)
        self.action_space = batch_space(self.single_action_space, n)
        self.observation_space = batch_space(self.single_observation_space, n)
        self._keys = None
        self._episodes = np.zeros(n, dtype=np.uint64)
        self._S = None
        self._renderers = None
        self._true = np.ones(n, dtype=bool)

    def __getstate__(self):
        state = self.__dict__.copy()
        state.pop("_core")
        state.pop("_compiled")
        state["_renderers"] = None
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)
        self._core = self._make_core()

    def _make_core(self):
        core = Core(self.scene, self.task, backend=self.backend)
        self._compiled = None
        if core.backend == "numba":
            from .compiled_step import CompiledStep
            self._compiled = CompiledStep(core)
        return core

    # ------------------------------------------------------------------------------------
    def reset(self, *, seed=None, options=None):
        """Reset all envs (or those in ``options["reset_mask"]``). seed: int (env i gets seed + i),
        a list of ints/None (one per env) or None."""
        int_seed = isinstance(seed, (int, np.integer)) and not isinstance(seed, bool)
        super().reset(seed=int(seed) if int_seed else None)
        n = self.num_envs
        mask = self._true.copy()
        if options and "reset_mask" in options:
            mask = np.asarray(options["reset_mask"], dtype=bool)
            if mask.shape != (n,):
                raise ValueError(f"options['reset_mask'] must have shape ({n},), got {mask.shape}")
            if self._S is None and not mask.all():
                raise ResetNeeded("the first reset must reset every env")
        if options:
            unknown = sorted(set(options) - {"reset_mask"})
            if unknown:
                raise ValueError(f"reset options: unknown key(s) {unknown}; allowed: ['reset_mask']")
        if self._keys is None:
            self._keys = seed_keys(self.np_random.integers(0, 2**63, size=n))
        if seed is None:
            self._episodes[mask] += np.uint64(1) if self._S is not None else np.uint64(0)
        else:
            if int_seed:
                seeds = [int(seed) + i for i in range(n)]
            else:
                seeds = list(seed)
                if len(seeds) != n:
                    raise ValueError(f"seed must be an int, None or a list of {n} seeds, got {len(seeds)} seeds")
            for i, s in enumerate(seeds):  # explicit seeding only, not the step path
                if not mask[i]:
                    continue
                if s is None:
                    self._keys[i] = seed_keys([self.np_random.integers(0, 2**63)])[0]
                else:
                    self._keys[i] = seed_keys([s])[0]
                self._episodes[i] = 0
        if self._S is None:
            self._S = np.zeros((6, n))
            self._target = np.zeros((2, n))
            self._arc = np.zeros((2, n))
            self._steps = np.zeros(n, dtype=np.int64)
            self._count = np.zeros(n, dtype=np.int64)
            self._t = np.zeros(n)
            self._trig = np.zeros((4, n))  # cos/sin of theta and phi of self._S (for observations)
            self._d = np.zeros(n)
            self._done = np.zeros(n, dtype=bool)
            self._trails = [[] for _ in range(n)] if self.render_mode else None
        self._reset_envs(mask)
        self._autoreset = np.zeros(n, dtype=bool)
        obs = self._observe()
        info = {"kinetic_energy": kinetic_energy(self._S, self._core.params), "_kinetic_energy": self._true.copy(),
                "time": self._t.copy(), "_time": self._true.copy(), "distance": self._d.copy(), "_distance": self._true.copy()}
        return obs, info

    def _reset_envs(self, mask):
        idx = np.flatnonzero(mask)
        if idx.size == 0:
            return
        c = self._core
        S, target, arc = c.sample(self._keys[idx], self._episodes[idx])
        self._S[:, idx] = S
        if self._compiled is None:  # (the compiled backend's observe_rows fills trig)
            self._trig[:, idx] = c.angle_trig(S)
        self._target[:, idx] = target
        self._arc[:, idx] = arc
        self._steps[idx] = 0
        self._count[idx] = 0
        self._t[idx] = 0.0
        self._d[idx] = c.distance(S, target)
        self._done[idx] = False
        if self._trails is not None:
            for i in idx:
                self._trails[i] = [(self._S[X, i], self._S[Y, i])]

    def _observe(self):
        """Observations of every env (the compiled backend also refreshes the angle trig)."""
        if self._compiled is None:
            return self._core.observe(self._S, self._target, self._count, self._trig)
        obs = np.empty((self.num_envs, self._core.obs_dim), dtype=np.float32)
        self._compiled.observe_rows(np.arange(self.num_envs), self._S, self._trig, self._target, self._count, obs)
        return obs

    def _actions(self, actions, clip=True):
        """(num_envs, n_act) float64 actions, checked (shape, finite) and clipped to [-1, 1]."""
        c = self._core
        try:
            a = np.asarray(actions, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"actions must be a ({self.num_envs}, {c.n_act}) float array") from None
        if a.shape != (self.num_envs, c.n_act):
            if c.n_act == 1 and a.shape == (self.num_envs,):
                a = a[:, None]
            else:
                raise ValueError(f"actions must have shape ({self.num_envs}, {c.n_act}), got {a.shape}")
        finite = np.isfinite(a)
        if not finite.all():
            bad = np.flatnonzero(~finite.all(axis=1))
            raise ValueError(f"non-finite action in sub-env(s) {bad[:10].tolist()}{' ...' if bad.size > 10 else ''}")
        return np.clip(a, -1.0, 1.0) if clip else np.ascontiguousarray(a)

    def step(self, actions):
        if self._S is None:
            raise ResetNeeded("PennyVectorEnv.step() called before reset()")
        if self._compiled is not None:
            return self._step_compiled(actions)
        c = self._core
        n = self.num_envs
        a = self._actions(actions)
        acc1, acc2 = c.accelerations(a)
        if c.n_act == 2:
            ctrl = (a[:, 0] * a[:, 0] + a[:, 1] * a[:, 1]) / 2
        else:
            ctrl = (a[:, 0] * a[:, 0]) / 1
        S, log = c.advance(self._S, acc1, acc2)
        self._trig = c.angle_trig(S)
        reset_now = self._autoreset  # NEXT_STEP: envs whose episode ended at the previous step
        self._S = S
        if log is not None:
            env, times, ends, post = log
            counts = np.bincount(env, minlength=n)
            sR = ends * c.R
            ph = post[:, PHI]
            hit_arc = on_arc(post[:, X] + sR * np.cos(ph), post[:, Y] + sR * np.sin(ph),
                             self._arc[0, env], self._arc[1, env], c.k)
            n_arc = np.bincount(env, weights=hit_arc, minlength=n).astype(np.int64)
        else:
            counts = np.zeros(n, dtype=np.int64)
            n_arc = counts
        self._count = self._count + n_arc
        d = c.distance(S, self._target)
        reward, success = step_reward(c.k, self._d, d, S[THETA_DOT], ctrl, n_arc, self._count)
        self._d = d
        self._steps += 1
        self._t = self._t + c.dt
        terminated = np.asarray(success, dtype=bool)
        truncated = self._steps >= c.max_steps
        info = self._info(counts, *self._impact_arrays(counts, log), kinetic_energy(S, c.params))
        self._extend_trails()
        done = terminated | truncated
        if done.any():
            info["is_success"] = terminated.copy()
            info["_is_success"] = done.copy()
        if self.autoreset_mode == AutoresetMode.NEXT_STEP:
            if reset_now.any():
                self._episodes[reset_now] += np.uint64(1)
                self._reset_envs(reset_now)
                reward = np.where(reset_now, 0.0, reward)
                terminated = terminated & ~reset_now
                truncated = truncated & ~reset_now
                done = done & ~reset_now
                self._blank_info(info, reset_now)
            obs = c.observe(self._S, self._target, self._count, self._trig)
            self._autoreset = done
        else:
            obs = c.observe(self._S, self._target, self._count, self._trig)
            if done.any():
                self._end_episodes_same_step(info, obs, done, terminated)
                obs = c.observe(self._S, self._target, self._count, self._trig)
        return obs, reward.astype(np.float64), terminated, truncated, info

    def _step_compiled(self, actions):
        """step() with the numba backend: one compiled pass (envs/compiled_step.py) over the envs."""
        c = self._core
        n = self.num_envs
        a = self._actions(actions, clip=False)  # the compiled step clips, as PennyEnv does
        next_step = self.autoreset_mode == AutoresetMode.NEXT_STEP
        skip = self._autoreset if next_step else np.zeros(n, dtype=bool)
        self._S, obs, reward, terminated, truncated, counts, times, ends, ke = self._compiled.step(
            self._S, self._trig, a, skip, self._target, self._arc, self._count, self._d, self._steps, self._t)
        self._extend_trails()
        done = terminated | truncated
        if next_step:
            if skip.any():  # NEXT_STEP: the envs whose episode ended at the previous step reset now
                rows = np.flatnonzero(skip)
                self._episodes[rows] += np.uint64(1)
                self._reset_envs(skip)
                self._compiled.observe_rows(rows, self._S, self._trig, self._target, self._count, obs)
                ke[rows] = kinetic_energy(self._S[:, rows], c.params)
            self._autoreset = done
            info = self._info(counts, times, ends, ke)
            if done.any():
                info["is_success"], info["_is_success"] = terminated.copy(), done.copy()
            return obs, reward, terminated, truncated, info
        info = self._info(counts, times, ends, ke)
        if done.any():
            info["is_success"], info["_is_success"] = terminated.copy(), done.copy()
            rows = self._end_episodes_same_step(info, obs, done, terminated)
            self._compiled.observe_rows(rows, self._S, self._trig, self._target, self._count, obs)
        return obs, reward, terminated, truncated, info

    def _end_episodes_same_step(self, info, obs, done, terminated):
        """SAME_STEP autoreset: the last obs and info of the envs whose episode ended go to
        info["final_obs"] / info["final_info"], then those envs reset; returns their indices."""
        n = self.num_envs
        rows = np.flatnonzero(done)
        final_obs = np.empty(n, dtype=object)
        final_info = np.empty(n, dtype=object)
        for i in rows:  # only the envs whose episode ended (SB3-style final observations)
            final_obs[i] = obs[i].copy()
            final_info[i] = {"is_success": bool(terminated[i])}
        info["final_obs"], info["_final_obs"] = final_obs, done.copy()
        info["final_info"], info["_final_info"] = final_info, done.copy()
        self._episodes[done] += np.uint64(1)
        self._reset_envs(done)
        return rows

    def _extend_trails(self):
        if self._trails is not None:
            for i in range(self.num_envs):
                self._trails[i].append((self._S[X, i], self._S[Y, i]))
                del self._trails[i][:-200]

    def _impact_arrays(self, counts, log):
        """(impact_times (N, K) NaN-padded, impact_ends (N, K) 0-padded), K the largest count."""
        n = self.num_envs
        if log is None:
            return np.zeros((n, 0)), np.zeros((n, 0), dtype=np.int8)
        env, times, ends, _ = log
        K = int(counts.max())
        first = np.cumsum(counts) - counts
        rank = np.arange(env.size) - first[env]
        it = np.full((n, K), np.nan)
        ie = np.zeros((n, K), dtype=np.int8)
        it[env, rank] = times
        ie[env, rank] = ends
        return it, ie

    def _info(self, counts, times, ends, ke):
        t = self._true
        info = {"impacts": counts, "_impacts": t.copy(), "impact_times": times, "_impact_times": t.copy(),
                "impact_ends": ends, "_impact_ends": t.copy(), "kinetic_energy": ke, "_kinetic_energy": t.copy(),
                "time": self._t.copy(), "_time": t.copy(), "distance": self._d.copy(), "_distance": t.copy()}
        if self._core.impacts:
            info["arc_impacts"] = self._count.copy()
            info["_arc_impacts"] = t.copy()
        return info

    def _blank_info(self, info, mask):
        """NEXT_STEP: the resetting envs report their reset values."""
        info["impacts"] = np.where(mask, 0, info["impacts"])
        if info["impact_times"].shape[1]:
            K = int(info["impacts"].max())  # the largest count among the envs that did step
            info["impact_times"] = info["impact_times"][:, :K].copy()
            info["impact_ends"] = info["impact_ends"][:, :K].copy()
            info["impact_times"][mask] = np.nan
            info["impact_ends"][mask] = 0
        info["kinetic_energy"][mask] = kinetic_energy(self._S[:, mask], self._core.params)
        info["time"][mask] = 0.0
        info["distance"][mask] = self._d[mask]
        if "arc_impacts" in info:
            info["arc_impacts"][mask] = 0
        if "is_success" in info:
            info["_is_success"] &= ~mask
            if not info["_is_success"].any():
                del info["is_success"], info["_is_success"]

    # -- state access ---------------------------------------------------------------------
    @property
    def states(self) -> np.ndarray:
        """(num_envs, 6) copy of the pennies' states (x, y, theta, phi, theta_dot, phi_dot)."""
        if self._S is None:
            raise ResetNeeded("call reset() first")
        return self._S.T.copy()

    @property
    def targets(self) -> np.ndarray:
        if self._S is None:
            raise ResetNeeded("call reset() first")
        return self._target.T.copy()

    def render(self):
        """Frames of the sub-envs (a tuple of uint8 arrays) in render_mode "rgb_array"."""
        if self.render_mode is None:
            gym.logger.warn("PennyVectorEnv.render() called without render_mode='rgb_array'")
            return None
        if self._S is None:
            raise ResetNeeded("PennyVectorEnv.render() called before reset()")
        from .rendering import Renderer
        if self._renderers is None:
            self._renderers = Renderer(self._core, "rgb_array", self.metadata["render_fps"])
        r = self._renderers
        return tuple(r.frame(tuple(self._S[:, i]), tuple(self._target[:, i]), self._trails[i], tuple(self._arc[:, i]))
                     for i in range(self.num_envs))

    def close_extras(self, **kwargs):
        self._renderers = None
