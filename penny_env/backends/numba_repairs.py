"""Two defects of numba's disk cache (numba 0.61-0.68), repaired once per process by :func:`repair_numba_cache`
(called by interrupts.load_numba before penny_env compiles or loads anything), each wrapping one private numba
method and otherwise leaving numba as it is.

1. Concurrent saves (:func:`lock_numba_cache_saves`). numba's cache index is not safe for concurrent writers:
   two processes that save two signatures of one function each read the index, both take the data file
   ``<name>.1.nbc``, and the index that survives maps one signature to the other's machine code.
2. Parallel loops called from cached functions (:func:`keep_parallel_init_on_cached_loads`; numba issues
   #8578 and #9938, PR #9950 open). A parallel (prange) function records that its threads must be launched
   before it runs, and numba launches them when it loads that function from the cache. A function that
   *calls* a parallel one inherits the record when it is compiled, from the callee's machine code, but machine
   code loaded from the cache has lost it: a caller compiled in a process that loaded its parallel callee
   from the cache is cached without it, and a later process that loads that caller calls the parallel loop
   with no threads launched: a call through a null pointer (the vector env's ``step_envs_packed`` crashed in
   its warm-up, in test_parallel's subprocesses, after another process had compiled it that way). The
   repair gives a cached load's machine code its record back, so the callers compiled from it keep it; the
   callers cached before the repair are covered by threads.locked, which launches numba's threads before a
   parallel loop's first call.
"""
from __future__ import annotations

import os


def lock_numba_cache_saves() -> None:
    """numba's ``IndexDataCacheFile.save`` wrapped once per process so that it holds an exclusive ``flock`` on
    ``<index>.lock`` while it reads the index, picks the data file's name and writes both (milliseconds; a compile
    itself is not held): saves from several processes (parallel jobs, test workers) take turns (module docstring, 1).
    Without fcntl (Windows) or a writable lock file, numba's own save."""
    from numba.core import caching
    save = caching.IndexDataCacheFile.save
    if getattr(save, "penny_env_locked", False):
        return

    def locked_save(self, key, data, _save=save):
        index = getattr(self, "_index_path", None)  # (numba's private layout, 0.61-0.68; else its own save)
        try:
            import fcntl
            fd = os.open(str(index) + ".lock", os.O_RDWR | os.O_CREAT, 0o666) if index else None
        except (ImportError, OSError):
            fd = None
        if fd is None:
            return _save(self, key, data)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
            return _save(self, key, data)
        finally:
            os.close(fd)  # (closing the descriptor releases the lock)
    locked_save.penny_env_locked = True
    caching.IndexDataCacheFile.save = locked_save


def keep_parallel_init_on_cached_loads() -> None:
    """numba's ``CompileResult._rebuild`` (a load from the disk cache) wrapped once per process so that the loaded
    machine code keeps its ``reload_init`` (the launch of numba's threads, for a parallel function): the callers that
    numba then compiles against it inherit it, as they do from freshly compiled code (module docstring, 2). Where
    numba's internals are not as expected, nothing is changed (threads.locked still launches the threads)."""
    from numba.core import compiler
    cls = getattr(compiler, "CompileResult", None)
    rebuild = getattr(cls, "_rebuild", None)
    if rebuild is None or getattr(rebuild, "penny_env_keeps_init", False):
        return
    rebuild = rebuild.__func__  # (a classmethod)

    def rebuild_keeping_init(klass, *args, **kwargs):
        result = rebuild(klass, *args, **kwargs)
        kept = getattr(getattr(result, "library", None), "_reload_init", None)
        if isinstance(kept, set) and result.reload_init:
            kept.update(result.reload_init)
        return result
    rebuild_keeping_init.penny_env_keeps_init = True
    cls._rebuild = classmethod(rebuild_keeping_init)


def repair_numba_cache() -> None:
    """Both repairs (module docstring), once per process."""
    lock_numba_cache_saves()
    keep_parallel_init_on_cached_loads()
