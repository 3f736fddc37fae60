"""The test workers share their compiled builds (tests/shared_builds.py): a worker that needs a function another
is compiling waits for it and loads its machine code from the cache instead of compiling it again."""
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

FIRST = """
    import sys
    from tests import shared_builds
    shared_builds.install()
    import mod
    with shared_builds._held(shared_builds._lock_path(mod.f)):  # (a worker compiling f)
        print("locked", flush=True)
        sys.stdin.readline()
        mod.f(1.0)
    print(sum(mod.f.stats.cache_misses.values()), flush=True)
"""
SECOND = """
    from tests import shared_builds
    shared_builds.install()
    import mod
    print("calling", flush=True)
    mod.f(1.0)
    print(sum(mod.f.stats.cache_hits.values()), sum(mod.f.stats.cache_misses.values()), flush=True)
"""


def test_a_worker_waits_for_a_compile_of_another_and_loads_it(tmp_path):
    pytest.importorskip("numba")
    (tmp_path / "mod.py").write_text("import numba\n\n\n@numba.njit(cache=True)\ndef f(x):\n    return x + 1.0\n")
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache"), "PYTHONPATH": f"{tmp_path}{os.pathsep}{ROOT}"}

    def start(code):
        return subprocess.Popen([sys.executable, "-c", textwrap.dedent(code)], cwd=tmp_path, env=env, text=True,
                                stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    first = start(FIRST)
    assert first.stdout.readline().strip() == "locked", first.stderr.read()
    second = start(SECOND)
    try:
        assert second.stdout.readline().strip() == "calling", second.stderr.read()
        time.sleep(1.0)  # (without the lock, the second compiles f now, before the first has saved it)
        first.stdin.write("go\n")
        first.stdin.flush()
        out1, err1 = first.communicate(timeout=300)
        out2, err2 = second.communicate(timeout=300)
    finally:
        for p in (first, second):
            p.kill()
    assert first.returncode == 0 and out1.split() == ["1"], err1[-2000:]  # the first compiled f
    assert second.returncode == 0 and out2.split() == ["1", "0"], err2[-2000:]  # the second loaded it
