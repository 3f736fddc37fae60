"""The vector env's step resident on a CUDA GPU (PennyVectorEnv(..., backend="cuda")).

The same step as on the CPU (step/functional.step_env: the stages and the autoreset in all three of
Gymnasium's modes, written once), built by backends/env.py as a kernel with one thread per env. Everything
a step touches lives on the device in buffers allocated once: the envs' state (functional.EnvState, with
each env's seed key, episode counter and pending-reset flag: resets are drawn on the device, by the same
counter-based draws as on the CPU), the actions, and two sets of outputs (functional.StepResults and the
impact buffers) that the steps use in turn. A warm step is: the actions copied into their buffer (on the
device when they are a device tensor), three kernel launches with their arguments marshalled once
(builder.PreparedLaunch; backends/env.py: the rare list's counter cleared, the fast kernel, the rare kernel), on
the current torch stream; no allocation, no copy to the host, no
synchronization. So a step can be captured in a CUDA graph (:class:`CudaGraphStep`).

Outputs (``outputs``): "torch" (device tensors on the buffers, zero-copy), "device" (numba device arrays:
the same without torch, e.g. under numba's CUDA simulator) or "numpy" (copied to the host each step, with
the CPU's checks and info layout). The two output sets alternate, so a step's outputs stay valid until the
step after the next; info masks (``_key``) are constant device tensors shared by all steps.

Runs under numba's CUDA simulator too (NUMBA_ENABLE_CUDASIM=1; outputs "device" or "numpy"), which is how
the tests check it against the CPU backend on machines without a GPU (tests/backends/test_cuda.py).
"""
from __future__ import annotations

import contextlib

import numpy as np

from ..physics.scalar import ImpactBuffers
from ..step.functional import SAME_STEP, EnvState, StepResults, check_actions
from .runner import RunnerOptions, StepOutputs, StepSpec, reset_outputs


def torch_available_on_cuda() -> bool:
    try:
        import torch
    except ImportError:
        return False
    return bool(torch.cuda.is_available())


