"""Compiled builds shared between the test workers (pytest-xdist): one worker compiles a function, the others load it.

The workers of ``pytest -n 2`` share numba's disk cache (the checkout's __pycache__ folders), but nothing stops two
of them compiling the same function at the same time: both miss the cache, both compile, both save. In a fresh
clone that doubles the suite's first compiles, and the workers start on the same modules. Here numba's
``Dispatcher.compile`` takes an exclusive ``flock`` on a lock file beside the function's cache index first (one
per cached function and cache folder), then runs as it is: a worker that waited finds the other's machine code in
the cache and loads it. A function without a disk cache, or compiled in another cache folder (a test's own
NUMBA_CACHE_DIR), never waits for the others. Only the test workers do this (conftest.py); the package itself
never holds a lock around a compile (backends/interrupts.py: a forked child must not wait on its parent's).

In-process, numba's own compiler lock is taken before the file lock, so two threads of one worker never hold
file locks in opposite orders; a compile nested in another (a callee typed while its caller compiles) takes the
callee's lock inside the caller's, in the order of the call graph, the same in every worker.
"""
from __future__ import annotations

import contextlib
import os

_HELD: dict = {}  # lock path -> [file descriptor, depth] (re-entrant within this process)


def _lock_path(dispatcher):
    """The lock file of a dispatcher's disk cache (its index file's path + ".compile.lock"), or None."""
    cache_file = getattr(getattr(dispatcher, "_cache", None), "_cache_file", None)
    index = getattr(cache_file, "_index_path", None)
    return None if index is None else f"{index}.compile.lock"


@contextlib.contextmanager
def _held(path):
    import fcntl
    entry = _HELD.get(path)
    if entry is not None:  # (a nested compile of the same function in this process: already held)
        entry[1] += 1
        try:
            yield
        finally:
            entry[1] -= 1
        return
    try:
        os.makedirs(os.path.dirname(path), exist_ok=True)
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError:  # (a cache folder this process may read but not write: nothing to share)
        yield
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        _HELD[path] = [fd, 1]
        try:
            yield
        finally:
            del _HELD[path]
    finally:
        os.close(fd)  # (closing releases the flock)


def install() -> bool:
    """Wrap numba's Dispatcher.compile (once per process); False where numba is not installed."""
    try:
        from numba.core import dispatcher, sigutils
        from numba.core.compiler_lock import global_compiler_lock
    except ImportError:
        return False
    compile_ = dispatcher.Dispatcher.compile
    if getattr(compile_, "shared_between_workers", False):
        return True

    def compile(self, sig):
        path = _lock_path(self)
        # (typing a caller asks its callees for signatures they already hold: no lock for those)
        if path is None or self.overloads.get(tuple(sigutils.normalize_signature(sig)[0])) is not None:
            return compile_(self, sig)
        with global_compiler_lock, _held(path):
            return compile_(self, sig)

    compile.shared_between_workers = True
    compile.__wrapped__ = compile_
    dispatcher.Dispatcher.compile = compile
    return True
