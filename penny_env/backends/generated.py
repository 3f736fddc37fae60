"""Generated source lives in real files, so that tracebacks, profilers and numba's disk cache point at
real lines: the CPU loops with their bodies in place (builder.hoisted_source), the CUDA kernels' two-line
glue (builder.Builder.kernel), the law dispatch and the constants' unpacking (packing.py).

A generated module is named after what it holds and a hash of its source, and written once into the first
writable folder of: $PENNY_ENV_GENERATED_DIR, the user's cache ($XDG_CACHE_HOME or ~/.cache, then
penny_env/generated), the system's temporary folder. Never into the package's own folder: an installed
package's folder belongs to pip (``pip uninstall`` would leave generated files behind), a checkout's to git. A
module is never rewritten with other content (its name changes with it), so its timestamp, which numba's cache
index checks, stays put.
"""
from __future__ import annotations

import hashlib
import os
import tempfile
from pathlib import Path

_DIR: list = []


def _writable(folder: Path) -> bool:
    try:
        folder.mkdir(parents=True, exist_ok=True)
        probe = folder / f".probe_{os.getpid()}"
        probe.write_text("")
        probe.unlink()
        return True
    except OSError:
        return False


def generated_dir() -> Path:
    """The folder of the generated modules (module docstring), chosen once per process."""
    if not _DIR:
        env = os.environ.get("PENNY_ENV_GENERATED_DIR")
        cache = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
        uid = os.getuid() if hasattr(os, "getuid") else 0
        candidates = ([Path(env)] if env else []) + [cache / "penny_env" / "generated",
                                                     Path(tempfile.gettempdir()) / f"penny_env_generated_{uid}"]
        for folder in candidates:
            if _writable(folder):
                _DIR.append(folder)
                break
        else:
            raise OSError(f"penny_env: no writable folder for its generated source among {[str(c) for c in candidates]}; "
                          "set PENNY_ENV_GENERATED_DIR to one")
    return _DIR[0]


def source_file(name: str, source: str) -> Path:
    """The file holding ``source``, named ``<name>_<hash>.py``, written now if it is not there yet."""
    digest = hashlib.sha256(source.encode()).hexdigest()[:16]
    path = generated_dir() / f"{name}_{digest}.py"
    if not path.exists() or path.read_text() != source:
        tmp = path.with_suffix(f".tmp{os.getpid()}")
        tmp.write_text(source)
        os.replace(tmp, path)  # (atomic: a concurrent reader sees the whole file or none)
    return path


def define(name: str, source: str, namespace: dict, module: str = __name__) -> dict:
    """Execute ``source`` from its file (:func:`source_file`) with ``namespace`` as its globals; returns the
    namespace, which now holds what the source defines. ``module``: the functions' __module__ (the module
    that generates them: numba's cache needs a real module's name)."""
    namespace.setdefault("__name__", module)
    path = source_file(name, source)
    exec(compile(source, str(path), "exec"), namespace)  # noqa: S102 (our own generated source, from its file)
    return namespace
