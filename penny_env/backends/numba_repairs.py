"""Three defects of numba's disk cache (numba 0.61-0.68), repaired once per process by :func:`repair_numba_cache`
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
3. Damaged cache files (:func:`recompile_damaged_cache_entries`). numba unpickles its index (``.nbi``) and data
   (``.nbc``) files as they are: one truncated file (a half-written copy of ~/.cache, a disk error) made every
   later process that loads that function fail with a bare ``_pickle.UnpicklingError`` naming neither the file
   nor the remedy. A file that does not unpickle is now a miss, as a missing file is for numba: the function
   compiles again, numba's next save rewrites the entry, and one warning names the file.

Each repair wraps internals as numba 0.61 to 0.68 (:data:`KNOWN_NUMBA`, the versions tests/backends/
test_numba_repairs.py holds them to) define them. Before it wraps one, it checks that the internal is there and of
the kind it expects (a class, a plain method with its parameters, a classmethod); where it is not (another numba),
it leaves numba as it is and logs one line naming the internal: numba then runs as it would without penny_env.
"""
from __future__ import annotations

import inspect
import logging
import os
import types

KNOWN_NUMBA = ((0, 61), (0, 68))  # the numba releases (major, minor) the repairs are known for, both included
_REPORTED: set = set()  # the internals found otherwise (logged once per process each)
_DAMAGED: set = set()   # the damaged cache files reported (once per process each)


def numba_version() -> tuple:
    """(major, minor) of the installed numba (its ``__version__``), without importing it."""
    from importlib.metadata import PackageNotFoundError, version
    try:
        parts = version("numba").split(".")[:2]
        return tuple(int("".join(ch for ch in p if ch.isdigit()) or 0) for p in parts)
    except (PackageNotFoundError, ValueError):
        return ()


def known_range() -> str:
    (a, b), (c, d) = KNOWN_NUMBA
    return f"{a}.{b} to {c}.{d}"


def keep_numbas_own(internal: str, consequence: str) -> bool:
    """One logged line (once per process and internal) saying that ``internal`` is not as a repair expects, so
    numba's own behaviour is kept, and what that means (``consequence``). Returns False (nothing was wrapped)."""
    if internal not in _REPORTED:
        _REPORTED.add(internal)
        found = ".".join(str(v) for v in numba_version()) or "unknown"
        logging.getLogger("penny_env").warning(
            f"penny_env: {internal} is not as penny_env's repair expects (numba {found}; the repairs are known for "
            f"numba {known_range()}): numba's own behaviour is kept, {consequence}")
    return False


def plain_method(cls, name: str, params: tuple, wrapped: str):
    """cls's attribute ``name`` where it is a plain function taking exactly ``params``, or where it is penny_env's
    wrapper of one already (it has the attribute ``wrapped``), else None."""
    f = inspect.getattr_static(cls, name, None) if isinstance(cls, type) else None
    if not isinstance(f, types.FunctionType):
        return None
    if getattr(f, wrapped, False):
        return f
    try:
        return f if tuple(inspect.signature(f).parameters) == params else None
    except (TypeError, ValueError):
        return None


def _index_file_class():
    try:
        from numba.core import caching
    except ImportError:
        return None
    return getattr(caching, "IndexDataCacheFile", None)


def lock_numba_cache_saves() -> bool:
    """numba's ``IndexDataCacheFile.save`` wrapped once per process so that it holds an exclusive ``flock`` on
    ``<index>.lock`` while it reads the index, picks the data file's name and writes both (milliseconds; a compile
    itself is not held): saves from several processes (parallel jobs, test workers) take turns (module docstring, 1).
    Without fcntl (Windows) or a writable lock file, numba's own save. True where the repair is in place."""
    cls = _index_file_class()
    save = plain_method(cls, "save", ("self", "key", "data"), "penny_env_locked")
    if save is None:
        return keep_numbas_own("numba.core.caching.IndexDataCacheFile.save",
                               "so concurrent cache saves of one function from several processes are not serialised")
    if getattr(save, "penny_env_locked", False):
        return True

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
    cls.save = locked_save
    return True


