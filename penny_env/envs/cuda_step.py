"""The vector env's step on a CUDA GPU (PennyVectorEnv(..., backend="cuda")): the same step functions
(envs/functional.py) and physics, built for the "cuda" target by physics/builder.py, one thread per env.

The envs' state (functional.EnvState) lives on the device as numba device arrays for the whole run. A
step launches functional.step_envs' kernel; the envs whose episode ended are reset on the host (Core.sample,
counter-based numpy draws, as on the CPU) and only their rows are copied to the device (reset_rows' kernel).
Outputs: torch tensors on the device, zero-copy through ``__cuda_array_interface__`` (outputs="torch"),
or numpy arrays copied to the host (outputs="numpy"). Actions: a device tensor (any object with
``__cuda_array_interface__``) stays on the device; numpy in is copied there.

Runs under numba's CUDA simulator too (NUMBA_ENABLE_CUDASIM=1, numpy outputs), which is how the tests
check it against the CPU backend on machines without a GPU (tests/test_cuda.py).
"""
from __future__ import annotations

import numpy as np

from ..physics.scalar import ImpactBuffers
from .functional import EnvState, StepResults

prange = range  # the loop below is compiled as a kernel (physics/builder.py)


def reset_row(j, rows, S, target, arc, dist, st):
    """Env rows[j] of the EnvState st gets the j-th column of the freshly drawn S (6, M), target, arc and
    dist, and a zero step count, arc count and time."""
    i = rows[j]
    for r in range(6):
        st.S[r, i] = S[r, j]
    for r in range(2):
        st.target[r, i] = target[r, j]
        st.arc[r, i] = arc[r, j]
    st.dist[i] = dist[j]
    st.count[i] = 0
    st.steps[i] = 0
    st.time[i] = 0.0


def reset_rows(rows, S, target, arc, dist, st):
    for j in prange(rows.shape[0]):
        reset_row(j, rows, S, target, arc, dist, st)


def torch_available_on_cuda() -> bool:
    try:
        import torch
    except ImportError:
        return False
    return bool(torch.cuda.is_available())


class CudaStep:
    """The device side of a PennyVectorEnv with backend="cuda" (see the module docstring)."""

    def __init__(self, env, kind, device=None, outputs="torch"):
        from numba import cuda

        from ..physics.builder import Builder
        from .functional import compiled_env_functions
        if outputs not in ("torch", "numpy"):
            raise ValueError(f"outputs must be 'torch' or 'numpy', got {outputs!r}")
        if outputs == "torch" and not torch_available_on_cuda():
            raise ValueError("outputs='torch' needs torch with CUDA; pass outputs='numpy' for numpy arrays")
        if device is not None:
            if isinstance(device, bool) or not isinstance(device, (int, np.integer)):
                raise TypeError(f"device must be a CUDA device index (int) or None, got {type(device).__name__}")
            if not 0 <= device < len(cuda.gpus):
                raise ValueError(f"device must be in [0, {len(cuda.gpus)}) (the CUDA devices here), got {device}")
            cuda.select_device(int(device))
        self.cuda = cuda
        self.device = 0 if device is None else int(device)
        self.outputs = outputs
        self.env = env
        self.fns = compiled_env_functions(kind, "cuda", law=env._m.law)
        b = Builder("cuda", f"reset_{kind}")
        b.copy(reset_row)
        self.reset_rows = b.loop(reset_rows)
        n = env.num_envs
        dev = cuda.device_array
        self.st = EnvState(dev((6, n)), dev((4, n)), dev((2, n)), dev((2, n)), dev(n, np.int64), dev(n), dev(n, np.int64),
                           dev(n))
        self.p, self.m, self.k = env._p, env._m, env._core.k

    # -- host <-> device ---------------------------------------------------------------------------
    def upload(self, S, target, arc, count, dist, steps, time):
        """The whole state from host arrays."""
        for d, h in zip(self.st, (S, None, target, arc, count, dist, steps, time)):
            if h is not None:
                d.copy_to_device(np.ascontiguousarray(h))

    def upload_rows(self, rows, S, target, arc, dist):
        """Rows ``rows`` freshly drawn (S (6, M), target (2, M), arc (2, M), dist (M,)) into the device state."""
        if len(rows):
            c = np.ascontiguousarray
            self.reset_rows(c(rows, dtype=np.int64), c(S), c(target), c(arc), c(dist), self.st)

    def observe(self, rows, obs):
        """trig and obs rows of the envs in ``rows`` (host int array) on the device."""
        if len(rows):
            self.fns["observe_rows_kernel"](np.ascontiguousarray(rows, dtype=np.int64), self.st, self.p, obs)

    def host(self, name):
        return getattr(self.st, name).copy_to_host()

    def out(self, a):
        """A device array as the env's output type (torch on the device, zero-copy; or numpy on the host)."""
        if self.outputs == "numpy":
            return a.copy_to_host()
        import torch
        return torch.as_tensor(a, device=f"cuda:{self.device}")

    def actions(self, actions, shape):
        """The actions on the device, float64 (N, n_act), checked: TypeError for a wrong type, ValueError naming
        the sub-env(s) for a wrong shape or a non-finite entry (as core.check_actions on the CPU)."""
        from .core import check_actions
        if hasattr(actions, "__cuda_array_interface__") and not isinstance(actions, np.ndarray):
            a = self.cuda.as_cuda_array(actions)
            if a.dtype.kind != "f":
                raise TypeError(f"actions must be a floating-point array, got dtype {a.dtype}")
            if a.shape != shape:
                raise ValueError(f"actions must have shape {shape}, got shape {a.shape}")
            import torch
            t = torch.as_tensor(a, device=f"cuda:{self.device}").to(torch.float64)
            finite = torch.isfinite(t).all(dim=1)
            if not bool(finite.all()):
                bad = torch.nonzero(~finite).flatten().cpu().numpy()
                raise ValueError(f"actions: non-finite action in sub-env(s) {bad[:10].tolist()}{' ...' if bad.size > 10 else ''}")
            return self.cuda.as_cuda_array(t.contiguous())
        return self.cuda.to_device(check_actions(actions, shape, "actions"))

    # -- the step ----------------------------------------------------------------------------------
    def step(self, a, skip, obs_dim, K):
        """One step of every env not in skip (a host bool array), a: the checked device actions
        (:meth:`actions`): returns (StepResults, ImpactBuffers) of device arrays. The caller resets the
        envs whose episode ended."""
        cuda = self.cuda
        n = self.env.num_envs
        dev = cuda.device_array
        out = StepResults(dev((n, obs_dim), np.float32), dev(n), dev(n, np.bool_), dev(n, np.bool_), dev(n), dev(n, np.int8))
        buf = ImpactBuffers(dev(n, np.int64), dev((n, K)), dev((n, K), np.int8), dev((n, K, 6)), dev((n, K), np.int8),
                            dev(n, np.int64), dev(n, np.int8))
        self.fns["step_envs_kernel"](self.st, a, cuda.to_device(np.ascontiguousarray(skip)), self.p, self.m, self.k, out, buf)
        return out, buf
