"""PennyVectorEnv: N pennies stepped by one loop over the one-env step (envs/functional.py)."""
from __future__ import annotations

import numpy as np
import gymnasium as gym
from gymnasium import spaces
from gymnasium.error import ResetNeeded
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from ..physics.compiled import announce_compile, compiles
from ..physics.parallel import SERIAL_BELOW
from ..physics.scalar import impact_buffers, scalar_model
from .core import Core, check_actions, check_seed, render_fps, seed_keys, X, Y
from .functional import env_functions, env_params, kinetic_energy, pack
from .scene import resolve

MAX_IMPACTS_IN_INFO = 8


class PennyVectorEnv(VectorEnv):
    """``num_envs`` copies of :class:`~penny_env.envs.penny_env.PennyEnv` stepped as one batch.

    Same scenes, tasks, spaces, rewards and episode logic as PennyEnv (the spaces, rewards and
    observation layout are tabled in its docstring); ``single_action_space`` and
    ``single_observation_space`` are PennyEnv's, the batched spaces add a leading num_envs axis:

    =============================  =========================================================
    space                          value
    =============================  =========================================================
    ``single_action_space``        ``Box(-1, 1, (k,), float32)``, k = 2 (both), 1 (steer, drive)
    ``action_space``               ``Box(-1, 1, (num_envs, k), float32)``
    ``single_observation_space``   ``Box(low, high, (10,) or (11,), float32)`` (PennyEnv's table)
    ``observation_space``          the same with a leading ``num_envs`` axis
    =============================  =========================================================

    The step is PennyEnv's own step function (functional.env_step) in a loop over the envs: with
    the numba backend one compiled call, parallel over the envs (numba ``prange``); with
    backend="python" the same functions uncompiled (slow; for debugging). States live in one
    (6, num_envs) float64 array.

    Equivalence: sub-env i seeded with seed + i follows the trajectory of PennyEnv seeded with
    seed + i under the same actions, episode after episode, bitwise (the same function; tested).

    ``PennyVectorEnv(num_envs, scene="ellipse", task="reach", max_episode_steps=None,
    autoreset_mode=AutoresetMode.NEXT_STEP, render_mode=None, backend="auto",
    max_impacts_in_info=8, **overrides)``. max_episode_steps: episodes are truncated after this
    many steps (None: the task's).

    Autoreset (``autoreset_mode``):

    * NEXT_STEP (default): the step after an env's episode ended resets it (its obs is the reset
      obs, reward 0, terminated = truncated = False, impacts 0);
    * SAME_STEP: the ending step returns the reset obs and puts the last obs in
      ``info["final_obs"]`` (and ``{"is_success": ...}`` in ``info["final_info"]``), masked by
      ``info["_final_obs"]``;
    * DISABLED: nothing resets by itself; call ``reset(options={"reset_mask": mask})`` for the
      envs whose episode ended (stepping them on continues their episode; TorchRL does this).

    info (arrays over envs, each with its ``_key`` mask, fixed shapes from step to step):

    ====================  =========================================================================
    key                   value
    ====================  =========================================================================
    ``impacts``           (num_envs,) int64: every impact of the step (exact count)
    ``impact_times``      (num_envs, max_impacts_in_info) [s since the step's start], NaN-padded:
                          the first max_impacts_in_info impacts of the step
    ``impact_ends``       (num_envs, max_impacts_in_info) int8, +1 front / -1 back, 0-padded
    ``kinetic_energy``    [J]; ``time`` [s since reset]; ``distance`` [m] to the target
    ``arc_impacts``       impacts task: running count of impacts on the marked arc
    ``is_success``        every step: the task's success condition (True only where it terminated)
    ``limit``             (num_envs,) int8: 0, or the documented limit that truncated the env's
                          episode (1 "speed", 2 "impacts"; PennyEnv's table)
    ====================  =========================================================================

    **GPU** (``backend="cuda"``, ``device`` a CUDA device index, ``outputs`` "torch" or "numpy"): the
    same step functions built for CUDA (physics/builder.py), one GPU thread per env, the state kept on
    the device (envs/cuda_step.py). Observations, rewards, flags and the info's arrays come out as torch
    tensors on the device, zero-copy (outputs="torch", the default with backend="cuda"), or as numpy
    arrays (outputs="numpy"); actions may be device tensors (they stay there) or numpy. ``backend="auto"``
    takes CUDA where numba-cuda finds a GPU, with numpy outputs unless outputs="torch" is asked (so code
    written for numpy keeps working). SAME_STEP's ``final_obs`` rows are numpy. docs/gpu.md.

    Interrupted steps: a step interrupted by an exception (KeyboardInterrupt) may leave the
    envs' bookkeeping half done (stepped but not marked for autoreset); the next step() then
    raises ResetNeeded until a reset() of every env.

    reset options: ``reset_mask`` (num_envs,) bool, ``state`` ((6,) or (num_envs, 6)) and
    ``target`` ((2,) or (num_envs, 2)) for the envs reset (checked as PennyEnv's options).

    Bad input: a wrong action type raises TypeError, a wrong shape or a non-finite action in any
    sub-env ValueError naming the sub-env(s); no state changes.
    """

    metadata = {"render_modes": ["rgb_array"], "autoreset_mode": AutoresetMode.NEXT_STEP, "render_fps": 20}

    def __init__(self, num_envs: int = 1, scene="ellipse", task="reach", max_episode_steps=None,
                 autoreset_mode=AutoresetMode.NEXT_STEP, render_mode=None, backend="auto",
                 max_impacts_in_info: int = MAX_IMPACTS_IN_INFO, device=None, outputs=None, **overrides):
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)):
            raise TypeError(f"num_envs must be a positive integer, got {type(num_envs).__name__}")
        if num_envs < 1:
            raise ValueError(f"num_envs must be a positive integer, got {num_envs!r}")
        if isinstance(max_impacts_in_info, bool) or not isinstance(max_impacts_in_info, (int, np.integer)):
            raise TypeError(f"max_impacts_in_info must be an integer, got {type(max_impacts_in_info).__name__}")
        if max_impacts_in_info < 0:
            raise ValueError(f"max_impacts_in_info must be >= 0, got {max_impacts_in_info}")
        if max_episode_steps is not None:
            overrides["max_episode_steps"] = max_episode_steps
        self.scene, self.task = resolve(scene, task, **overrides)
        try:
            autoreset_mode = AutoresetMode(autoreset_mode)
        except ValueError:
            raise ValueError(f"autoreset_mode must be an AutoresetMode, got {autoreset_mode!r}") from None
        if render_mode is not None and render_mode != "rgb_array":
            raise ValueError(f"PennyVectorEnv render_mode must be None or 'rgb_array', got {render_mode!r}")
        self.num_envs = int(num_envs)
        if backend not in ("auto", "numba", "python", "cuda"):
            raise ValueError(f"backend must be 'auto', 'numba', 'python' or 'cuda', got {backend!r}")
        if outputs not in (None, "numpy", "torch"):
            raise ValueError(f"outputs must be None, 'numpy' or 'torch', got {outputs!r}")
        if backend not in ("auto", "cuda") and (device is not None or outputs == "torch"):
            raise ValueError(f"device and outputs='torch' need backend='cuda' (or 'auto' on a GPU), got backend={backend!r}")
        self.backend = backend
        self.device = device
        self.outputs = outputs
        self.render_mode = render_mode
        self.autoreset_mode = autoreset_mode
        self.max_impacts_in_info = int(max_impacts_in_info)
        self.metadata = dict(self.metadata, autoreset_mode=autoreset_mode,
                             render_fps=render_fps(self.scene.control_dt))
        self._setup()

    def _setup(self):
        c = self._make_core()
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
        self._in_step = False
        self._scratch = None  # the step's post-impact states, rest flags and arc counts (reused)

    def __getstate__(self):
        state = self.__dict__.copy()
        for key in ("_core", "_fns", "_p", "_m", "_consts", "_gpu", "_step_envs"):
            state.pop(key)
        state["_scratch"] = None
        if self._gpu is not None and self._S is not None:  # the device's state travels as host arrays
            for name, attr in (("S", "_S"), ("trig", "_trig"), ("target", "_target"), ("arc", "_arc"), ("count", "_count"),
                               ("dist", "_d"), ("steps", "_steps"), ("time", "_t")):
                state[attr] = self._gpu.host(name)
        state["_renderers"] = None
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)
        self._make_core()
        if self._gpu is not None and self._S is not None:
            self._gpu.upload(self._S, self._target, self._arc, self._count, self._d, self._steps, self._t)
            self._gpu.observe(np.arange(self.num_envs), self._gpu.cuda.device_array((self.num_envs, self._core.obs_dim),
                                                                                   np.float32))  # (the trig rows)

    def _make_core(self):
        on_gpu = self._on_gpu()
        core = self._core = Core(self.scene, self.task, backend="python" if on_gpu else self.backend)
        if on_gpu and not compiles(core.table):
            if self.backend == "cuda" or self.device is not None or self.outputs == "torch":
                raise ValueError(f"backend='cuda': scene.table {type(core.table).__name__} has no compiled formulas "
                                 "(registered tables with formulas and the open plane run on the GPU)")
            on_gpu = False
            core = self._core = Core(self.scene, self.task, backend=self.backend)
        self._p = env_params(core)
        self._m = scalar_model(core.params, core.table, core.law, core.settings)
        self._fns = env_functions(core.backend, self._m.kind)
        self._consts = pack(self._p, self._m, core.k)
        # fewer envs than parallel.SERIAL_BELOW: the serial loop, called directly (parallel.locked)
        serial = getattr(self._fns["step_envs"], "serial", None)
        self._step_envs = serial() if serial is not None and self.num_envs < SERIAL_BELOW else self._fns["step_envs"]
        self._gpu = None
        if on_gpu:
            from .cuda_step import CudaStep
            outputs = self.outputs or ("torch" if self.backend == "cuda" else "numpy")
            self._gpu = CudaStep(self, self._m.kind, self.device, outputs)
        elif core.backend == "numba":
            self._warm_up()
        return core

    def _on_gpu(self) -> bool:
        """backend "cuda" (numba-cuda and a GPU or its simulator, else ValueError); "auto" with a device or
        torch outputs asked likewise, else where numba-cuda finds a real GPU."""
        import importlib.util

        from ..physics.builder import cuda_available
        if self.backend == "cuda" or (self.backend == "auto" and (self.device is not None or self.outputs == "torch")):
            if importlib.util.find_spec("numba_cuda") is None:
                raise ValueError("backend='cuda' needs numba-cuda, the cuda extra: in a clone of penny_env, pip install -e \".[cuda]\" (docs/gpu.md)")
            if not cuda_available():
                raise ValueError("backend='cuda': numba-cuda finds no CUDA GPU here (nor its simulator, NUMBA_ENABLE_CUDASIM=1)")
            return True
        if self.backend != "auto" or importlib.util.find_spec("numba_cuda") is None:
            return False
        import numba
        return not numba.config.ENABLE_CUDASIM and cuda_available()

    def _warm_up(self):
        """Load the machine code (or compile it) now rather than in the first step."""
        c = self._core
        announce_compile("vector env step", "open plane" if c.table is None else type(c.table).__name__, self._m.kind,
                         self._fns["step_envs"].__wrapped__)
        from ..physics.parallel import SERIAL_BELOW, serial_now
        # both loops: one penny runs on the calling thread, SERIAL_BELOW in parallel (not in a forked child)
        for n in (1,) if serial_now() else (1, SERIAL_BELOW):
            S = np.zeros((6, n))
            trig = np.zeros((4, n))
            obs = np.empty((n, c.obs_dim), dtype=np.float32)
            ints = lambda: np.zeros(n, dtype=np.int64)  # noqa: E731
            st = (S, trig, np.zeros((2, n)), np.zeros((2, n)), ints(), np.zeros(n), ints(), np.zeros(n))
            self._fns["observe_rows"](np.zeros(1, dtype=np.int64), st, self._consts, obs[:1])
            out = (obs, np.zeros(n), np.zeros(n, dtype=bool), np.zeros(n, dtype=bool), np.zeros(n), np.zeros(n, dtype=np.int8))
            self._fns["step_envs"](st, np.zeros((n, 2)), np.zeros(n, dtype=bool), self._consts, out,
                                   tuple(impact_buffers(n, 1)))

    # ------------------------------------------------------------------------------------
    def reset(self, *, seed=None, options=None):
        """Reset all envs (or those in ``options["reset_mask"]``). seed: int (env i gets seed + i),
        a list of ints/None (one per env) or None."""
        n = self.num_envs
        int_seed = isinstance(seed, (int, np.integer)) and not isinstance(seed, (bool, np.bool_))
        if not (seed is None or int_seed or isinstance(seed, (list, tuple, np.ndarray))):
            raise TypeError(f"seed must be an int >= 0, None or a list of {n} seeds, got {type(seed).__name__}")
        if int_seed:
            seed = check_seed(seed, "seed", n)
        elif seed is not None:
            seed = [None if s is None else check_seed(s, f"seed[{i}]") for i, s in enumerate(seed)]
        super().reset(seed=seed if int_seed else None)
        c = self._core
        mask = self._true.copy()
        states = targets = None
        if options is not None:
            states, targets = c.check_options(options, n, extra=("reset_mask",))
            if "reset_mask" in options:
                mask = np.asarray(options["reset_mask"])
                if mask.dtype != bool:
                    raise TypeError(f"options['reset_mask'] must be a bool array, got dtype {mask.dtype}")
                if mask.shape != (n,):
                    raise ValueError(f"options['reset_mask'] must have shape ({n},), got {mask.shape}")
                if self._S is None and not mask.all():
                    raise ResetNeeded("the first reset must reset every env")
                if self._in_step and not mask.all():
                    raise ResetNeeded("the previous step was interrupted: reset every env (no reset_mask)")
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
            self._trig = np.zeros((4, n))  # cos/sin of theta and phi of self._S (the certificate uses them)
            self._d = np.zeros(n)
            self._trails = [[] for _ in range(n)] if self.render_mode else None
        rows = self._reset_envs(mask, states, targets)
        self._autoreset = np.zeros(n, dtype=bool)
        self._in_step = False
        K = self.max_impacts_in_info  # the step's info keys and shapes (TorchRL reads specs from them)
        if self._gpu is not None:
            return self._reset_gpu(rows, K)
        obs = np.empty((n, c.obs_dim), dtype=np.float32)  # every row: the envs outside a reset_mask keep their state
        self._fns["observe_rows"](np.arange(n), self._state(), self._consts, obs)
        info = self._info(np.zeros(n, dtype=np.int64), np.full((n, K), np.nan), np.zeros((n, K), dtype=np.int8),
                          kinetic_energy(self._S, self._p), np.zeros(n, dtype=bool), np.zeros(n, dtype=np.int8))
        return obs, info

    def _reset_gpu(self, rows, K):
        """reset() on the GPU: the rows drawn on the host go to the device, every row's observation is
        computed there; outputs as the step's (torch on the device or numpy)."""
        from numba import cuda
        g, n = self._gpu, self.num_envs
        g.upload_rows(rows, self._S[:, rows], self._target[:, rows], self._arc[:, rows], self._d[rows])
        obs = cuda.device_array((n, self._core.obs_dim), np.float32)
        g.observe(np.arange(n), obs)
        S = g.host("S")
        out = g.out
        info = self._info(out(cuda.to_device(np.zeros(n, dtype=np.int64))), out(cuda.to_device(np.full((n, K), np.nan))),
                          out(cuda.to_device(np.zeros((n, K), dtype=np.int8))),
                          out(cuda.to_device(kinetic_energy(S, self._p))), out(cuda.to_device(np.zeros(n, dtype=bool))),
                          out(cuda.to_device(np.zeros(n, dtype=np.int8))))
        return out(obs), info

    def _reset_envs(self, mask, states=None, targets=None):
        """Draw the next episode of the envs in mask (their trig and obs: observe_rows); returns their indices."""
        idx = np.flatnonzero(mask)
        if idx.size == 0:
            return idx
        c = self._core
        S, target, arc = c.sample(self._keys[idx], self._episodes[idx])
        if states is not None:
            S = states[idx].T
        if targets is not None:
            target = targets[idx].T
        self._S[:, idx] = S
        self._target[:, idx] = target
        self._arc[:, idx] = arc
        self._steps[idx] = 0
        self._count[idx] = 0
        self._t[idx] = 0.0
        self._d[idx] = c.distance(S, target)
        if self._trails is not None:
            for i in idx:
                self._trails[i] = [(self._S[X, i], self._S[Y, i])]
        return idx

    def step(self, actions):
        if self._S is None:
            raise ResetNeeded("PennyVectorEnv.step() called before reset()")
        if self._in_step:
            raise ResetNeeded("PennyVectorEnv.step(): the previous step was interrupted (an exception such as "
                              "KeyboardInterrupt inside it) and its bookkeeping may be half done; call reset()")
        if self._gpu is not None:
            return self._step_gpu(actions)
        n = self.num_envs
        c = self._core
        a = check_actions(actions, (n, c.n_act), "actions")  # the step clips, as PennyEnv does
        next_step = self.autoreset_mode == AutoresetMode.NEXT_STEP
        skip = self._autoreset if next_step else np.zeros(n, dtype=bool)
        K = self.max_impacts_in_info
        obs = np.empty((n, c.obs_dim), dtype=np.float32)  # new arrays each step: the caller may keep them
        rew = np.empty(n)
        term = np.empty(n, dtype=bool)
        trunc = np.empty(n, dtype=bool)
        energy = np.empty(n)
        limit = np.empty(n, dtype=np.int8)
        # the info's impact counts, times and ends are the buffers' (new arrays each step); the post-impact
        # states, rest flags and arc counts, which the info does not return, are reused from step to step
        if self._scratch is None:
            self._scratch = (np.empty((n, K, 6)), np.empty((n, K), dtype=np.int8), np.empty(n, dtype=np.int64))
        post, rest, arc_count = self._scratch
        buf = (np.empty(n, dtype=np.int64), np.empty((n, K)), np.empty((n, K), dtype=np.int8), post, rest,
               arc_count)  # (scalar.ImpactBuffers' fields; step_env clears every row)
        # from here to the autoreset flags the step's bookkeeping must run whole (class docstring)
        self._in_step = True
        self._step_envs(self._state(), a, skip, self._consts, (obs, rew, term, trunc, energy, limit), buf)
        n_imp, times, ends = buf[0], buf[1], buf[2]
        self._extend_trails()
        done = term | trunc
        if next_step and skip.any():  # the envs whose episode ended at the previous step reset now
            self._episodes[skip] += np.uint64(1)
            rows = self._reset_envs(skip)
            self._fns["observe_rows"](rows, self._state(), self._consts, obs)
            energy[rows] = kinetic_energy(self._S[:, rows], self._p)
        info = self._info(n_imp, times, ends, energy, term, limit)
        if next_step:
            self._autoreset = done
        elif self.autoreset_mode == AutoresetMode.SAME_STEP and done.any():
            self._end_episodes_same_step(info, obs, done, term)
        self._in_step = False
        return obs, rew, term, trunc, info

    def _step_gpu(self, actions):
        """step() on the GPU (envs/cuda_step.py): the kernel steps every env; the envs whose episode ended
        reset on the host (their rows copied to the device), as the CPU step does, in the same order."""
        g, n, c = self._gpu, self.num_envs, self._core
        next_step = self.autoreset_mode == AutoresetMode.NEXT_STEP
        skip = self._autoreset if next_step else np.zeros(n, dtype=bool)
        K = self.max_impacts_in_info
        a = g.actions(actions, (n, c.n_act))  # checked before the step starts (nothing changes on bad input)
        self._in_step = True
        res, buf = g.step(a, skip, c.obs_dim, K)
        reset_rows = np.zeros(0, dtype=np.int64)
        if next_step and skip.any():
            self._episodes[skip] += np.uint64(1)
            reset_rows = self._reset_envs(skip)
            g.upload_rows(reset_rows, self._S[:, reset_rows], self._target[:, reset_rows], self._arc[:, reset_rows],
                          self._d[reset_rows])
            g.observe(reset_rows, res.obs)
        term, trunc = res.terminated.copy_to_host(), res.truncated.copy_to_host()
        done = term | trunc
        final = None
        if self.autoreset_mode == AutoresetMode.SAME_STEP and done.any():
            rows = np.flatnonzero(done)
            final = (rows, res.obs.copy_to_host()[rows])
            self._episodes[done] += np.uint64(1)
            reset_rows = self._reset_envs(done)
            g.upload_rows(reset_rows, self._S[:, reset_rows], self._target[:, reset_rows], self._arc[:, reset_rows],
                          self._d[reset_rows])
            g.observe(reset_rows, res.obs)
        if self._trails is not None:
            self._S = g.host("S")
            self._extend_trails()
        out = g.out
        energy = out(res.kinetic_energy)
        if reset_rows.size:  # the reset envs' energy (the kernel left their rows)
            energy[reset_rows] = energy.new_tensor(kinetic_energy(self._S[:, reset_rows], self._p)) \
                if hasattr(energy, "new_tensor") else kinetic_energy(self._S[:, reset_rows], self._p)
        term_out = out(res.terminated)
        info = self._info(out(buf.count), out(buf.time), out(buf.end), energy, term_out, out(res.limit))
        if next_step:
            self._autoreset = done
        elif final is not None:
            rows, last = final
            final_obs, final_info = np.empty(n, dtype=object), np.empty(n, dtype=object)
            for j, i in enumerate(rows):
                final_obs[i] = last[j]
                final_info[i] = {"is_success": bool(term[i])}
            info["final_obs"], info["_final_obs"] = final_obs, done.copy()
            info["final_info"], info["_final_info"] = final_info, done.copy()
        self._in_step = False
        return out(res.obs), out(res.reward), term_out, out(res.truncated), info

    def _end_episodes_same_step(self, info, obs, done, terminated):
        """SAME_STEP autoreset: the last obs and info of the envs whose episode ended go to
        info["final_obs"] / info["final_info"], then those envs reset."""
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
        self._fns["observe_rows"](self._reset_envs(done), self._state(), self._consts, obs)

    def _state(self):
        """The envs' state arrays as the plain tuple of functional.EnvState's fields the step takes."""
        return (self._S, self._trig, self._target, self._arc, self._count, self._d, self._steps, self._t)

    def _extend_trails(self):
        if self._trails is not None:
            for i in range(self.num_envs):
                self._trails[i].append((self._S[X, i], self._S[Y, i]))
                del self._trails[i][:-200]

    def _info(self, counts, times, ends, energy, success, limit):
        t = self._true
        if self._gpu is not None:  # the running values live on the device
            g = self._gpu
            time, dist, count = (g.out(getattr(g.st, name)).clone() if g.outputs == "torch" else g.host(name)
                                 for name in ("time", "dist", "count"))
        else:
            time, dist = self._t.copy(), self._d.copy()
            count = self._count.copy() if self._core.impacts else None
        info = {"impacts": counts, "_impacts": t.copy(), "impact_times": times, "_impact_times": t.copy(),
                "impact_ends": ends, "_impact_ends": t.copy(), "kinetic_energy": energy,
                "_kinetic_energy": t.copy(), "time": time, "_time": t.copy(), "distance": dist,
                "_distance": t.copy(), "is_success": success.copy() if hasattr(success, "copy") else success.clone(),
                "_is_success": t.copy(), "limit": limit, "_limit": t.copy()}
        if self._core.impacts:
            info["arc_impacts"] = count
            info["_arc_impacts"] = t.copy()
        return info

    @property
    def array_namespace(self) -> str:
        """"torch" where the step returns torch tensors (the CUDA backend's default outputs), else "numpy"."""
        return "torch" if getattr(self, "_gpu", None) is not None and self._gpu.outputs == "torch" else "numpy"

    # -- state access ---------------------------------------------------------------------
    @property
    def states(self) -> np.ndarray:
        """(num_envs, 6) copy of the pennies' states (x, y, theta, phi, theta_dot, phi_dot), numpy."""
        if self._S is None:
            raise ResetNeeded("call reset() first")
        if self._gpu is not None:
            return self._gpu.host("S").T.copy()
        return self._S.T.copy()

    @property
    def targets(self) -> np.ndarray:
        if self._S is None:
            raise ResetNeeded("call reset() first")
        if self._gpu is not None:
            return self._gpu.host("target").T.copy()
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