def keep_parallel_init_on_cached_loads() -> bool:
    """numba's ``CompileResult._rebuild`` (a load from the disk cache) wrapped once per process so that the loaded
    machine code keeps its ``reload_init`` (the launch of numba's threads, for a parallel function): the callers that
    numba then compiles against it inherit it, as they do from freshly compiled code (module docstring, 2). Where
    numba's internals are not as expected (no such class, or ``_rebuild`` not a classmethod), nothing is changed
    (threads.locked still launches the threads). True where the repair is in place."""
    try:
        from numba.core import compiler
    except ImportError:
        return False
    cls = getattr(compiler, "CompileResult", None)
    rebuild = inspect.getattr_static(cls, "_rebuild", None) if isinstance(cls, type) else None
    if not (isinstance(rebuild, classmethod) and isinstance(rebuild.__func__, types.FunctionType)):
        return keep_numbas_own("numba.core.compiler.CompileResult._rebuild (a classmethod)",
                               "so callers compiled against a cached parallel loop do not record the launch of numba's "
                               "threads (penny_env's own loops launch them before their first call)")
    rebuild = rebuild.__func__
    if getattr(rebuild, "penny_env_keeps_init", False):
        return True

    def rebuild_keeping_init(klass, *args, **kwargs):
        result = rebuild(klass, *args, **kwargs)
        kept = getattr(getattr(result, "library", None), "_reload_init", None)
        loaded = getattr(result, "reload_init", None)
        if isinstance(kept, set) and loaded:
            kept.update(loaded)
        return result
    rebuild_keeping_init.penny_env_keeps_init = True
    cls._rebuild = classmethod(rebuild_keeping_init)
    return True


def report_damaged_file(path, exc) -> None:
    """The warning of a damaged cache file (module docstring, 3), once per process and file."""
    if path in _DAMAGED:
        return
    _DAMAGED.add(path)
    logging.getLogger("penny_env").warning(
        f"penny_env: numba's cache file {path} is damaged ({type(exc).__name__}: {str(exc)[:200]}); it is treated as "
        "missing: the function compiles again and numba rewrites the entry (if this repeats, delete the file or set "
        "NUMBA_CACHE_DIR to another folder)")


def recompile_damaged_cache_entries() -> bool:
    """numba's ``IndexDataCacheFile._load_index`` and ``_load_data`` wrapped once per process so that a file that
    does not unpickle (truncated, overwritten with other bytes) is a miss with one warning naming it (module
    docstring, 3): an index read as empty, a data file as absent (numba's ``load`` then returns None, and its
    caller compiles). An OSError (or a MemoryError) stays numba's to handle, as before. A data file whose bytes
    still unpickle into something else is beyond this (pickle rejects truncated and random bytes). True where the
    repair is in place."""
    cls = _index_file_class()
    load_index = plain_method(cls, "_load_index", ("self",), "penny_env_damage_is_a_miss")
    load_data = plain_method(cls, "_load_data", ("self", "name"), "penny_env_damage_is_a_miss")
    if load_index is None or load_data is None:
        return keep_numbas_own("numba.core.caching.IndexDataCacheFile._load_index / _load_data",
                               "so a damaged cache file fails with numba's own error (then delete numba's cache "
                               "folder, or set NUMBA_CACHE_DIR to another one)")
    if getattr(load_index, "penny_env_damage_is_a_miss", False):
        return True

    def index_or_empty(self, _load=load_index):
        try:
            return _load(self)
        except (OSError, MemoryError):
            raise
        except Exception as exc:  # noqa: BLE001 (unpickling damaged bytes raises any kind: all mean "damaged")
            report_damaged_file(getattr(self, "_index_path", "(an index file)"), exc)
            return {}

    def data_or_none(self, name, _load=load_data):
        try:
            return _load(self, name)
        except (OSError, MemoryError):
            raise
        except Exception as exc:  # noqa: BLE001
            report_damaged_file(os.path.join(str(getattr(self, "_cache_path", "")), str(name)), exc)
            return None
    index_or_empty.penny_env_damage_is_a_miss = data_or_none.penny_env_damage_is_a_miss = True
    cls._load_index = index_or_empty
    cls._load_data = data_or_none
    return True


def repair_numba_cache() -> None:
    """The three repairs (module docstring), once per process."""
    lock_numba_cache_saves()
    keep_parallel_init_on_cached_loads()
    recompile_damaged_cache_entries()
