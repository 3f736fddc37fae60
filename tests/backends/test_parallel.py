"""The compiled parallel loops survive what deployments do: fork() after a parallel call, two Python
threads stepping two vector envs (and batch calls), and a user's own threading layer choice
(backends/threads.py). Each case runs in a subprocess, so an abort fails the test, not the suite."""
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

pytest.importorskip("numba")
ROOT = Path(__file__).resolve().parents[2]


def run_script(code, **env):
    """(returncode, stdout + stderr) of ``code`` in a new interpreter on this checkout."""
    full = {k: v for k, v in os.environ.items() if k not in ("NUMBA_THREADING_LAYER", "OMP_WAIT_POLICY")}
    full.update(env, PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], cwd=ROOT, env=full, capture_output=True,
                         text=True, timeout=600)
    return out.returncode, out.stdout + out.stderr


FORK = """
    import os
    import numpy as np
    import gymnasium as gym
    import penny_env, penny_env.batch as pb
    from penny_env.backends.threads import SERIAL_BELOW
    N = SERIAL_BELOW  # enough pennies for the parallel loops (fewer run on the calling thread)

    def use(seed):
        v = gym.make_vec("PennyReach-Plane-v0", num_envs=N)
        v.reset(seed=seed)
        for _ in range(5):
            v.step(np.full((N, 2), 0.5, dtype=np.float32))
        S = np.zeros((N, 6)); S[:, 4] = 8.0; S[:, 3] = np.linspace(0, 6, N)
        res = pb.simulate(S, table={"kind": "circle", "radius": 0.2}, law="elastic", t_final=0.3)
        assert res.final_states.shape == (N, 6)
        return np.concatenate([v.step(np.full((N, 2), 0.5, dtype=np.float32))[0].ravel(), res.final_states.ravel()])

    use(0)  # the parent has run the parallel loops (vector env and batch)
    import numba
    from penny_env.backends import threads as parallel
    print("parent layer", numba.threading_layer())
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:
        try:
            obs = use(1)
            os.write(w, (f"{parallel.serial_now()} " + obs.tobytes().hex()).encode())
        finally:
            os._exit(0)
    os.close(w)
    chunks = []  # read to the end before waiting: the child blocks while the pipe is full
    while chunk := os.read(r, 1 << 16):
        chunks.append(chunk)
    _, status = os.waitpid(pid, 0)
    serial, hexobs = b"".join(chunks).decode().split()
    print("child exit", os.waitstatus_to_exitcode(status), "serial", serial)
    print("child equals parent", bytes.fromhex(hexobs) == use(1).tobytes())
"""


@pytest.mark.skipif(not hasattr(os, "fork"), reason="no fork() on this platform")
def test_a_forked_child_builds_and_steps_a_vector_env_after_the_parent_ran_one():
    # under GNU OpenMP (numba's default layer where it loads) the child runs penny_env's loops serially,
    # bitwise the same as the parent's parallel ones
    code, out = run_script(FORK)
    assert code == 0 and "child exit 0" in out and "child equals parent True" in out, out
    if "parent layer omp" in out:
        assert "serial True" in out, out


THREADS = """
    import threading
    import numpy as np
    import gymnasium as gym
    import numba
    import penny_env, penny_env.batch as pb

    from penny_env.backends.threads import SERIAL_BELOW
    N = SERIAL_BELOW  # enough pennies for the parallel loops (fewer run on the calling thread)
    envs = [gym.make_vec("PennyReach-Plane-v0", num_envs=N) for _ in range(2)]
    errors = []

    def run(v, seed):
        try:
            v.reset(seed=seed)
            a = np.full((N, 2), 0.3, dtype=np.float32)
            for _ in range(200):
                v.step(a)
            S = np.zeros((N, 6)); S[:, 4] = 8.0; S[:, 3] = np.linspace(0, 6, N)
            for _ in range(20):
                pb.simulate(S, table={"kind": "circle", "radius": 0.2}, law="elastic", t_final=0.2)
        except Exception as exc:  # noqa: BLE001
            errors.append(exc)

    ts = [threading.Thread(target=run, args=(v, i)) for i, v in enumerate(envs)]
    for t in ts:
        t.start()
    for t in ts:
        t.join()
    assert not errors, errors
    print("layer", numba.threading_layer())
"""


@pytest.mark.parametrize("layer", [None, "workqueue", "omp"])
def test_two_python_threads_step_two_vector_envs_and_batches_at_once(layer):
    # workqueue (penny_env's choice, and numba's only layer where OpenMP is missing) aborts the process
    # on concurrent parallel calls unless they are serialised
    code, out = run_script(THREADS, **({"NUMBA_THREADING_LAYER": layer} if layer else {}))
    if layer and code != 0 and "No threading layer could be loaded" in out:
        pytest.skip(f"numba's {layer} layer does not load here")
    assert code == 0 and "layer " in out, out
    if layer:
        assert f"layer {layer}" in out, out


