"""How much memory this process may still allocate: the least of what the machine has free and what the limits set
on this process allow (under ``ulimit -v`` or a container's memory limit, MemAvailable alone said a
PennyVectorEnv of 5e6 envs fits, and numpy's MemoryError came 137 s later).

* the machine: MemAvailable of /proc/meminfo (Linux), else the free physical pages (os.sysconf);
* the address-space limit (``ulimit -v``, RLIMIT_AS of :mod:`resource`), less what the process maps already
  (VmSize of /proc/self/status);
* the cgroup's limit, less its usage: cgroup v2 ``memory.max`` and ``memory.current``, v1
  ``memory.limit_in_bytes`` and ``memory.usage_in_bytes``, for the process's own cgroup (/proc/self/cgroup) and
  every cgroup above it.

A source that cannot be read (another OS, no cgroup mounted, "max") sets no bound. ``root`` lets the tests stand
up a fake /proc and /sys. The envs read it for their arrays (envs/limits.py), the backends for numba's import and
compiles (interrupts.check_compiler_room), so it lives with the backends, the lower layer.
"""
from __future__ import annotations

import os
from pathlib import Path

NO_LIMIT = 1 << 60  # cgroup v1 writes "no limit" as a page-rounded 2**63 - 1: anything above this is none


def _read_int(path: Path) -> int | None:
    try:
        text = path.read_text().strip()
    except (OSError, UnicodeDecodeError):
        return None
    if text == "max":
        return None
    try:
        value = int(text)
    except ValueError:
        return None
    return value if 0 <= value < NO_LIMIT else None


def machine_available(root: Path) -> int | None:
    """MemAvailable (bytes), else the free physical pages, else None."""
    try:
        with open(root / "proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    if root != Path("/"):
        return None
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def address_space_limit() -> int | None:
    """RLIMIT_AS's soft limit (bytes), or None without one."""
    try:
        import resource
        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    except (ImportError, AttributeError, OSError, ValueError):
        return None
    return None if soft == resource.RLIM_INFINITY or soft < 0 else soft


def address_space_left(root: Path = Path("/")) -> int | None:
    """RLIMIT_AS's soft limit less the process's mapped size (VmSize), or None without a limit."""
    soft = address_space_limit()
    if soft is None:
        return None
    mapped = 0
    try:
        with open(root / "proc/self/status") as f:
            for line in f:
                if line.startswith("VmSize:"):
                    mapped = int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return max(0, soft - mapped)


def _cgroup_dirs(root: Path):
    """(directory, limit file, usage file) of the process's cgroups and their ancestors, v2 then v1."""
    paths = {}
    try:
        for line in (root / "proc/self/cgroup").read_text().splitlines():
            parts = line.split(":", 2)
            if len(parts) == 3:
                hierarchy, controllers, path = parts
                if hierarchy == "0" and controllers == "":
                    paths["v2"] = path
                elif "memory" in controllers.split(","):
                    paths["v1"] = path
    except (OSError, UnicodeDecodeError):
        pass
    for version, mount, limit, usage in (("v2", "sys/fs/cgroup", "memory.max", "memory.current"),
                                         ("v1", "sys/fs/cgroup/memory", "memory.limit_in_bytes",
                                          "memory.usage_in_bytes")):
        base = root / mount
        rel = Path(paths.get(version, "/").lstrip("/"))
        seen = set()
        # the process's cgroup and its ancestors (inside a container the mount may be the cgroup itself)
        for parent in [rel, *rel.parents]:
            d = base / parent
            if d not in seen:
                seen.add(d)
                yield d, limit, usage


def cgroup_left(root: Path) -> int | None:
    """The least (limit - usage) over the process's cgroups that set a memory limit, or None."""
    left = None
    for d, limit_file, usage_file in _cgroup_dirs(root):
        limit = _read_int(d / limit_file)
        if limit is None:
            continue
        usage = _read_int(d / usage_file) or 0
        room = max(0, limit - usage)
        left = room if left is None else min(left, room)
    return left


def memory_left(root="/") -> tuple[int | None, str]:
    """(bytes this process may still allocate, the source that bounds it), (None, "") when none is known."""
    root = Path(root)
    best, source = None, ""
    for name, value in (("MemAvailable", machine_available(root)),
                        ("the address-space limit RLIMIT_AS, ulimit -v", address_space_left(root)),
                        ("the cgroup's memory limit", cgroup_left(root))):
        if value is not None and (best is None or value < best):
            best, source = value, name
    return best, source
