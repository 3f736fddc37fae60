"""PennyVectorEnv: N pennies stepped by one loop over the one-env step (step/functional.py)."""
from __future__ import annotations

import numpy as np
import gymnasium as gym
from gymnasium import spaces
from gymnasium.error import ResetNeeded
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from ..backends import stepping
from .core import Core, check_seed, render_fps, seed_keys, warn_limits, X, Y
from ..step.functional import DISABLED, LIMIT_LAW_NONFINITE, LIMIT_TASK_OUTPUT, NEXT_STEP, SAME_STEP
from .limits import check_int64, check_memory, vector_env_bytes
from .scene import resolve

MAX_IMPACTS_IN_INFO = 8
AUTORESET_CODES = {AutoresetMode.NEXT_STEP: NEXT_STEP, AutoresetMode.SAME_STEP: SAME_STEP, AutoresetMode.DISABLED: DISABLED}


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

    The step is PennyEnv's own step function (functional.env_step) in a loop over the envs, autoreset
    included (functional.step_env, written once for every backend): with the numba backend one compiled
    call, parallel over the envs (numba ``prange``); with backend="python" the same functions uncompiled
    (slow; for debugging); with backend="cuda" three kernel launches prepared once (docs/gpu.md), the state
    resident on the GPU. States
    live in one (6, num_envs) float64 array.

    Equivalence: sub-env i seeded with seed + i follows the trajectory of PennyEnv seeded with
    seed + i under the same actions, episode after episode, bitwise (the same function; tested).

    ``PennyVectorEnv(num_envs, scene="ellipse", task="reach", max_episode_steps=None,
    autoreset_mode=AutoresetMode.NEXT_STEP, render_mode=None, backend="auto",
    max_impacts_in_info=8, **overrides)``. max_episode_steps: episodes are truncated after this
    many steps (None: the task's). A num_envs beyond int64, or whose arrays would not fit in the
    memory available now (envs/limits.py estimates the bytes per env), is refused with a
    ValueError that says how much it needs.

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
                          episode (1 "speed", 2 "impacts", 3 "law_nonfinite", 4 "law_energy",
                          5 "outside_wall"; PennyEnv's table; 6 "action": a non-finite action
                          on the CUDA backend with torch outputs, below)
    ====================  =========================================================================

    **GPU** (``backend="cuda"``, ``device`` a CUDA device index, ``outputs`` "torch" or "numpy"): the
    same step functions built for CUDA (backends/builder.py), one GPU thread per env, the state and the
    autoreset on the device (backends/cuda_env.py): after warm-up a step allocates nothing, copies nothing
    to or from the host and never synchronizes (outputs="torch"). Observations, rewards, flags and the
    info's arrays are torch tensors on the device in buffers allocated once and used in turn by every
    other step: a step's outputs stay valid until the step after the next (keep them longer with
    ``.clone()``). SAME_STEP's ``final_obs`` is a device tensor masked by ``_final_obs``. A non-finite
    action does not raise there (that would need a round trip to the host): the env is not stepped and its
    episode ends, truncated, with ``info["limit"]`` 6 "action". outputs="numpy" copies the outputs to the
    host (and raises on non-finite actions as the CPU does). ``backend="auto"`` takes CUDA where numba-cuda
    finds a GPU, with numpy outputs unless outputs="torch" is asked. docs/gpu.md.

    Interrupted steps and resets: a step or a reset interrupted by an exception (KeyboardInterrupt)
    may leave the envs' bookkeeping half done (stepped but not marked for autoreset, half drawn); the
    next step() then raises ResetNeeded until a reset() of every env. A reset whose seed or options are
    refused changes nothing.

    reset options: ``reset_mask`` (num_envs,) bool, ``state`` ((6,) or (num_envs, 6)) and
    ``target`` ((2,) or (num_envs, 2)) for the envs reset (checked as PennyEnv's options).

    Bad input: a wrong action type raises TypeError, a wrong shape or a non-finite action in any
    sub-env ValueError naming the sub-env(s); no state changes.
    """

    metadata = {"render_modes": ["rgb_array"], "autoreset_mode": AutoresetMode.NEXT_STEP, "render_fps": 20}

    def __init__(self, num_envs: int = 1, scene="ellipse", task="reach", max_episode_steps=None,
                 autoreset_mode=AutoresetMode.NEXT_STEP, render_mode=None, backend="auto",
                 max_impacts_in_info: int = MAX_IMPACTS_IN_INFO, device=None, outputs=None, cuda_options=None,
                 **overrides):
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)):
            raise TypeError(f"num_envs must be a positive integer, got {type(num_envs).__name__}")
        if num_envs < 1:
            raise ValueError(f"num_envs must be a positive integer, got {num_envs!r}")
        check_int64("num_envs", num_envs)
        if isinstance(max_impacts_in_info, bool) or not isinstance(max_impacts_in_info, (int, np.integer)):
            raise TypeError(f"max_impacts_in_info must be an integer, got {type(max_impacts_in_info).__name__}")
        if max_impacts_in_info < 0:
            raise ValueError(f"max_impacts_in_info must be >= 0, got {max_impacts_in_info}")
        check_int64("max_impacts_in_info", max_impacts_in_info)
        if max_episode_steps is not None:
            overrides["max_episode_steps"] = max_episode_steps
        self.scene, self.task = resolve(scene, task, **overrides)
        # the envs' arrays must fit in memory (envs/limits.py): refused here rather than by a MemoryError in step()
        from ..step.tasks import task_record
        per_env = vector_env_bytes(task_record(self.task.kind).obs_dim, int(max_impacts_in_info))
        check_memory("num_envs", num_envs, per_env * int(num_envs),
                     f"a PennyVectorEnv of that many envs ({per_env} B per env with max_impacts_in_info = "
                     f"{max_impacts_in_info}; use fewer envs per process)")
        try:
            autoreset_mode = AutoresetMode(autoreset_mode)
        except ValueError:
            raise ValueError(f"autoreset_mode must be an AutoresetMode, got {autoreset_mode!r}") from None
        if render_mode is not None and render_mode != "rgb_array":
            raise ValueError(f"PennyVectorEnv render_mode must be None or 'rgb_array', got {render_mode!r}")
        self.num_envs = int(num_envs)
        if backend not in ("auto", "numba", "python", "cuda"):
            raise ValueError(f"backend must be 'auto', 'numba', 'python' or 'cuda', got {backend!r}")
        if outputs not in (None, "numpy", "torch", "device"):
            raise ValueError(f"outputs must be None, 'numpy', 'torch' or 'device', got {outputs!r}")
        if backend not in ("auto", "cuda") and (device is not None or outputs in ("torch", "device")):
            raise ValueError(f"device and outputs='torch' need backend='cuda' (or 'auto' on a GPU), got backend={backend!r}")
        if cuda_options is not None and (not isinstance(cuda_options, dict)
                                         or set(cuda_options) - {"kernels", "max_registers"}):
            raise ValueError(f"cuda_options must be a dict with keys 'kernels' and 'max_registers', got {cuda_options!r}")
        self.backend = backend
        self.device = device
        self.outputs = outputs
        self.cuda_options = dict(cuda_options or {})
        self.render_mode = render_mode
        self.autoreset_mode = autoreset_mode
        self.max_impacts_in_info = int(max_impacts_in_info)
        self.metadata = dict(self.metadata, autoreset_mode=autoreset_mode,
                             render_fps=render_fps(self.scene.control_dt))
        self._setup()

    def _setup(self):
        self._trails = None
        c = self._make_core()
        n = self.num_envs
        self.single_action_space = spaces.Box(-1.0, 1.0, (c.n_act,), np.float32)
        lo, hi = c.obs_bounds()
        self.single_observation_space = spaces.Box(lo, hi, dtype=np.float32)
        self.action_space = batch_space(self.single_action_space, n)
        self.observation_space = batch_space(self.single_observation_space, n)
        self._started = False    # a first reset has drawn every env's episode
        self._renderers = None
        self._in_step = False

    def __getstate__(self):
        state = self.__dict__.copy()
        for key in ("_core", "_fns", "_p", "_m", "_consts", "_runner"):
            state.pop(key)
        state["_host_state"] = self._runner.state_to_host() if self._started else None
        state["_renderers"] = None
        return state

    def __setstate__(self, state):
        host = state.pop("_host_state")
        self.__dict__.update(state)
        self._make_core()
        if host is not None:
            self._runner.state_from_host(host)

    def _make_core(self):
        """The Core and the runner (backends/stepping.make_runner: the CPU or a GPU, the step compiled or loaded
        now, not inside a step or a reset)."""
        core, runner = stepping.make_runner(lambda backend: Core(self.scene, self.task, backend=backend),
                                            self.num_envs, self.max_impacts_in_info,
                                            AUTORESET_CODES[self.autoreset_mode], self.backend, self.device,
                                            self.outputs, self.cuda_options)
        self._core, self._runner = core, runner
        spec = runner.spec
        self._p, self._m, self._fns, self._consts = spec.p, spec.m, spec.fns, spec.consts
        return core

    # ------------------------------------------------------------------------------------
    def reset(self, *, seed=None, options=None):
        """Reset all envs (or those in ``options["reset_mask"]``). seed: int (env i gets seed + i),
        a list of ints/None (one per env) or None. A refused seed or option changes nothing; a reset
        interrupted once it has begun changing the envs (Ctrl-C) makes the next step() raise ResetNeeded,
        as an interrupted step does."""
        n = self.num_envs
        int_seed = isinstance(seed, (int, np.integer)) and not isinstance(seed, (bool, np.bool_))
        if not (seed is None or int_seed or isinstance(seed, (list, tuple, np.ndarray))):
            raise TypeError(f"seed must be an int >= 0, None or a list of {n} seeds, got {type(seed).__name__}")
        seeds = None
        if int_seed:
            seed = check_seed(seed, "seed", n)
            seeds = [int(seed) + i for i in range(n)]
        elif seed is not None:
            seed = [None if s is None else check_seed(s, f"seed[{i}]") for i, s in enumerate(seed)]
            if len(seed) != n:
                raise ValueError(f"seed must be an int, None or a list of {n} seeds, got {len(seed)} seeds")
        c = self._core
        mask = np.ones(n, dtype=bool)
        states = targets = None
        if options is not None:
            states, targets = c.check_options(options, n, extra=("reset_mask",))
            if "reset_mask" in options:
                mask = np.asarray(options["reset_mask"])
                if mask.dtype != bool:
                    raise TypeError(f"options['reset_mask'] must be a bool array, got dtype {mask.dtype}")
                if mask.shape != (n,):
                    raise ValueError(f"options['reset_mask'] must have shape ({n},), got {mask.shape}")
                if not self._started and not mask.all():
                    raise ResetNeeded("the first reset must reset every env")
                if self._in_step and not mask.all():
                    raise ResetNeeded("the previous step or reset was interrupted: reset every env (no reset_mask)")
        # from here on the envs change: guarded as a step is (the flag is cleared once every row is whole)
        self._in_step = True
        super().reset(seed=seed if int_seed else None)
        first = not self._started
        if first:  # (every env's key is drawn below, its episode counter starts at 0)
            keys, episodes = np.zeros(n, dtype=np.uint64), np.zeros(n, dtype=np.int64)
        else:
            host = self._runner.state_to_host()
            keys, episodes = host.key.copy(), host.episode.copy()
        if first:
            keys[:] = seed_keys(self.np_random.integers(0, 2**63, size=n))
        if seed is None:
            episodes[mask] += 0 if first else 1
        else:
            # one vectorized hash for the seeds given; a None draws from np_random, in row order
            given = seeds if int_seed else [self.np_random.integers(0, 2**63) if s is None and mask[i] else s
                                            for i, s in enumerate(seed)]
            keys[mask] = seed_keys([s for s, m in zip(given, mask) if m])
            episodes[mask] = 0
        rows = np.flatnonzero(mask)
        obs, out = self._runner.reset(keys, episodes, rows, states, targets)
        self._started = True
        if first:
            self._trails = [[] for _ in range(n)] if self.render_mode else None
        if self._trails is not None:
            S = self._runner.host("S")
            for i in rows:
                self._trails[i] = [(S[X, i], S[Y, i])]
        info = self._info(out)
        self._in_step = False  # (last: every row whole)
        return obs, info

    def step(self, actions):
        if not self._started:
            raise ResetNeeded("PennyVectorEnv.step() called before reset()")
        if self._in_step:
            raise ResetNeeded("PennyVectorEnv.step(): the previous step() or reset() was interrupted (an exception such "
                              "as KeyboardInterrupt inside it) and its bookkeeping may be half done; call reset()")
        runner = self._runner
        actions = runner.check_actions(actions)  # before anything changes (TypeError / ValueError naming the sub-env)
        # from here to the end of the runner's step the bookkeeping must run whole (class docstring)
        self._in_step = True
        try:
            out = runner.step(actions)
        except Exception as exc:  # a user's law or table raising in the plain-Python step: named, reset needed
            named = self._core.named_failure(exc, "PennyVectorEnv.step")
            if named is None:
                raise
            raise named from exc
        self._in_step = False
        res = out.results
        self._extend_trails()
        info = self._info(out)
        if runner.outputs == "numpy":
            self._warn_faults(res)
            if self.autoreset_mode == AutoresetMode.SAME_STEP and res.ended.any():
                info.update(self._final_entries(res.final_obs.copy(), res.ended.copy(), res.terminated))
        elif self.autoreset_mode == AutoresetMode.SAME_STEP:  # (device outputs: which envs ended is not read here)
            info.update(self._final_entries(res.final_obs, res.ended, res.terminated))
        return res.obs, res.reward, res.terminated, res.truncated, info

    def _warn_faults(self, res):
        """A warning for the episodes that a guard ended at this step (the event loop's, physics/faults.py, or the
        task's outputs', with the cause found in the first such env's observation: core.warn_limits), one per kind,
        at the step whose info["limit"] says so, in every autoreset mode; info["limit"] names every one of them.
        (Device outputs leave it to info["limit"]: a warning would need the host to read the limits each step.)"""
        limits = res.limit
        if not limits.size:
            return
        # the usual case, no fault, in one pass (a numpy reduction costs about 1 us at any size; a few envs' bytes
        # are scanned faster by Python's max over the bytes)
        if (max(limits.tobytes()) if limits.size <= 64 else limits.max()) < LIMIT_LAW_NONFINITE:
            return
        task = np.flatnonzero(limits == LIMIT_TASK_OUTPUT)
        outputs = None
        if task.size:  # (SAME_STEP: the ended episode's last observation is final_obs; obs is the new episode's)
            i = task[0]
            outputs = (res.final_obs[i] if self.autoreset_mode == AutoresetMode.SAME_STEP else res.obs[i], res.dist[i])
        warn_limits(self._core, np.unique(limits[limits >= LIMIT_LAW_NONFINITE]), outputs)

    def _info(self, out) -> dict:
        """The info of a step or a reset, from the runner's outputs in their own array type (numpy, torch or numba
        device arrays): the same keys and shapes on every step and reset, each with its ``_key`` mask."""
        res = out.results
        mask = self._runner.mask
        info = {"impacts": out.counts, "_impacts": mask(), "impact_times": out.times, "_impact_times": mask(),
                "impact_ends": out.ends, "_impact_ends": mask(), "kinetic_energy": res.kinetic_energy,
                "_kinetic_energy": mask(), "time": res.time, "_time": mask(), "distance": res.dist, "_distance": mask(),
                "is_success": res.terminated, "_is_success": mask(), "limit": res.limit, "_limit": mask()}
        if self._core.counts_arc:
            info["arc_impacts"] = res.arc_count
            info["_arc_impacts"] = mask()
        return info

    @staticmethod
    def _final_entries(final_obs, ended, terminated) -> dict:
        """SAME_STEP autoreset, Gymnasium's keys: the last observation of the envs whose episode ended (rows of
        ``final_obs``, masked by ``_final_obs``) and their final info (``{"is_success": ..., "_is_success": ...}``,
        masked by ``_final_info``)."""
        return {"final_obs": final_obs, "_final_obs": ended, "final_info": {"is_success": terminated, "_is_success": ended},
                "_final_info": ended}

    def _extend_trails(self):
        if self._trails is not None:
            S = self._runner.host("S")
            for i in range(self.num_envs):
                self._trails[i].append((S[X, i], S[Y, i]))
                del self._trails[i][:-200]

    @property
    def array_namespace(self) -> str:
        """"torch" where the step returns torch tensors (the CUDA backend's default outputs), else "numpy"."""
        return "torch" if self._runner.outputs == "torch" else "numpy"

    # -- state access ---------------------------------------------------------------------
    @property
    def states(self) -> np.ndarray:
        """(num_envs, 6) copy of the pennies' states (x, y, theta, phi, theta_dot, phi_dot), numpy."""
        if not self._started:
            raise ResetNeeded("call reset() first")
        return self._runner.host("S").T.copy()

    @property
    def targets(self) -> np.ndarray:
        if not self._started:
            raise ResetNeeded("call reset() first")
        return self._runner.host("target").T.copy()

    def render(self):
        """Frames of the sub-envs (a tuple of uint8 arrays) in render_mode "rgb_array"."""
        if self.render_mode is None:
            gym.logger.warn("PennyVectorEnv.render() called without render_mode='rgb_array'")
            return None
        if not self._started:
            raise ResetNeeded("PennyVectorEnv.render() called before reset()")
        from .rendering import Renderer
        if self._renderers is None:
            self._renderers = Renderer(self._core, "rgb_array", self.metadata["render_fps"])
        r = self._renderers
        S, target, arc = (self._runner.host(name) for name in ("S", "target", "arc"))
        return tuple(r.frame(tuple(S[:, i]), tuple(target[:, i]), self._trails[i], tuple(arc[:, i]))
                     for i in range(self.num_envs))

    def close_extras(self, **kwargs):
        self._renderers = None