class DeviceStep:
    """The runner of a PennyVectorEnv with backend="cuda" (backends/runner.Runner; the module docstring)."""

    def __init__(self, spec: StepSpec, n: int, K: int, options: RunnerOptions = RunnerOptions(outputs="torch")):
        from numba import cuda
        device, outputs, kernels = options
        fns, consts, p, m = spec.fns, spec.consts, spec.p, spec.m
        if outputs not in ("torch", "numpy", "device"):
            raise ValueError(f"outputs must be 'torch', 'device' or 'numpy', got {outputs!r}")
        if kernels not in ("split", "one"):
            raise ValueError(f"kernels must be 'split' (a fast kernel for impact-free steps and one for the rest) or "
                             f"'one', got {kernels!r}")
        if outputs == "torch" and not torch_available_on_cuda():
            raise ValueError("outputs='torch' needs torch with CUDA; pass outputs='numpy' for numpy arrays")
        if device is not None:
            if isinstance(device, bool) or not isinstance(device, (int, np.integer)):
                raise TypeError(f"device must be a CUDA device index (int) or None, got {type(device).__name__}")
            if not 0 <= device < len(cuda.gpus):
                raise ValueError(f"device must be in [0, {len(cuda.gpus)}) (the CUDA devices here), got {device}")
            cuda.select_device(int(device))
        self.cuda = cuda
        self.spec = spec
        self.device = 0 if device is None else int(device)
        self.outputs = outputs
        self.fns = fns
        self.p = p
        d = spec.obs_dim
        self.n, self.K, self.obs_dim, self.n_act = n, K, d, spec.n_act
        self.same_step = p.autoreset == SAME_STEP
        self.torch = None
        if outputs == "torch" or torch_available_on_cuda():
            import torch
            self.torch = torch
        alloc = self._alloc
        self.st = EnvState(alloc((6, n)), alloc((4, n)), alloc((2, n)), alloc((2, n)), alloc(n, np.int64), alloc(n),
                           alloc(n, np.int64), alloc(n), alloc(n, np.uint64), alloc(n, np.int64), alloc(n, np.bool_))
        self.consts = self._upload(consts)
        self.actions = alloc((n, self.n_act))
        self.sets = [self._output_set() for _ in range(2)]
        self.reset_obs = self._alloc_output((n, d), np.float32)
        self.parity = 0
        self.masks = self._view(self._upload(np.ones(n, dtype=bool), output=True))  # (constant: shared by every step)
        self.kernels = kernels
        self.work = alloc(n, np.int64)      # the rare kernel's list of envs (backends/env.py, fast_step_env)
        self.work_count = alloc(1, np.int64)  # its length (cleared by each step's first kernel)
        k = spec.k
        if kernels == "split":
            clear = self.fns.clear_work_count.prepare(self.work_count)
            self.launches = [(clear,
                              self.fns.fast_step_envs.prepare(self.st, self.actions, p, m, k, out, buf, self.work,
                                                              self.work_count),
                              self.fns.rare_step_envs.prepare(self.st, self.actions, p, m, k, out, buf, self.work,
                                                              self.work_count))
                             for out, buf in self.sets]
        else:
            self.launches = [(self.fns.step_envs.prepare(self.st, self.actions, self.consts, out, buf),)
                             for out, buf in self.sets]
        # the user-facing outputs (torch tensors on the buffers for outputs "torch"): the info's impact arrays only
        self.views = [(StepResults(*map(self._view, out)), ImpactBuffers(*map(self._view, buf[:3]), *buf[3:]))
                      for out, buf in self.sets]
        self._streams = {}

    # -- buffers -------------------------------------------------------------------------------------
    def _alloc(self, shape, dtype=np.float64):
        """A zeroed device array (numba's), allocated once."""
        return self.cuda.to_device(np.zeros(shape, dtype=dtype))

    def _alloc_output(self, shape, dtype=np.float64):
        """A zeroed device array for an output, allocated once: with torch outputs a torch tensor's memory
        (viewed by numba), which the step hands out as that tensor without a copy."""
        if self.outputs == "torch":
            name = "bool" if np.dtype(dtype) == np.bool_ else np.dtype(dtype).name
            t = self.torch.zeros(shape, dtype=getattr(self.torch, name), device=f"cuda:{self.device}")
            return self.cuda.as_cuda_array(t, sync=False)
        return self._alloc(shape, dtype)

    def _upload(self, host, output=False):
        d = (self._alloc_output if output else self._alloc)(host.shape, host.dtype)
        d.copy_to_device(np.ascontiguousarray(host))
        return d

    def _output_set(self):
        """One set of outputs (StepResults) and impact buffers ((K, n) slots, counts starting at K so that the
        first step pads every slot; no post-impact states: the step does not return them)."""
        n, K, d, alloc = self.n, self.K, self.obs_dim, self._alloc_output
        out = StepResults(alloc((n, d), np.float32), alloc(n), alloc(n, np.bool_), alloc(n, np.bool_), alloc(n),
                          alloc(n, np.int8), alloc(n), alloc(n), alloc(n, np.int64),
                          alloc((n if self.same_step else 1, d), np.float32), alloc(n, np.bool_))
        # (no post-impact states: empty slots, numba's own arrays; the scratch the info does not return, too)
        buf = ImpactBuffers(self._upload(np.full(n, K, dtype=np.int64), output=True), alloc((K, n)), alloc((K, n), np.int8),
                            self._alloc((0, 6, n)), self._alloc((0, n), np.int8), self._alloc(n, np.int64),
                            self._alloc(n, np.int8))
        return out, buf

    def _view(self, a):
        """The user-facing object of device array a: a torch tensor on its memory (outputs "torch"), a itself."""
        if self.outputs == "torch":
            return self.torch.as_tensor(a, device=f"cuda:{self.device}")
        return a

    def stream(self):
        """numba's view of the current torch stream (so that a step joins torch's work, and graph capture), or
        the default stream without torch."""
        if self.torch is None:
            return 0
        handle = self.torch.cuda.current_stream(self.device).cuda_stream
        if not handle:  # torch's default stream is CUDA's legacy default stream: numba's 0
            return 0
        s = self._streams.get(handle)
        if s is None:
            s = self._streams[handle] = self.cuda.external_stream(handle)
        return s

    # -- host <-> device (reset, pickling, rendering: not the step) --------------------------------
    def host(self, name):
        return getattr(self.st, name).copy_to_host()

    def state_to_host(self) -> EnvState:
        return EnvState(*(a.copy_to_host() for a in self.st))

    def state_from_host(self, st) -> None:
        for d, h in zip(self.st, st):
            d.copy_to_device(np.ascontiguousarray(h))

    # -- the step ------------------------------------------------------------------------------------
    def check_actions(self, actions):
        """The actions checked as far as the host can without a round trip, as :meth:`step` copies them into their
        device buffer: a TypeError for a wrong type, a ValueError for a wrong shape; non-finite values are refused
        on the host for host arrays and, with numpy outputs (which synchronize anyway), for device arrays of every
        kind; otherwise (device outputs) they end the env's episode in the kernel (functional.LIMIT_ACTION).
        Returns (source, through_torch): the array to copy, and whether torch copies it."""
        shape = (self.n, self.n_act)
        torch = self.torch
        if torch is not None and isinstance(actions, torch.Tensor) and actions.is_cuda:
            # a torch tensor: checked from its metadata (no numba view: numba would synchronize on its stream)
            self._check_device_array(actions.dtype.is_floating_point, actions.dtype, tuple(actions.shape))
            if self.outputs == "numpy":  # (numpy outputs synchronize anyway: checked on the host as the CPU does)
                check_actions(actions.detach().cpu().numpy(), shape, "actions")
            return actions.reshape(shape), True
        if hasattr(actions, "copy_to_host") and hasattr(actions, "dtype") and not isinstance(actions, np.ndarray):
            # a numba device array (numba-cuda's, or its simulator's): copied on the device
            self._check_device_array(actions.dtype.kind == "f", actions.dtype, actions.shape)
            if actions.dtype != np.float64:
                raise TypeError("actions as a numba device array must be float64 (or pass a torch tensor)")
            if self.outputs == "numpy":
                check_actions(actions.copy_to_host(), shape, "actions")
            return actions.reshape(shape), False
        if hasattr(actions, "__cuda_array_interface__") and not isinstance(actions, np.ndarray):
            a = self.cuda.as_cuda_array(actions, sync=False)
            self._check_device_array(a.dtype.kind == "f", a.dtype, a.shape)
            if self.outputs == "numpy":
                check_actions(a.copy_to_host(), shape, "actions")
            if a.dtype == np.float64 and a.is_c_contiguous():
                return a.reshape(shape), False
            if torch is not None:
                return torch.as_tensor(a, device=f"cuda:{self.device}").reshape(shape), True
            raise TypeError("actions on the device without torch must be a C-contiguous float64 array")
        a = check_actions(actions, shape, "actions")
        return np.ascontiguousarray(a, dtype=np.float64), False

    def _check_device_array(self, floating: bool, dtype, shape) -> None:
        """TypeError for a device array that is not floating point, ValueError for one of the wrong shape."""
        if not floating:
            raise TypeError(f"actions must be a floating-point array, got dtype {dtype}")
        want = (self.n, self.n_act)
        if tuple(shape) != want and not (self.n_act == 1 and tuple(shape) == (self.n,)):
            raise ValueError(f"actions must have shape {want}, got shape {tuple(shape)}")

    def _actions_t(self):
        if not hasattr(self, "_act_t"):
            self._act_t = self.torch.as_tensor(self.actions, device=f"cuda:{self.device}")
        return self._act_t

    def launch(self, parity):
        """The step's kernels on output set ``parity`` (prepared once), on the current stream."""
        stream = self.stream()
        for launch in self.launches[parity]:
            launch.launch(stream)

    def step(self, actions):
        """One step on the device (module docstring) on ``actions`` (as :meth:`check_actions` returns them),
        copied into their buffer first; its outputs (StepOutputs) in the outputs' type: views of the output set the
        step wrote (valid until the step after the next), or host copies (outputs "numpy")."""
        source, through_torch = actions
        if through_torch:
            self._actions_t().copy_(source)
        else:
            self.actions.copy_to_device(source, stream=self.stream())
        parity = self.parity
        self.launch(parity)
        self.parity = parity ^ 1
        out, buf = self.views[parity]
        if self.outputs == "numpy":
            host = StepResults(*(a.copy_to_host() for a in out))
            return StepOutputs(host, buf.count.copy_to_host(), np.ascontiguousarray(buf.time.copy_to_host().T),
                               np.ascontiguousarray(buf.end.copy_to_host().T))
        return StepOutputs(out, buf.count, buf.time.T, buf.end.T)

    def warm_up(self) -> None:
        """Nothing more to load: the step's kernels were compiled when their launches were prepared."""

    def mask(self):
        """The info masks: new numpy arrays (outputs "numpy"), else one constant device array shared by every key."""
        return np.ones(self.n, dtype=bool) if self.outputs == "numpy" else self.masks

    # -- reset ---------------------------------------------------------------------------------------
    def reset(self, keys, episodes, rows, states=None, targets=None):
        """The reset on the device: keys, episode counters and pending flags uploaded, the rows' fresh episodes
        drawn on the device (the same draws as on the CPU), reset options applied, every row's observation computed
        there. Returns (obs, StepOutputs of the reset's info) in the outputs' type."""
        host = self.state_to_host()
        host.key[:], host.episode[:] = keys, episodes
        host.pending[rows] = False
        for name in ("key", "episode", "pending"):
            getattr(self.st, name).copy_to_device(getattr(host, name))
        d_rows = self.cuda.to_device(np.ascontiguousarray(rows, dtype=np.int64))
        stream = self.stream()
        self.fns.reset_rows(d_rows, self.st, self.consts, self.reset_obs, stream=stream)
        if states is not None or targets is not None:
            fresh = self.state_to_host()  # the drawn rows, with the options' states and targets put in
            if states is not None:
                fresh.S[:, rows] = states[rows].T
                self.st.S.copy_to_device(fresh.S)
            if targets is not None:
                fresh.target[:, rows] = targets[rows].T
                self.st.target.copy_to_device(fresh.target)
            self.fns.observe_rows(d_rows, self.st, self.consts, self.reset_obs, stream=stream)
        others = np.flatnonzero(~np.isin(np.arange(self.n), rows))
        if others.size:
            self.fns.observe_rows(self.cuda.to_device(others.astype(np.int64)), self.st, self.consts, self.reset_obs,
                                  stream=stream)
        out = reset_outputs(None, self.state_to_host(), self.p, self.K)
        if self.outputs == "numpy":
            obs = self.reset_obs.copy_to_host()
            return obs, out._replace(results=out.results._replace(obs=obs))
        def up(a):
            return a if a is None else self._view(self._upload(np.ascontiguousarray(a), output=True))
        obs = self._view(self.reset_obs)
        results = StepResults(*(up(a) for a in out.results))._replace(obs=obs)
        return obs, StepOutputs(results, up(out.counts), up(out.times), up(out.ends))


