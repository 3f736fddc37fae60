"""penny_env's repairs of numba's and llvmlite's private internals (backends/numba_repairs.py,
interrupts.guard_llvmlite_close): in place on the numba releases they are known for (numba_repairs.KNOWN_NUMBA: a
newer numba fails here until the repairs have been checked against it), and where an internal is not as expected
(a renamed class, a classmethod become a staticmethod), numba's own behaviour with one logged line, never a bare
AttributeError about numba's internals."""
import logging
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

numba = pytest.importorskip("numba")

from penny_env.backends import numba_repairs  # noqa: E402
from penny_env.backends.interrupts import guard_llvmlite_close, load_numba  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def fresh_reports(monkeypatch, caplog):
    """An empty record of the internals reported (each is logged once per process), and the log captured."""
    monkeypatch.setattr(numba_repairs, "_REPORTED", set())
    caplog.set_level(logging.WARNING, logger="penny_env")
    return caplog


def repair_lines(caplog):
    return [r.getMessage() for r in caplog.records if "is not as penny_env's repair expects" in r.getMessage()]


@pytest.mark.fast
def test_the_installed_numba_is_one_the_repairs_are_known_for_and_every_repair_is_in_place(fresh_reports):
    from llvmlite.binding import ffi
    from numba.core import caching, compiler
    load_numba()
    low, high = numba_repairs.KNOWN_NUMBA
    assert low <= numba_repairs.numba_version() <= high, (
        f"numba {numba.__version__} is outside the releases the repairs are known for ({numba_repairs.known_range()}): "
        "check penny_env/backends/numba_repairs.py and interrupts.guard_llvmlite_close against it, then widen KNOWN_NUMBA")
    assert caching.IndexDataCacheFile.save.penny_env_locked
    assert compiler.CompileResult._rebuild.__func__.penny_env_keeps_init
    assert ffi.OutputString.close.penny_env_guarded and ffi.ObjectRef.close.penny_env_guarded
    numba_repairs.repair_numba_cache()  # (again: a no-op, nothing logged)
    guard_llvmlite_close()
    assert numba_repairs.lock_numba_cache_saves() and numba_repairs.keep_parallel_init_on_cached_loads()
    assert not repair_lines(fresh_reports)


@pytest.mark.fast
def test_a_rebuild_that_is_no_classmethod_keeps_numbas_own_with_one_line(monkeypatch, fresh_reports):
    from numba.core import compiler
    own = compiler.CompileResult._rebuild.__func__
    static = staticmethod(lambda *a, **k: own(compiler.CompileResult, *a, **k))
    monkeypatch.setattr(compiler.CompileResult, "_rebuild", static)
    assert numba_repairs.keep_parallel_init_on_cached_loads() is False
    assert numba_repairs.keep_parallel_init_on_cached_loads() is False
    assert compiler.CompileResult.__dict__["_rebuild"] is static  # (numba's own, untouched)
    lines = repair_lines(fresh_reports)
    assert len(lines) == 1 and "numba.core.compiler.CompileResult._rebuild" in lines[0], lines
    monkeypatch.delattr(compiler, "CompileResult")
    assert numba_repairs.keep_parallel_init_on_cached_loads() is False


@pytest.mark.fast
def test_a_renamed_cache_file_class_or_save_keeps_numbas_own_with_one_line(monkeypatch, fresh_reports):
    from numba.core import caching
    monkeypatch.delattr(caching, "IndexDataCacheFile")
    assert numba_repairs.lock_numba_cache_saves() is False

    class OtherLayout:
        def save(self, entry):  # (another signature: not the method the repair knows)
            return entry
    monkeypatch.setattr(caching, "IndexDataCacheFile", OtherLayout, raising=False)
    assert numba_repairs.lock_numba_cache_saves() is False
    assert OtherLayout.save(None, 3) == 3 and not hasattr(OtherLayout.save, "penny_env_locked")
    lines = repair_lines(fresh_reports)
    assert len(lines) == 1 and "IndexDataCacheFile.save" in lines[0], lines


@pytest.mark.fast
def test_llvmlite_classes_not_as_expected_keep_their_own_close_with_one_line(monkeypatch, fresh_reports):
    import types

    import llvmlite.binding
    from llvmlite.binding import ffi
    load_numba()  # (OutputString's close guarded already)
    # an llvmlite without ObjectRef, as guard_llvmlite_close imports it (llvmlite's own module keeps it: its objects
    # use it while this test runs)
    monkeypatch.setattr(llvmlite.binding, "ffi", types.SimpleNamespace(OutputString=ffi.OutputString))

    class Closer:
        close = staticmethod(lambda: "closed")  # (no plain method: left alone)
    guard_llvmlite_close()
    guard_llvmlite_close((Closer,))
    assert Closer.close() == "closed" and not hasattr(Closer.__dict__["close"], "penny_env_guarded")
    lines = repair_lines(fresh_reports)
    assert len(lines) == 2 and "llvmlite.binding.ffi.ObjectRef" in lines[0] and "Closer.close" in lines[1], lines


