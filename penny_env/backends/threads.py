"""The threading setup of the compiled parallel loops (numba ``prange``): which threading layer, how its
idle threads wait, one lock around every parallel call, and a serial path in forked children.

Deployed, the vector env and the batch API meet three things the parallel loop must survive:

* a learner on the same cores (SB3, torch): GNU OpenMP's idle threads spin (OMP_WAIT_POLICY active), and
  a parallel step beside one busy process ran several times slower than with threads that sleep;
* ``fork()`` after a parallel call (multiprocessing's default start method on Linux, SubprocVecEnv with
  "fork", Ray workers): a child that runs GNU OpenMP again is terminated ("fork() called from a process
  already using GNU OpenMP, this is unsafe");
* two Python threads stepping two vector envs: numba's workqueue layer (the one numba uses where OpenMP is
  missing, as in macOS wheels) aborts the process on concurrent use.

What penny_env does (docs/contention.md measures the alternatives side by side):

* the layer stays numba's default choice (TBB where it loads, else OpenMP, else workqueue): on a quiet
  machine workqueue ran the vector step about 40 % slower than OpenMP;
* :func:`configure` sets ``OMP_WAIT_POLICY=passive`` unless the user set it, before numba starts its
  threads (GNU OpenMP reads it when numba loads it): idle threads sleep instead of spinning, which costs a
  few per cent on a quiet machine and keeps the step from collapsing beside a busy process;
* :data:`PARALLEL_LOCK` serialises penny_env's parallel calls from several Python threads, so workqueue's
  unsafe case never happens (a parallel call already uses every core, so taking turns loses nothing);
* a child forked after the parent launched numba's threads, on any layer, runs penny_env's loops serially
  (the same functions compiled without ``parallel``, bitwise the same results; :func:`locked`): GNU
  OpenMP cannot run there, and a child forked while another thread was inside a parallel step under
  workqueue or TBB blocked for more than 20 s in 2 of 3 tries. The child also gets a fresh
  :data:`PARALLEL_LOCK` (:func:`_after_fork_in_child`): the parent's may be held, at the fork, by a thread
  the child does not have. Forked workers usually step one env each, so they lose little;
* so do calls with fewer than :data:`SERIAL_BELOW` pennies, where waking the sleeping threads would cost
  more than the work.

tests/backends/test_parallel.py checks all three cases. What remains is in README.md ("Deployment").
"""
from __future__ import annotations

import os
import threading

from .interrupts import compiling

PARALLEL_LOCK = threading.RLock()  # held around every call of a compiled parallel (prange) function
WAIT_POLICY = "passive"
# pennies per call below which the loop runs on the calling thread: waking OpenMP's sleeping threads took
# about 65 us per call on 2 cores (make_vec PennyReach-Ellipse-v0: 1.5 M env-steps/s at N = 256 against
# 2.6 M with spinning threads), about what one core needs for 150 pennies' steps
SERIAL_BELOW = 512
_FORKED_AFTER_OPENMP = False  # this process is a fork() child of one whose numba threads (OpenMP, workqueue
# or TBB) were launched: its loops run serially (the name is older than the other layers' case)


def threads_launched() -> bool:
    """numba's parallel threads are launched in this process, on whatever threading layer."""
    try:
        from numba.np.ufunc import parallel
    except ImportError:
        return False
    return bool(getattr(parallel, "_is_initialized", False))


def openmp_running() -> bool:
    """numba's threads are launched on its OpenMP layer in this process."""
    from numba.np.ufunc import parallel
    if not getattr(parallel, "_is_initialized", False):
        return False
    import numba
    try:
        return numba.threading_layer() == "omp"
    except ValueError:
        return False


def _after_fork_in_child() -> None:
    """In a fork() child: a new, free PARALLEL_LOCK (the parent's may be held by a thread that the child does not
    have, forever), and serial loops if numba's threads were launched (the child has none of them)."""
    global _FORKED_AFTER_OPENMP, PARALLEL_LOCK
    PARALLEL_LOCK = threading.RLock()
    try:
        _FORKED_AFTER_OPENMP = _FORKED_AFTER_OPENMP or threads_launched()
    except Exception:  # noqa: BLE001 (never break a fork over this)
        _FORKED_AFTER_OPENMP = True


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_after_fork_in_child)


def configure() -> None:
    """Let OpenMP's idle threads sleep (OMP_WAIT_POLICY=passive unless the user set it) before numba launches
    its threads. Called before any penny_env parallel function is compiled or run. The threading layer is
    left to the user (NUMBA_THREADING_LAYER) or numba's default order."""
    os.environ.setdefault("OMP_WAIT_POLICY", WAIT_POLICY)


def serial_now() -> bool:
    """Run penny_env's loops serially: this is a child forked after numba's threads were launched (see the
    module docstring)."""
    return _FORKED_AFTER_OPENMP


def launch_threads() -> None:
    """numba's threads launched now (a no-op once they are). A parallel loop's first call needs it: numba launches
    them when it compiles a parallel loop or loads one from its disk cache, but not when it loads a function that
    calls one and was compiled against a cached copy of that loop (numba issues #8578, #9938): the call went through
    a null pointer (numba_repairs.py, which keeps new cache entries right; this covers those written before)."""
    import numba
    numba.get_num_threads()  # (public API; it launches the threads first)


def locked(f, serial=None, count=None):
    """f called under :data:`PARALLEL_LOCK` (a compiled parallel function, for several Python threads);
    count(args) gives the pennies of a call (default: the first argument's last axis). ``serial()`` (the same function
    compiled without ``parallel``, built on first use) runs instead in a child forked after numba's threads were launched,
    and for fewer than :data:`SERIAL_BELOW` pennies, where waking the sleeping threads costs more than the work they share."""
    built = []
    count = count or (lambda args: args[0].shape[-1])

    def serial_function():
        if not built:
            built.append(serial())
        return built[0]

    warm = set()  # the paths ("serial", "parallel") called once: their first call compiles (or loads) them

    def call(*args):
        path = "serial" if serial is not None and (_FORKED_AFTER_OPENMP or count(args) < SERIAL_BELOW) else "parallel"
        if path not in warm:
            with compiling():  # (a Ctrl-C is held until the compile is done, and raised once it is kept: interrupts.py)
                if path == "parallel":
                    launch_threads()
                out = run(path, args)
                warm.add(path)
            return out
        return run(path, args)

    def run(path, args):
        if path == "serial":
            return serial_function()(*args)
        with PARALLEL_LOCK:
            return f(*args)
    call.__name__ = getattr(f, "__name__", "call")
    call.__wrapped__ = f
    # for a caller whose batch is always smaller than SERIAL_BELOW: the serial function, called directly
    # (right in a forked child too), saves the check and the lock on every call
    call.serial = serial_function if serial is not None else None
    call.serial_built = lambda: tuple(built)  # (the serial function where it is built: interrupts.overloads)
    return call
