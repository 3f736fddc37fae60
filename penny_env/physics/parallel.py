"""The threading setup of the compiled parallel loops (numba ``prange``): which threading layer, and
one lock around every parallel call.

Deployed, the vector env and the batch API meet three things the parallel loop must survive:

* a learner on the same cores (SB3, torch): GNU OpenMP's idle threads spin (OMP_WAIT_POLICY active),
  and a parallel step beside one busy process ran 6 to 8 times slower than with threads that sleep;
* ``fork()`` after a parallel call (multiprocessing's default start method on Linux, SubprocVecEnv
  with "fork", Ray workers): a child that runs GNU OpenMP again is terminated ("fork() called from a
  process already using GNU OpenMP, this is unsafe");
* two Python threads stepping two vector envs: numba's workqueue layer aborts the process on
  concurrent use (it is not thread-safe).

numba's own workqueue layer sleeps when idle and is fork-safe; :data:`PARALLEL_LOCK` serialises
penny_env's parallel calls from several Python threads, so its one unsafe case never happens (and a
parallel call already uses every core, so taking turns loses nothing). :func:`configure` therefore picks
the workqueue layer, unless the user chose one (NUMBA_THREADING_LAYER in the environment, or
``numba.config.THREADING_LAYER`` set) or numba's threads already run (the layer is then fixed for the
process). The layer is process-wide: it also runs the user's own ``parallel=True`` functions, which
must then not be called from several threads at once (TBB is the layer that allows it: install tbb and
set NUMBA_THREADING_LAYER=tbb). tests/test_parallel.py checks all three cases.
"""
from __future__ import annotations

import os
import threading

PARALLEL_LOCK = threading.RLock()  # held around every call of a compiled parallel (prange) function
LAYER = "workqueue"


def configure() -> None:
    """Pick the workqueue threading layer for numba's parallel loops if nothing chose one yet (see the
    module docstring). Called before any penny_env parallel function is compiled or run."""
    import numba
    from numba.np.ufunc import parallel

    if "NUMBA_THREADING_LAYER" in os.environ or numba.config.THREADING_LAYER != "default":
        return
    if getattr(parallel, "_is_initialized", False):  # threads launched: the layer is fixed
        return
    numba.config.THREADING_LAYER = LAYER


def locked(f):
    """f called under :data:`PARALLEL_LOCK` (a compiled parallel function, for several Python threads)."""
    def call(*args):
        with PARALLEL_LOCK:
            return f(*args)
    call.__name__ = getattr(f, "__name__", "call")
    call.__wrapped__ = f
    return call
