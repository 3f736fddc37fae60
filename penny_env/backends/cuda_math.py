"""The math namespace ``xp`` of the CUDA copies (backends/builder.py, target "cuda"): kernels.SCALAR's
functions and constants for numba-cuda device code, as backends/numba_math.py is for the CPU. ``math``'s
functions compile to CUDA's libdevice (their last bit can differ from the CPU's libm: docs/gpu.md).
Imported only where numba-cuda is installed."""
import math
import types

_NAMESPACE = []


def _where(cond, a, b):
    return a if cond else b


def namespace():
    """The namespace module (built once per process: ``where`` is a device function)."""
    if not _NAMESPACE:
        from numba import cuda

        from . import numba_math
        ns = types.ModuleType("penny_env_cuda_math")
        ns.scalar = True
        ns.sin, ns.cos, ns.sqrt, ns.inf, ns.pi = math.sin, math.cos, math.sqrt, math.inf, math.pi
        ns.abs, ns.minimum, ns.maximum = abs, min, max
        ns.where = cuda.jit(device=True)(_where)
        import numba
        if numba.config.ENABLE_CUDASIM:  # the simulator runs the kernels as Python: Python's ints, masked (exact)
            from ..physics.kernels import SCALAR as ints
        else:
            ints = numba_math
        ns.u64, ns.to_float = ints.u64, ints.to_float
        for name in ("ONE", "GOLDEN", "M1", "M2", "MASK", "U11", "U27", "U30", "U31"):
            setattr(ns, name, getattr(ints, name))
        _NAMESPACE.append(ns)
    return _NAMESPACE[0]
