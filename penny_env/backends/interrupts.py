"""Ctrl-C and the compiler: numba compiles a function at its first call for a signature, and llvmlite frees
its objects in finalizers that Python's cycle collector runs at any later moment. A KeyboardInterrupt inside
either corrupted LLVM's state: the process aborted ("free(): double free detected in tcache 2", llvmlite's
``ffi.close`` in ``__del__``) when a thread sent SIGINT every 3 ms while a vector env stepped. So every place
that may compile holds SIGINT until the compile is done (:func:`compiling`): the envs' warm-up when they are
built, and the first call of each path of a compiled loop (threads.locked). A hold is bounded in time
(HOLD_LIMIT_S, IMPORT_HOLD_LIMIT_S): a block stuck in Python code gets the Ctrl-C all the same.

numba's import, which loads LLVM and OpenBLAS, needs address space: under a ``ulimit -v`` a little too small it spun
forever inside OpenBLAS's start (C code holding the GIL: no signal handler, held or not, runs there), or failed with
a bare MemoryError or "Could not find/load shared object file 'libllvmlite.so'". :func:`load_numba` refuses first,
with a MemoryError naming the limit (:func:`check_compiler_room`)."""
from __future__ import annotations

import contextlib
import threading

from .memory import address_space_left, address_space_limit
from .numba_repairs import keep_numbas_own, plain_method, repair_numba_cache

# how long a Ctrl-C may be held, at most, before it is raised inside a block that has not finished: a compile on a busy
# 2-core machine takes up to about 3 minutes, numba's import a few seconds
HOLD_LIMIT_S = 300.0
IMPORT_HOLD_LIMIT_S = 30.0
# the address space (bytes) numba's import and a first compile take beyond what the process maps before them (VmSize
# on Linux x86-64, 2 cores, numba 0.68: the import about 175 MB with OpenBLAS's buffers; with a first compile of the
# single env 510 MB, of the vector env's serial and parallel steps 620 MB; loading them from numba's cache about
# 320 MB): less room than this under an address-space limit is refused before numba is imported
COMPILER_ROOM = 640 << 20


@contextlib.contextmanager
def compiling(collect=True, hold_limit=None):
    """Around a compile (or a load from numba's cache) that a user's Ctrl-C could interrupt: SIGINT is held until the
    block ends and then raised as KeyboardInterrupt, and the compiler's garbage (llvmlite objects in reference
    cycles) is collected inside the block. A KeyboardInterrupt inside numba's compiler, or inside an llvmlite
    object's finalizer run by a later collection in the middle of a step, corrupted LLVM's state: the process
    aborted ("double free detected"). In a thread other than the main one (where Python delivers signals) the
    block only collects. A handler of the user's own (a training loop's that saves a checkpoint, say) is held
    the same way and called once, after the block, with the first held signal. collect: False, no collection (an
    import); a function, collect where it says so (a warm-up that may have found everything compiled already).

    A held signal never outlives a stuck block: ``hold_limit`` seconds (None: HOLD_LIMIT_S) after the first one came,
    if the block is still running, it is delivered inside the block (one logged line says so; numba's state may then
    be broken, as an interrupted compile leaves it). A block nested in another holds nothing itself: the outer one
    governs."""
    import gc
    import signal
    held = []
    main = threading.current_thread() is threading.main_thread()
    previous = signal.getsignal(signal.SIGINT) if main else None
    # (Python's default_int_handler or the user's; not SIG_IGN, SIG_DFL or None, nor an outer block's hold)
    main = main and callable(previous) and not getattr(previous, "penny_env_hold", False)
    limit = HOLD_LIMIT_S if hold_limit is None else float(hold_limit)
    lock = threading.Lock()
    state = {"timer": None, "overdue": False, "done": False}

    def deliver_overdue():
        """The timer's thread: the hold limit passed with the block running: the signal is simulated again in the main
        thread (``hold`` then lets it through)."""
        import _thread
        with lock:
            if state["done"]:
                return
            state["overdue"] = True
            _thread.interrupt_main(signal.SIGINT)

    def hold(signum, frame):
        if state["overdue"]:
            import logging
            logging.getLogger("penny_env").warning(
                f"penny_env: Ctrl-C was held {limit:g} s for a compile (or numba's import) that has not finished; it is "
                "raised now, inside it (numba's state in this process may be broken: start a new one to compile again)")
            held.clear()
            signal.signal(signal.SIGINT, previous)
            previous(signum, frame)  # (default_int_handler raises KeyboardInterrupt here, inside the block)
            return
        held.append((signum, frame))
        if state["timer"] is None:
            state["timer"] = threading.Timer(limit, deliver_overdue)
            state["timer"].daemon = True
            state["timer"].start()
    hold.penny_env_hold = True
    if main:
        signal.signal(signal.SIGINT, hold)
    try:
        yield
        if collect is True or (callable(collect) and collect()):
            gc.collect()
    finally:
        if main:
            with lock:
                state["done"] = True
                if state["timer"] is not None:
                    state["timer"].cancel()
                if state["overdue"]:
                    held.clear()  # (the simulated signal, pending or delivered, is the held one)
            signal.signal(signal.SIGINT, previous)
    if held:
        previous(*held[0])  # (default_int_handler raises KeyboardInterrupt)


def check_compiler_room() -> None:
    """MemoryError naming the address-space limit (``ulimit -v``, RLIMIT_AS) where it leaves this process less than
    COMPILER_ROOM to import numba and compile (module docstring); nothing without a limit. Other memory (MemAvailable,
    a cgroup's limit) is physical, which numba's reservations of address space do not take."""
    room = address_space_left()
    if room is not None and room < COMPILER_ROOM:
        mib = 1 << 20
        limit = address_space_limit()
        raise MemoryError(
            f"penny_env: the address-space limit (RLIMIT_AS, ulimit -v {limit // 1024} KiB) leaves this process "
            f"{room / mib:.0f} MiB, less than the {COMPILER_ROOM / mib:.0f} MiB the compiled backend needs to import "
            f"numba and compile the env step: raise the limit (ulimit -v {(limit + COMPILER_ROOM - room) // 1024 + 1}"
            " or more), or use backend='python'")


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
    """numba imported (once per process) with Ctrl-C held (for IMPORT_HOLD_LIMIT_S at most): an import interrupted
    half way leaves numba's modules broken for the rest of the process ("module 'numba' has no attribute 'core'").
    First, a MemoryError naming the address-space limit where it leaves too little room (:func:`check_compiler_room`).
    The envs, the batch API and the registration of a law or a table call it before they build anything compiled;
    ``import penny_env`` itself stays free of numba."""
    import sys
    if "numba.core.registry" in sys.modules:  # (imported by the user first: its finalizers get the guard all the same)
        guard_llvmlite_close()
        repair_numba_cache()
        return
    check_compiler_room()
    with compiling(collect=False, hold_limit=IMPORT_HOLD_LIMIT_S):
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
