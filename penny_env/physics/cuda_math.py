"""The math namespace ``xp`` of the CUDA copies (physics/builder.py, target "cuda"): kernels.SCALAR's
functions for numba-cuda device code, as physics/numba_math.py is for the CPU. ``math``'s functions
compile to CUDA's libdevice (their last bit can differ from the CPU's libm: docs/gpu.md). Imported only
where numba-cuda is installed."""
import math
import types

_NAMESPACE = []


def _where(cond, a, b):
    return a if cond else b


def namespace():
    """The namespace module (built once per process: ``where`` is a device function)."""
    if not _NAMESPACE:
        from numba import cuda
        ns = types.ModuleType("penny_env_cuda_math")
        ns.scalar = True
        ns.sin, ns.cos, ns.sqrt, ns.inf = math.sin, math.cos, math.sqrt, math.inf
        ns.abs, ns.minimum, ns.maximum = abs, min, max
        ns.where = cuda.jit(device=True)(_where)
        _NAMESPACE.append(ns)
    return _NAMESPACE[0]
