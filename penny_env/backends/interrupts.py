"""Ctrl-C, concurrent processes and the compiler: numba compiles a function at its first call for a signature, and llvmlite frees
its objects in finalizers that Python's cycle collector runs at any later moment. A KeyboardInterrupt inside
either corrupted LLVM's state: the process aborted ("free(): double free detected in tcache 2", llvmlite's
``ffi.close`` in ``__del__``) when a thread sent SIGINT every 3 ms while a vector env stepped. So every place
that may compile holds SIGINT until the compile is done (:func:`compiling`): the envs' warm-up when they are
built, and the first call of each path of a compiled loop (threads.locked)."""
from __future__ import annotations

import contextlib
import os
import threading

_LOCK = threading.RLock()
_HELD = {"depth": 0, "fd": None}


def _forget_in_child() -> None:
    # a child forked inside a held block does not hold the parent's lock (its copy of the descriptor must not release it)
    _HELD.update(depth=0, fd=None)


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_in_child)


@contextlib.contextmanager
def cache_lock():
    """One process at a time compiles (or loads from numba's disk cache) penny_env's code. numba's cache index is not
    safe for concurrent writers: two processes that save two signatures of one function (a serial and a parallel
    loop, C- and Fortran-ordered arrays) each read the index, both take the data file ``<name>.1.nbc``, and the
    index that survives maps one signature to the other's machine code; a later process that loads it crashes
    (a segmentation fault at the vector env's warm-up, seen after pytest-xdist workers and parallel jobs compiled
    side by side). An exclusive ``flock`` on ``compile.lock`` in the generated modules' folder (user-wide) is held
    around every compile point (:func:`compiling`); reentrant within a process; without fcntl (Windows) or a
    writable folder, no lock."""
    with _LOCK:
        if _HELD["depth"] == 0:
            _HELD["fd"] = _acquire()
        _HELD["depth"] += 1
        try:
            yield
        finally:
            _HELD["depth"] -= 1
            if _HELD["depth"] == 0 and _HELD["fd"] is not None:
                fd, _HELD["fd"] = _HELD["fd"], None
                _release(fd)


def _acquire():
    try:
        import fcntl

        from .generated import generated_dir
        fd = os.open(generated_dir() / "compile.lock", os.O_RDWR | os.O_CREAT, 0o666)
    except (ImportError, OSError):
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
    except OSError:
        os.close(fd)
        return None
    return fd


def _release(fd) -> None:
    import fcntl
    try:
        fcntl.flock(fd, fcntl.LOCK_UN)
    finally:
        os.close(fd)


@contextlib.contextmanager
def compiling(collect=True):
    """Around a compile (or a load from numba's cache) that a user's Ctrl-C could interrupt: SIGINT is held until the
    block ends and then raised as KeyboardInterrupt, and the compiler's garbage (llvmlite objects in reference
    cycles) is collected inside the block. A KeyboardInterrupt inside numba's compiler, or inside an llvmlite
    object's finalizer run by a later collection in the middle of a step, corrupted LLVM's state: the process
    aborted ("double free detected"). In a thread other than the main one (where Python delivers signals) the
    block only collects. A handler of the user's own (a training loop's that saves a checkpoint, say) is held
    the same way and called once, after the block, with the first held signal. collect: False, no collection (an
    import); a function, collect where it says so (a warm-up that may have found everything compiled already)."""
    import gc
    import signal
    import threading
    held = []
    main = threading.current_thread() is threading.main_thread()
    previous = signal.getsignal(signal.SIGINT) if main else None
    if main and callable(previous):  # (Python's default_int_handler or the user's; not SIG_IGN, SIG_DFL or None)
        signal.signal(signal.SIGINT, lambda signum, frame: held.append((signum, frame)))
    else:
        main = False
    try:
        with cache_lock():  # (numba's disk cache takes one writer at a time: cache_lock)
            yield
            if collect is True or (callable(collect) and collect()):
                gc.collect()
    finally:
        if main:
            signal.signal(signal.SIGINT, previous)
    if held:
        previous(*held[0])  # (default_int_handler raises KeyboardInterrupt)


def guard_llvmlite_close(classes=None) -> None:
    """llvmlite's ``close`` of an LLVM string or object frees it (a C call) and then marks it freed (Python lines); a
    KeyboardInterrupt between the two leaves it unmarked, and its ``__del__`` frees it again: the process aborts
    ("free(): double free detected in tcache 2", ``OutputString.close`` from ``__del__``, seen with a SIGINT every 3
    ms around the batch API). Both ``close`` methods are wrapped once per process so that a SIGINT arriving in them
    is held and raised again (``signal.raise_signal``) right after: the interrupt still comes, one close later.
    Main thread only (Python delivers signals there); llvmlite's own behaviour is otherwise unchanged."""
    import signal
    if classes is None:
        from llvmlite.binding import ffi
        classes = (ffi.OutputString, ffi.ObjectRef)
    for cls in classes:
        close = cls.close
        if getattr(close, "penny_env_guarded", False):
            continue

        def guarded(self, _close=close):
            if threading.current_thread() is not threading.main_thread():
                return _close(self)
            previous = signal.getsignal(signal.SIGINT)
            if not callable(previous):
                return _close(self)
            held = []
            signal.signal(signal.SIGINT, lambda signum, frame: held.append(signum))
            try:
                return _close(self)
            finally:
                signal.signal(signal.SIGINT, previous)
                if held:
                    signal.raise_signal(signal.SIGINT)
        guarded.penny_env_guarded = True
        cls.close = guarded


def load_numba() -> None:
    """numba imported (once per process) with Ctrl-C held: an import interrupted half way leaves numba's modules
    broken for the rest of the process ("module 'numba' has no attribute 'core'"). The envs and the batch API call
    it before they build anything compiled; ``import penny_env`` itself stays free of numba."""
    import sys
    if "numba.core.registry" in sys.modules:  # (imported by the user first: its finalizers get the guard all the same)
        guard_llvmlite_close()
        return
    with compiling(collect=False):
        import numba  # noqa: F401
        import numba.core.registry  # noqa: F401
        guard_llvmlite_close()


def overloads(*functions) -> int:
    """How many signatures numba has compiled (or loaded) for ``functions`` (dispatchers, and threads.locked's
    wrappers: their parallel dispatcher and the serial one where it is built): a warm-up that changed it made
    the compiler's garbage, and collects it (:func:`compiling`)."""
    total = 0
    for f in functions:
        for d in (f, getattr(f, "__wrapped__", None)):
            total += len(getattr(d, "overloads", ()) or ())
        serial = getattr(f, "serial_built", None)
        if serial is not None:
            total += sum(len(getattr(d, "overloads", ()) or ()) for d in serial())
    return total