NUMBA_OF_ANOTHER_SHAPE = """
    import numpy as np
    import numba.core.compiler as compiler
    from llvmlite.binding import ffi
    from numba.core import caching
    own = compiler.CompileResult._rebuild.__func__
    compiler.CompileResult._rebuild = staticmethod(lambda *a, **k: own(compiler.CompileResult, *a, **k))
    own_save = caching.IndexDataCacheFile.save

    def save(self, key, data, *more):  # (another signature, the same save)
        return own_save(self, key, data)
    caching.IndexDataCacheFile.save = save
    own_close = ffi.ObjectRef.close

    def close(self, *more):  # (another signature, the same close)
        return own_close(self)
    ffi.ObjectRef.close = close
    import penny_env as pe
    env = pe.PennyVectorEnv(2, "ellipse", "reach", backend="numba")
    env.reset(seed=0)
    print("stepped", env.step(np.zeros((2, 2), np.float32))[1].shape)
"""


def test_a_numba_whose_internals_differ_builds_and_steps_the_compiled_envs():
    # every compiled env failed to build with a bare AttributeError about numba's internals
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    out = subprocess.run([sys.executable, "-c", textwrap.dedent(NUMBA_OF_ANOTHER_SHAPE)], cwd=ROOT, env=env,
                         capture_output=True, text=True, timeout=600)
    text = out.stdout + out.stderr
    assert out.returncode == 0 and "stepped (2,)" in text, text
    for internal in ("CompileResult._rebuild", "IndexDataCacheFile.save", "ObjectRef.close"):
        assert text.count(f"{internal}") >= 1, (internal, text)
    assert text.count("is not as penny_env's repair expects") == 3, text


def damage(path, how):
    data = path.read_bytes()
    path.write_bytes(data[:len(data) // 2] if how == "truncated" else bytes(range(256)) * 4)


@pytest.mark.fast
@pytest.mark.parametrize("how", ["truncated", "random"])
def test_a_damaged_cache_file_is_a_miss_with_one_warning_naming_it(tmp_path, monkeypatch, how, fresh_reports):
    # one truncated .nbi or .nbc made every later process fail with a bare _pickle.UnpicklingError
    from numba.core import caching
    load_numba()
    assert numba_repairs.recompile_damaged_cache_entries()
    monkeypatch.setattr(numba_repairs, "_DAMAGED", set())
    cache_file = caching.IndexDataCacheFile(cache_path=str(tmp_path), filename_base="f", source_stamp="stamp")
    cache_file.save(("sig", "target"), b"machine code")
    index, data = tmp_path / "f.nbi", tmp_path / "f.1.nbc"
    for damaged in (data, index):
        damage(damaged, how)
        assert cache_file.load(("sig", "target")) is None  # (a miss: numba's caller compiles)
        assert cache_file.load(("sig", "target")) is None
        cache_file.save(("sig", "target"), b"machine code")  # (what numba does after the compile: the entry rewritten)
        assert cache_file.load(("sig", "target")) == b"machine code"
    lines = [r.getMessage() for r in fresh_reports.records if "is damaged" in r.getMessage()]
    assert len(lines) == 2 and str(data) in lines[0] and str(index) in lines[1], lines
    assert "treated as missing" in lines[0] and "NUMBA_CACHE_DIR" in lines[0]


CACHED_FUNCTION = '''
import numba


@numba.njit(cache=True)
def twice(x):
    return 2.0 * x
'''


@pytest.mark.parametrize("suffix", [".nbi", ".nbc"])
def test_a_process_after_a_damaged_cache_file_recompiles_and_repairs_the_entry(tmp_path, suffix):
    (tmp_path / "loops.py").write_text(CACHED_FUNCTION)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"),
               PYTHONPATH=os.pathsep.join([str(tmp_path), str(ROOT)]))
    use = ("from penny_env.backends.interrupts import load_numba; load_numba()\n"
           "import loops; print('result', loops.twice(21.0))")

    def run():
        out = subprocess.run([sys.executable, "-c", use], cwd=tmp_path, env=env, capture_output=True, text=True,
                             timeout=300)
        return out.returncode, out.stdout + out.stderr
    assert run()[0] == 0
    (damaged,) = (tmp_path / "cache").rglob(f"*{suffix}")
    damage(damaged, "truncated")
    code, text = run()
    assert code == 0 and "result 42.0" in text and f"cache file {damaged} is damaged" in text, text
    code, text = run()  # (the entry was rewritten: loaded, no warning)
    assert code == 0 and "result 42.0" in text and "damaged" not in text, text
