"""Ctrl-C, again and again (issue 40): a thread sends SIGINT every 3 ms while the main thread builds and steps a
vector env, a single env, or calls the batch API (tests/envs/sigint_storm.py, in a fresh process each). At 2f3b42e
the vector env's process aborted ("free(): double free detected in tcache 2": an llvmlite object finalized by the
cycle collector inside a step met the KeyboardInterrupt). Now every compile holds SIGINT until it is done and
collects the compiler's garbage (backends/interrupts.py), and an interrupted step or reset makes the next step
raise ResetNeeded until a reset: the process survives, nothing non-finite comes out, and a reset(seed) env then
steps bitwise as a fresh one."""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow
@pytest.mark.parametrize("what, steps", [("vector", 3000), ("single", 3000), ("batch", 1000)])
def test_a_storm_of_interrupts_leaves_the_process_and_the_envs_whole(what, steps):
    env = dict(os.environ, PYTHONPATH=str(ROOT), PYTHONFAULTHANDLER="1")
    r = subprocess.run([sys.executable, str(Path(__file__).with_name("sigint_storm.py")), what, str(steps)],
                       capture_output=True, text=True, timeout=1800, env=env, cwd=ROOT)
    assert r.returncode == 0, f"exit {r.returncode}: {r.stderr[-3000:]}"
    out = json.loads(r.stdout.strip().splitlines()[-1])
    assert out["interrupts"] > 0, out  # (the storm reached the work)
    assert out["errors"] == [], out["errors"][:5]
    assert out["same_after_reset"], out


def test_a_handler_of_the_users_own_is_held_through_a_compile_and_called_once_after():
    """A training loop's own SIGINT handler (one that saves a checkpoint and raises, say) met a compile as Python's
    default one did; it is held the same way and called once, after the block, with the signal."""
    import signal

    from penny_env.backends.interrupts import compiling
    calls = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: calls.append(signum))
    try:
        with compiling(collect=False):
            for _ in range(3):
                os.kill(os.getpid(), signal.SIGINT)
                sum(range(10000))  # (Python runs a handler between bytecodes)
            assert calls == []
        assert calls == [signal.SIGINT]
        os.kill(os.getpid(), signal.SIGINT)
        sum(range(10000))
        assert calls == [signal.SIGINT] * 2  # (restored after the block)
    finally:
        signal.signal(signal.SIGINT, previous)



LLVMLITE_CLOSE_GUARDED = """
    import os, signal
    from llvmlite.binding import ffi
    from penny_env.backends.interrupts import guard_llvmlite_close, load_numba
    load_numba()
    print("guarded", ffi.OutputString.close.penny_env_guarded and ffi.ObjectRef.close.penny_env_guarded)

    class Resource:  # llvmlite's shape: free, then mark; the SIGINT comes in between
        def __init__(self):
            self.freed = self.marked = False

        def close(self):
            self.freed = True
            os.kill(os.getpid(), signal.SIGINT)
            sum(range(10000))  # (Python would run the handler here, between the two steps)
            self.marked = True

    guard_llvmlite_close((Resource,))
    guard_llvmlite_close((Resource,))  # (wrapped once)
    r = Resource()
    try:
        r.close()
        print("no KeyboardInterrupt")
    except KeyboardInterrupt:
        print("KeyboardInterrupt after close", r.freed and r.marked)
"""


def test_llvmlite_close_is_guarded_and_a_sigint_in_it_comes_right_after(python_sigint_handler):
    """llvmlite's close frees, then marks freed: a KeyboardInterrupt between the two made __del__ free again (the
    process aborted: double free). penny_env wraps both close methods when it loads numba; a SIGINT that arrives
    inside close is raised again once close is done. In a fresh interpreter (its main thread, Python's own SIGINT
    handler): in a test worker, what earlier tests left (threads, handlers) is not the case under test."""
    pytest.importorskip("numba")
    import textwrap
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    r = subprocess.run([sys.executable, "-c", textwrap.dedent(LLVMLITE_CLOSE_GUARDED)], capture_output=True,
                       text=True, timeout=600, env=env, cwd=ROOT)
    assert r.returncode == 0, r.stderr[-3000:]
    assert "guarded True" in r.stdout and "KeyboardInterrupt after close True" in r.stdout, r.stdout + r.stderr[-3000:]
