"""The compile notice (backends/cache.py's announce_compile) and the quick modes of the commands that
measure first-use compile time and the vector env beside a busy process."""
import re
import logging

import pytest
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

numba = pytest.importorskip("numba")


def test_the_compile_notice_is_one_line_once_and_only_when_numba_compiles(caplog):
    from penny_env.backends import cache as compiled

    def f(x):
        return x + 1

    uncached = numba.njit(f)  # caching off: its first call compiles
    assert compiled.compiles_now(uncached) is True
    compiled._ANNOUNCED.discard(("test entry", 99))
    with caplog.at_level(logging.WARNING, logger="penny_env"):
        compiled.announce_compile("test entry", "Shape", 99, uncached)
        compiled.announce_compile("test entry", "Shape", 99, uncached)  # once per (entry, kind) per process
    lines = [r.getMessage() for r in caplog.records if r.name == "penny_env"]
    assert len(lines) == 1 and lines[0].startswith("penny_env: compiling the test entry for table Shape")


@pytest.mark.parametrize("writable, says", [
    (False, r"numba finds no writable cache folder here, so every process compiles it again \(set NUMBA_CACHE_DIR"),
    (True, r"it runs a law, table or task from outside penny_env, which is never cached: every process compiles it")])
def test_the_compile_notice_promises_a_cached_load_only_where_numba_caches(caplog, monkeypatch, writable, says):
    # with no writable cache folder the line still said "numba caches the machine code, later runs load it in about a
    # second", and every process compiled again
    from penny_env.backends import cache as compiled
    monkeypatch.setattr(compiled, "_CACHE_AVAILABLE", [writable])
    monkeypatch.setattr(compiled, "_ANNOUNCED", set())
    with caplog.at_level(logging.WARNING, logger="penny_env"):
        compiled.announce_compile("uncached entry", "Shape", 95, numba.njit(lambda x: x))  # (caching off)
        compiled.announce_compile("cached entry", "Shape", 95, numba.njit(cache=True)(compiled._probe))
    (uncached, cached) = [r.getMessage() for r in caplog.records if r.name == "penny_env"]
    assert re.search(says, uncached) and "later runs load it" not in uncached, uncached
    assert "numba caches the machine code, later runs load it in about a second" in cached, cached


def test_no_notice_when_the_machine_code_is_cached(caplog, tmp_path, monkeypatch):
    from penny_env.backends import cache as compiled

    monkeypatch.setattr(numba.config, "CACHE_DIR", str(tmp_path))  # a fresh cache for this test's function
    cached = numba.njit(cache=True)(compiled._probe)
    assert compiled.compiles_now(cached) is True  # nothing cached yet
    assert numba.njit(cache=True)(compiled._probe)() == 0  # compiles and saves
    again = numba.njit(cache=True)(compiled._probe)
    assert compiled.compiles_now(again) is False
    compiled._ANNOUNCED.discard(("cached entry", 98))
    with caplog.at_level(logging.WARNING, logger="penny_env"):
        compiled.announce_compile("cached entry", "Shape", 98, again)
    assert not [r for r in caplog.records if r.name == "penny_env"]


@pytest.mark.slow
def test_compile_time_quick(capsys, reports_untouched):
    from devtools import compile_time
    compile_time.main(["--quick"])
    out = capsys.readouterr().out
    assert "| Plane | single |" in out and "Total cold CPU seconds per shape" in out
    row = next(line for line in out.splitlines() if line.startswith("| Plane | single |"))
    cold_cpu, warm_cpu = float(row.split("|")[4]), float(row.split("|")[6])
    assert cold_cpu > warm_cpu > 0  # the second process loaded what the first compiled


@pytest.mark.slow
def test_contention_quick(capsys, reports_untouched):
    from devtools import contention
    contention.main(["--quick"])
    out = capsys.readouterr().out
    rows = [line for line in out.splitlines() if line.startswith("| penny_env default |") or line.startswith("| 1 thread |")]
    assert len(rows) == 2, out
    assert re.search(r"\| penny_env default \| (omp|tbb|workqueue|serial) \|", out)  # numba's default choice of layer
    for row in rows:
        quiet, busy = float(row.split("|")[4]), float(row.split("|")[5])
        assert quiet > 0 and busy > 0


def test_a_build_says_it_is_still_at_it_and_how_long_it_took(caplog, monkeypatch):
    # issue 40, item 13: on a busy machine the first build took about 170 s with one line at its start: it looked hung
    import time
    from penny_env.backends import cache as compiled
    monkeypatch.setattr(compiled, "HEARTBEAT_SECONDS", 0.05)
    monkeypatch.setattr(compiled, "POLL_SECONDS", 0.005)

    def warm_up(f, fail=False):
        watch = compiled.announce_compile("watched vector env step", "Shape", 97 if not fail else 96, f)
        for _ in range(200_000):  # wait (by events, not by a clock) for the first "still compiling" line
            if watch.lines:
                break
            time.sleep(0.001)
        if fail:
            raise RuntimeError("numba could not compile")
        f(1)
        return watch

    for key in (("watched vector env step", 97), ("watched vector env step", 96)):
        compiled._ANNOUNCED.discard(key)
    with caplog.at_level(logging.WARNING, logger="penny_env"):
        watch = warm_up(numba.njit(lambda x: x + 2))
        watch.join()
        failing = numba.njit(lambda x: x + 3)
        with pytest.raises(RuntimeError):
            warm_up(failing, fail=True)
    lines = [r.getMessage() for r in caplog.records if r.name == "penny_env"]
    first = lines[0]
    assert first.startswith("penny_env: compiling the watched vector env step for table Shape") and \
        "3 minutes or more on a busy or small one" in first
    assert watch.lines[0].startswith("penny_env: still compiling the watched vector env step for table Shape: ")
    assert "it is not hung" in watch.lines[0]
    assert re.match(r"penny_env: compiled the watched vector env step for table Shape in [0-9.]+ s$", watch.lines[-1])
    assert sum(line.startswith("penny_env: compiled ") for line in lines) == 1  # (the failed build says nothing more)


def test_cuda_kernels_quick_compiles_the_planes_kernels_and_refuses_docs(tmp_path, capsys):
    """`python -m devtools.cuda_kernels --quick` (the README says every command takes --quick): two small kernels of
    the open plane at one compute capability, registers from ptxas where it is installed, and never into docs/."""
    pytest.importorskip("numba_cuda")
    from devtools import cuda_kernels
    out = tmp_path / "kernels.md"
    assert cuda_kernels.main(["--quick", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "plane" in printed and "observe_rows" in printed and "ellipse" not in printed
    if cuda_kernels.find_ptxas():
        assert "| sm_90 | plane | observe_rows |" in out.read_text()
    with pytest.raises(SystemExit):
        cuda_kernels.main(["--quick", "--out", str(ROOT / "docs" / "cuda_kernels.md")])
