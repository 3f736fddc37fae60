"""The disk-cache rules of the compiled code (numba's ``cache=True``): which builds may be cached, under
which names, where, and the one line that says a first use compiles.

Every cached copy's name carries a hash of the sources it inlines (:func:`source_digest`), so no cache
location (the package's __pycache__, NUMBA_CACHE_DIR, the user-wide cache of a read-only install) can serve
stale machine code; only penny_env's own formulas, laws and tasks are cached (:func:`cacheable`), never a
user's, which a later process could replace under the same name.
"""
from __future__ import annotations

from pathlib import Path

def source_digest(modules) -> str:
    """A short hash of the sources of ``modules``: it goes into the qualified name of every cached
    compiled copy (:func:`jit_copy`), so numba's cache files are named after the sources of everything
    they inline. numba checks a cached function against its own file only, while these copies also
    freeze constants and callees of other modules (quadrature rules, table formulas, laws, the physics
    called by the environment's step); a name keyed on all those sources can never load stale machine
    code, whichever cache location numba picks (the package's __pycache__, NUMBA_CACHE_DIR, the
    user-wide cache of a read-only install)."""
    import hashlib

    h = hashlib.sha256()
    for m in modules:
        h.update(m.__name__.encode() + b"\0" + Path(m.__file__).read_bytes() + b"\0")
    return h.hexdigest()[:16]


def drop_stale_cache(folder, modules) -> None:
    """Tidy-up only (correctness comes from :func:`source_digest` in the copies' names): delete the
    machine code cached in ``folder`` (a package __pycache__) by earlier versions of ``modules``, so that
    edits do not pile up old files there. Only files whose names lack the current digest go: processes
    that start together after an edit (pytest-xdist workers, a pool of env workers) compile and load the
    current files side by side, and none deletes what another has just written. Other
    cache locations keep old files, which are never loaded (their names carry the old digest)."""
    folder = Path(folder)
    current = source_digest(modules)
    stamp = folder / "penny_env_numba.stamp"
    try:
        if stamp.exists() and stamp.read_text() == current:
            return
        for f in list(folder.glob("*.nbi")) + list(folder.glob("*.nbc")):
            if current not in f.name:
                f.unlink(missing_ok=True)
        folder.mkdir(exist_ok=True)
        stamp.write_text(current)
    except OSError:  # read-only install: numba caches elsewhere (or not at all)
        pass


_CACHE_AVAILABLE: list = []


def _probe():
    """A function for numba to pick a cache location for (disk_cache_available)."""
    return 0



def disk_cache_available() -> bool:
    """numba finds a writable place to cache this package's functions: the package's __pycache__,
    NUMBA_CACHE_DIR, or numba's user-wide cache directory (a read-only install). Where none is writable
    (no writable home either), the functions compile in each process, with one logged warning, rather
    than fail ("cannot cache function ...: no locator available")."""
    if not _CACHE_AVAILABLE:
        import numba
        try:
            numba.njit(cache=True)(_probe)  # numba picks its cache location when caching is enabled
            ok = True
        except RuntimeError:
            ok = False
            import logging
            logging.getLogger("penny_env").warning("penny_env: numba finds no writable cache directory "
                                                   "(set NUMBA_CACHE_DIR to one): "
                                                   "the compiled env step and physics compile in every process")
        _CACHE_AVAILABLE.append(ok)
    return _CACHE_AVAILABLE[0]


_ANNOUNCED: set = set()


def compiles_now(dispatcher):
    """True if numba has no machine code cached on disk for ``dispatcher`` (its first call compiles),
    False if its cache index exists (the first call loads it; it could still compile a signature the
    index lacks), None if numba's cache internals are not as expected (private API, numba 0.61-0.68)."""
    cache = getattr(dispatcher, "_cache", None)
    index = getattr(getattr(cache, "_cache_file", None), "_index_path", None)
    if cache is None:
        return None
    if index is None:
        return True if type(cache).__name__ == "NullCache" else None  # NullCache: caching is off
    return not Path(index).exists()


# What a first compile costs (docs/compile_time.md, a quiet 2-core machine: the vector env step 22-28 s, the single
# env and the batch API 4-11 s; the vector env took about 170 s on a busy 2-core machine at load 5)
COMPILE_COST = {"vector": "about 30 s on a quiet 2-core machine, 3 minutes or more on a busy or small one",
                "other": "about 10 s on a quiet 2-core machine, a minute or more on a busy or small one"}
HEARTBEAT_SECONDS = 30.0  # a "still compiling" line this often while a build runs, so that it does not look hung
POLL_SECONDS = 0.25       # how often the watcher looks at the build (a sleeping thread: no work for the build)