@contextlib.contextmanager
def capture_guard():
    """Wrap a CUDA graph capture that holds env steps (CudaGraphStep, training/ppo_torch.py): numba frees
    device memory lazily, from a queue flushed when it fills (cuMemFree), and Python's cycle collector may drop
    the last reference to a numba array (an env closed before) at any moment; a cuMemFree while a stream is
    being captured invalidates the capture. Inside, numba defers its frees (cuda.defer_cleanup), after a
    collection."""
    import gc

    from numba import cuda
    gc.collect()
    with cuda.defer_cleanup():
        yield


class CudaGraphStep:
    """``env.step`` captured in a CUDA graph (torch.cuda.graph) and replayed: ``step = CudaGraphStep(env)``,
    then ``obs, reward, terminated, truncated, info = step(actions)`` with actions a device tensor of the
    action space's shape. The actions are copied into the graph's static input, the captured step replays
    (its kernel launch, on the current stream), and the outputs are the captured step's tensors, the same
    ones at every call (clone what you keep). Needs backend="cuda", outputs="torch" and a GPU. To fold the
    step into a larger graph (a policy's forward pass and the step, as training/ppo_torch.py does), capture
    ``env.step`` inside your own ``torch.cuda.graph`` the same way: after warm-up steps it allocates nothing
    and never synchronizes."""

    def __init__(self, env, warmup: int = 2):
        g = getattr(env, "_runner", None)
        if not isinstance(g, DeviceStep) or g.outputs != "torch":
            raise ValueError("CudaGraphStep needs a PennyVectorEnv with backend='cuda' and outputs='torch'")
        torch = g.torch
        self.env = env
        self.actions = torch.zeros((env.num_envs, g.n_act), dtype=torch.float32, device=f"cuda:{g.device}")
        side = torch.cuda.Stream(device=g.device)
        side.wait_stream(torch.cuda.current_stream(g.device))
        with torch.cuda.stream(side):  # warm-up on a side stream, as torch's graph capture asks
            for _ in range(warmup):
                env.step(self.actions)
        torch.cuda.current_stream(g.device).wait_stream(side)
        self.graph = torch.cuda.CUDAGraph()
        # captured on the warm-up's stream: the step's launches already know it (no stream set up while capturing)
        with capture_guard(), torch.cuda.graph(self.graph, stream=side):
            self.outputs = env.step(self.actions)

    def __call__(self, actions):
        self.actions.copy_(actions)
        self.graph.replay()
        return self.outputs