def test_the_users_threading_layer_choice_is_kept():
    code, out = run_script("""
        import numba, numpy as np, gymnasium as gym, penny_env
        from penny_env.backends.threads import SERIAL_BELOW  # (fewer pennies run on the calling thread)
        v = gym.make_vec("PennyReach-Plane-v0", num_envs=SERIAL_BELOW)
        v.reset(seed=0)
        v.step(np.zeros((SERIAL_BELOW, 2), dtype=np.float32))
        print("layer", numba.threading_layer())
    """, NUMBA_THREADING_LAYER="omp")
    if code != 0 and "threading layer" in out and "omp" in out.lower() and "could not" in out.lower():
        pytest.skip("numba's OpenMP layer does not load here")
    assert code == 0 and "layer omp" in out, out


def test_the_parallel_loops_equal_the_serial_ones_on_a_walled_table():
    # the vector step and the batch's event loop at SERIAL_BELOW + 8 pennies (parallel, prange) against the
    # same pennies in calls of 8 (the calling thread): bitwise, with impacts (their records' writes must land)
    import numpy as np

    from penny_env import PennyVectorEnv
    import penny_env.batch as pb
    from penny_env.backends.threads import SERIAL_BELOW
    n = SERIAL_BELOW + 8
    big, small = PennyVectorEnv(n, "stadium", "impacts"), PennyVectorEnv(8, "stadium", "impacts")
    ob, _ = big.reset(seed=5)
    os_, _ = small.reset(seed=5)
    assert np.array_equal(ob[:8], os_)
    rng = np.random.default_rng(0)
    impacts = 0
    for _ in range(40):
        a = rng.uniform(-1, 1, (n, 2))
        rb, rs = big.step(a), small.step(a[:8])
        for x, y in zip(rb[:4], rs[:4]):
            assert np.array_equal(x[:8], y)
        assert np.array_equal(rb[4]["impacts"][:8], rs[4]["impacts"])
        assert np.array_equal(rb[4]["kinetic_energy"][:8], rs[4]["kinetic_energy"])
        impacts += int(rb[4]["impacts"].sum())
    assert impacts > 100
    S = np.zeros((n, 6))
    S[:, 4] = 20.0
    S[:, 3] = np.linspace(0, 6, n)
    whole = pb.simulate(S, table={"kind": "circle", "radius": 0.12}, law="elastic", t_final=2.0)
    part = pb.simulate(S[:8], table={"kind": "circle", "radius": 0.12}, law="elastic", t_final=2.0)
    assert np.array_equal(whole.final_states[:8], part.final_states) and whole.impact_counts[:8].sum() >= 16
    assert np.array_equal(whole.impact_counts[:8], part.impact_counts)


FORK_WHILE_STEPPING = """
    import os, threading, time
    import numpy as np
    import numba
    import penny_env
    from penny_env.backends import threads
    from penny_env.backends.threads import SERIAL_BELOW
    N = 2 * SERIAL_BELOW  # the parallel loop
    v = penny_env.PennyVectorEnv(N)
    v.reset(seed=0)
    v.step(np.zeros((N, 2)))
    print("layer", numba.threading_layer())

    def fork_and_use():
        # the child builds and steps vector envs at once (a small one, and one big enough for the parallel loop);
        # exit 0 when it ran serially, "blocked" when it had not finished after 60 s
        pid = os.fork()
        if pid == 0:
            try:
                for n in (4, SERIAL_BELOW):
                    w = penny_env.PennyVectorEnv(n)
                    w.reset(seed=1)
                    w.step(np.zeros((n, 2)))
                os._exit(0 if threads.serial_now() else 3)
            except BaseException:
                os._exit(2)
        deadline = time.time() + 60
        while True:
            done, status = os.waitpid(pid, os.WNOHANG)
            if done:
                return os.waitstatus_to_exitcode(status)
            if time.time() > deadline:
                os.kill(pid, 9)
                os.waitpid(pid, 0)
                return "blocked"
            time.sleep(0.05)

    # 1. deterministic: a thread holds the parallel lock at the fork (as a thread inside a parallel step does)
    held, release = threading.Event(), threading.Event()

    def hold():
        with threads.PARALLEL_LOCK:
            held.set()
            release.wait()
    t = threading.Thread(target=hold, daemon=True)
    t.start()
    held.wait()
    print("held lock child", fork_and_use())
    release.set()
    t.join()

    # 2. the trial's case: a background thread steps the vector env in a loop while the main thread forks
    stop, steps = threading.Event(), [0]

    def run():
        while not stop.is_set():
            v.step(np.zeros((N, 2)))
            steps[0] += 1
    t = threading.Thread(target=run, daemon=True)
    t.start()
    while steps[0] < 2:
        time.sleep(0.01)
    print("stepping children", [fork_and_use() for _ in range(3)])
    stop.set()
    t.join()
"""


