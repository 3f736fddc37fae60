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
    current files side by side, and none deletes what another has just written (a segmentation fault
    was seen once while loading after such concurrent deletions; its cause is not pinned down). Other
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


def announce_compile(entry: str, shape: str, kind: int, dispatcher) -> None:
    """One line on the "penny_env" logger (at WARNING, which Python prints to stderr when logging is
    not configured; silence it with logging.getLogger("penny_env").setLevel(logging.ERROR)) before
    the first build of ``entry`` for table kind ``kind`` in this process, if numba will compile it
    (:func:`compiles_now`); nothing when it loads the cache. Once per (entry, kind) per process."""
    if (entry, kind) in _ANNOUNCED:
        return
    _ANNOUNCED.add((entry, kind))
    fresh = compiles_now(dispatcher)
    if fresh is False:
        return
    import logging
    verb = "compiling" if fresh else "compiling (or loading from numba's cache)"
    # (docs/compile_time.md, 2 cores: the vector env step 22-28 s, the single env and the batch API 4-11 s)
    cost = "about 30 s" if "vector" in entry else "about 10 s"
    logging.getLogger("penny_env").warning(
        f"penny_env: {verb} the {entry} for table {shape}: the first use of a table shape after installing takes "
        f"{cost} (minutes on a slow or busy machine); numba caches the machine code, later runs load it "
        "in about a second")


def cacheable(functions) -> bool:
    """Code that inlines ``functions`` (a table's formulas, the laws, a task's stages) may go to numba's disk
    cache: penny_env's own only (a user's would be frozen into cached machine code that a later process,
    with other functions under the same name, would load)."""
    return all(f is None or f.__module__.startswith("penny_env.") for f in functions)