def announce_compile(entry: str, shape: str, kind: int, dispatcher):
    """One line on the "penny_env" logger (at WARNING, which Python prints to stderr when logging is
    not configured; silence it with logging.getLogger("penny_env").setLevel(logging.ERROR)) before
    the first build of ``entry`` for table kind ``kind`` in this process, if numba will compile it
    (:func:`compiles_now`), saying what that costs; nothing when it loads the cache. Once per (entry, kind) per
    process. While the build runs, a watcher thread (:class:`CompileWatch`, returned; None when nothing is
    announced) logs a line every HEARTBEAT_SECONDS, and one with the elapsed time when it has finished."""
    if (entry, kind) in _ANNOUNCED:
        return None
    _ANNOUNCED.add((entry, kind))
    fresh = compiles_now(dispatcher)
    if fresh is False:
        return None
    import logging
    import sys
    verb = "compiling" if fresh else "compiling (or loading from numba's cache)"
    cost = COMPILE_COST["vector" if "vector" in entry else "other"]
    what = f"the {entry} for table {shape}"
    if type(getattr(dispatcher, "_cache", None)).__name__ != "NullCache":
        first, later = "the first use of a table shape after installing", ("numba caches the machine code, later runs "
                                                                          "load it in about a second")
    elif _CACHE_AVAILABLE and not _CACHE_AVAILABLE[0]:
        first, later = "a build", ("numba finds no writable cache folder here, so every process compiles it again "
                                   "(set NUMBA_CACHE_DIR to a writable folder to cache it)")
    else:  # (a user's law, table or task: never cached, cacheable())
        first, later = "a build", ("it runs a law, table or task from outside penny_env, which is never cached: every "
                                   "process compiles it again")
    logging.getLogger("penny_env").warning(
        f"penny_env: {verb} {what}: {first} takes {cost}; a line every {HEARTBEAT_SECONDS:g} s says it is still at it; "
        f"{later}")
    watch = CompileWatch(what, dispatcher, sys._getframe(1))
    watch.start()
    return watch


def _compiled_count(dispatcher) -> int:
    """How many machine-code versions numba holds for ``dispatcher`` (0 before its first compile ends)."""
    return len(getattr(dispatcher, "overloads", ()) or ())


class CompileWatch:
    """A daemon thread that follows one build from the frame that announced it (the env's or the batch's warm-up):
    while that frame is still running on its thread, a line every HEARTBEAT_SECONDS ("still compiling ..., 60 s so
    far"); once it has returned, one line with the build's elapsed time if the dispatcher then holds machine code
    (nothing if the build failed: its exception says why). It only reads: the build runs as it would without it."""

    def __init__(self, what: str, dispatcher, frame):
        import threading
        import time
        self.what, self.dispatcher, self.frame = what, dispatcher, frame
        self.before = _compiled_count(dispatcher)
        self.ident = threading.get_ident()
        self.t0 = time.perf_counter()
        self.lines: list[str] = []
        self._thread = threading.Thread(target=self._run, name="penny_env compile watch", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def join(self, timeout=None) -> None:
        self._thread.join(timeout)

    def _running(self) -> bool:
        """The announcing frame is still on its thread's stack."""
        import sys
        f = sys._current_frames().get(self.ident)
        while f is not None:
            if f is self.frame:
                return True
            f = f.f_back
        return False

    def _log(self, text: str) -> None:
        import logging
        self.lines.append(text)
        logging.getLogger("penny_env").warning(text)

    def _run(self) -> None:
        import time
        next_line = HEARTBEAT_SECONDS
        while self._running():
            elapsed = time.perf_counter() - self.t0
            if elapsed >= next_line:
                self._log(f"penny_env: still compiling {self.what}: {elapsed:.0f} s so far (a busy or small machine "
                          "takes minutes; it is not hung)")
                next_line += HEARTBEAT_SECONDS
            time.sleep(POLL_SECONDS)
        self.frame = None  # (do not keep the caller's locals alive)
        if _compiled_count(self.dispatcher) > self.before:
            self._log(f"penny_env: compiled {self.what} in {time.perf_counter() - self.t0:.1f} s")


def cacheable(functions) -> bool:
    """Code that inlines ``functions`` (a table's formulas, the laws, a task's stages) may go to numba's disk
    cache: penny_env's own only (a user's would be frozen into cached machine code that a later process,
    with other functions under the same name, would load)."""
    return all(f is None or f.__module__.startswith("penny_env.") for f in functions)