@pytest.mark.skipif(not hasattr(os, "fork"), reason="no fork() on this platform")
@pytest.mark.parametrize("layer", [None, "omp", "workqueue", "tbb"])
def test_a_child_forked_while_another_thread_steps_uses_penny_env_at_once(layer):
    # repro_fork_lock (issue 31): under workqueue and TBB a child forked while a background thread ran
    # PennyVectorEnv.step blocked for more than 20 s in 2 of 3 tries: it inherited PARALLEL_LOCK held by a thread
    # it does not have. The child now gets a fresh lock and runs serially on every layer (backends/threads.py).
    code, out = run_script(FORK_WHILE_STEPPING, **({"NUMBA_THREADING_LAYER": layer} if layer else {}))
    if layer and code != 0 and ("No threading layer could be loaded" in out or "libtbb" in out
                                or "threading layer" in out and "not" in out.lower()):
        pytest.skip(f"numba's {layer} layer does not load here (TBB needs libtbb, the tbb package)")
    assert code == 0 and "held lock child 0" in out and "stepping children [0, 0, 0]" in out, out
    if layer:
        assert f"layer {layer}" in out, out



def test_numba_cache_saves_take_turns_across_processes(tmp_path):
    """numba's cache index takes one writer at a time (two processes saving two signatures of one function both took
    <name>.1.nbc, and a later load crashed): penny_env wraps numba's save in an exclusive lock on <index>.lock. A
    child holds that lock; the parent's save waits until the child has let go (the order of the events, not a
    time), and then the index holds the parent's entry."""
    pytest.importorskip("numba")
    from numba.core import caching

    from penny_env.backends.interrupts import load_numba
    load_numba()
    assert caching.IndexDataCacheFile.save.penny_env_locked
    index = tmp_path / "f.nbi"
    log = tmp_path / "events"
    child = subprocess.Popen([sys.executable, "-c", f"""
import fcntl, os, time
fd = os.open({str(index) + ".lock"!r}, os.O_RDWR | os.O_CREAT)
fcntl.flock(fd, fcntl.LOCK_EX)
open({str(log)!r}, "a").write("child holds\\n")
time.sleep(1.0)
open({str(log)!r}, "a").write("child lets go\\n")
"""])
    try:
        while not log.exists():
            time.sleep(0.01)
        cache_file = caching.IndexDataCacheFile(cache_path=str(tmp_path), filename_base="f", source_stamp="stamp")
        cache_file.save(("sig", "target"), b"machine code")
        log.open("a").write("parent saved\n")
    finally:
        child.wait(timeout=60)
    assert log.read_text().splitlines() == ["child holds", "child lets go", "parent saved"]
    assert cache_file.load(("sig", "target")) == b"machine code"


CALLER_OF_A_PARALLEL_LOOP = '''
import numba
import numpy as np


@numba.njit(parallel=True, cache=True)
def doubled(a):
    out = np.zeros(a.shape[0])
    for i in numba.prange(a.shape[0]):
        out[i] = 2.0 * a[i]
    return out


@numba.njit(cache=True)
def total(a):
    return doubled(a).sum()
'''


def run_in(folder, code, **env):
    """(returncode, output) of ``code`` in a new interpreter that imports the module ``loops`` from ``folder``."""
    full = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "NUMBA_THREADING_LAYER")}
    full.update(env, PYTHONPATH=os.pathsep.join([str(folder), str(ROOT)]))
    out = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], cwd=folder, env=full, capture_output=True,
                         text=True, timeout=300)
    return out.returncode, out.stdout + out.stderr


def cache_a_caller_compiled_against_a_cached_loop(folder, repaired):
    """The order that crashed (numba issues #8578, #9938): one process compiles and caches the parallel loop, a second
    loads it from the cache and compiles (and caches) a function that calls it, with or without penny_env's repair."""
    (folder / "loops.py").write_text(CALLER_OF_A_PARALLEL_LOOP)
    code, out = run_in(folder, "import numpy as np, loops; print(loops.doubled(np.ones(1000)).sum())")
    assert code == 0 and "2000.0" in out, out
    repair = ("from penny_env.backends.numba_repairs import repair_numba_cache; repair_numba_cache()\n"
              if repaired else "")
    code, out = run_in(folder, repair + "import numpy as np, loops; print(loops.total(np.ones(1000)))")
    assert code == 0 and "2000.0" in out, out


def test_a_caller_cached_against_a_cached_parallel_loop_launches_the_threads_when_loaded(tmp_path):
    # numba_repairs.keep_parallel_init_on_cached_loads: the caller's cache entry keeps the launch of numba's threads,
    # so a third process that loads it (numba alone, no penny_env) runs it
    cache_a_caller_compiled_against_a_cached_loop(tmp_path, repaired=True)
    code, out = run_in(tmp_path, "import numpy as np, loops; print(loops.total(np.ones(1000)))")
    assert code == 0 and "2000.0" in out, out


def test_a_locked_loop_launches_the_threads_before_its_first_parallel_call(tmp_path):
    # threads.locked covers cache entries written without the repair (by an older penny_env, or numba alone)
    cache_a_caller_compiled_against_a_cached_loop(tmp_path, repaired=False)
    code, out = run_in(tmp_path, """
        import numpy as np, loops
        from penny_env.backends import threads
        total = threads.locked(loops.total, count=lambda args: threads.SERIAL_BELOW)  # (the parallel path)
        print(total(np.ones(1000)))
    """)
    assert code == 0 and "2000.0" in out, out
