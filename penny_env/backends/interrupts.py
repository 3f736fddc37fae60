"""Ctrl-C and the compiler: numba compiles a function at its first call for a signature, and llvmlite frees
its objects in finalizers that Python's cycle collector runs at any later moment. A KeyboardInterrupt inside
either corrupted LLVM's state: the process aborted ("free(): double free detected in tcache 2", llvmlite's
``ffi.close`` in ``__del__``) when a thread sent SIGINT every 3 ms while a vector env stepped. So every place
that may compile holds SIGINT until the compile is done (:func:`compiling`): the envs' warm-up when they are
built, and the first call of each path of a compiled loop (threads.locked)."""
from __future__ import annotations

import contextlib
import threading

from .numba_repairs import keep_numbas_own, plain_method, repair_numba_cache


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
    Main thread only (Python delivers signals there); llvmlite's own behaviour is otherwise unchanged. A class or a
    ``close`` that is not as expected (another llvmlite: a renamed class, a ``close`` that is no plain method) is left
    as it is, with one logged line (numba_repairs.keep_numbas_own)."""
    import signal
    if classes is None:
        try:
            from llvmlite.binding import ffi
        except ImportError:
            return
        classes = []
        for name in ("OutputString", "ObjectRef"):
            cls = getattr(ffi, name, None)
            if isinstance(cls, type):
                classes.append(cls)
            else:
                keep_numbas_own(f"llvmlite.binding.ffi.{name}", "so a Ctrl-C inside its close is not held")
    for cls in classes:
        close = plain_method(cls, "close", ("self",), "penny_env_guarded")
        if close is None:
            keep_numbas_own(f"{cls.__module__}.{cls.__qualname__}.close", "so a Ctrl-C inside it is not held")
            continue
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
        repair_numba_cache()
        return
    with compiling(collect=False):
        import numba  # noqa: F401
        import numba.core.registry  # noqa: F401
        guard_llvmlite_close()
        repair_numba_cache()


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
