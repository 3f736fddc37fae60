"""Run by tests/envs/test_interrupts.py in a fresh process: once the modules are imported, a thread sends SIGINT every
3 ms while the main thread builds and steps an env (or calls the batch API), catching KeyboardInterrupt and
ResetNeeded and resetting. (An interrupted import of a module is Python's own business, not tried here.)
Prints one JSON line: interrupts seen, refusals, errors, and whether a reset(seed) env then steps as a fresh one.
Usage: python sigint_storm.py vector|single|batch STEPS"""
import json
import os
import signal
import sys
import threading
import time

import numpy as np

what, steps = sys.argv[1], int(sys.argv[2])
stop = False


def fire():
    time.sleep(0.05)  # (th.start() returns first)
    while not stop:
        time.sleep(0.0031)
        os.kill(os.getpid(), signal.SIGINT)


# The storm's own handler raises KeyboardInterrupt only while armed, and disarms itself when it does: the harness
# arms it around each call into penny_env (attempt) and never while it counts, so an interrupt that arrives in the
# harness's own except clause (it stopped the process now and then) is dropped, not raised outside any try.
# penny_env holds a handler of the user's own during a compile as it holds Python's (backends/interrupts.py).
armed = [False]


def on_sigint(signum, frame):
    if armed[0]:
        armed[0] = False
        raise KeyboardInterrupt


def attempt(f):
    """(True, f()) or (False, None) where a KeyboardInterrupt stopped it; other exceptions propagate."""
    try:
        armed[0] = True
        try:
            return True, f()
        finally:
            armed[0] = False
    except KeyboardInterrupt:
        return False, None


def interruptible(f):
    """f() until it returns without a KeyboardInterrupt; (its result, the interrupts caught)."""
    n = 0
    while True:
        ok, out = attempt(f)
        if ok:
            return out, n
        n += 1


def storm_steps(step, reset, after, n_int, refused):
    """``steps`` calls step(j) under the storm: an interrupted one counted, a ResetNeeded refusal counted and the env
    reset (through the storm), any other exception recorded in ``errors``; after(j, out) checks a whole step's
    outputs and returns the interrupts its own calls caught. Returns (interrupts, refusals), added to those given."""
    for j in range(steps):
        try:
            ok, out = attempt(lambda: step(j))
        except ResetNeeded:
            refused += 1
            n_int += interruptible(reset)[1]
            continue
        except Exception as ex:  # noqa: BLE001
            errors.append(f"{type(ex).__name__}: {str(ex)[:100]}")
            continue
        n_int += 1 if not ok else after(j, out)
    return n_int, refused


import gymnasium as gym  # noqa: E402
from gymnasium.error import ResetNeeded  # noqa: E402

import penny_env  # noqa: E402,F401
import penny_env.batch as pb  # noqa: E402

n_int = refused = 0
errors = []
rng = np.random.default_rng(0)
th = threading.Thread(target=fire, daemon=True)
N = 64
A = rng.uniform(-1, 1, (steps, N, 2)).astype(np.float32)
signal.signal(signal.SIGINT, on_sigint)
if what == "vector":
    th.start()  # (from the build on: the storm meets the compile or the cache load too)
    v, k = interruptible(lambda: gym.make_vec("PennyReach-Ellipse-v0", num_envs=N, max_episode_steps=20))
    n_int += k
    n_int += interruptible(lambda: v.reset(seed=0))[1]
    def check(j, out):
        if not (np.isfinite(out[0]).all() and np.isfinite(out[1]).all()):
            errors.append(f"non-finite at {j}")
        return 0
    n_int, refused = storm_steps(lambda j: v.step(A[j]), v.reset, check, n_int, refused)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    stop = True
    v.reset(seed=5)
    f = gym.make_vec("PennyReach-Ellipse-v0", num_envs=N, max_episode_steps=20)
    f.reset(seed=5)
    same = all(np.array_equal(v.step(A[j])[0], f.step(A[j])[0]) for j in range(100))
elif what == "single":
    th.start()
    e, k = interruptible(lambda: gym.make("PennyPark-Stadium-v0"))
    n_int += k
    n_int += interruptible(lambda: e.reset(seed=0))[1]
    n_int, refused = storm_steps(lambda j: e.step(A[j, 0]), e.reset,
                                 lambda j, out: interruptible(e.reset)[1] if out[2] or out[3] else 0, n_int, refused)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    stop = True
    e.reset(seed=5)
    f = gym.make("PennyPark-Stadium-v0")
    f.reset(seed=5)
    same = all(np.array_equal(e.step(A[j, 0])[0], f.step(A[j, 0])[0]) for j in range(100))
else:
    S = np.column_stack([rng.uniform(-0.05, 0.05, (64, 2)), rng.uniform(-3, 3, (64, 2)), rng.uniform(-20, 20, (64, 2))])

    def run():
        return pb.simulate(S, table={"kind": "stadium", "radius": 0.1, "length": 0.15}, law="plastic",
                           t_final=0.2).final_states
    th.start()  # (a call takes longer than 3 ms: most are interrupted; none may break the next)
    for j in range(steps // 10):
        try:
            n_int += not attempt(run)[0]
        except Exception as ex:  # noqa: BLE001
            errors.append(f"{type(ex).__name__}: {str(ex)[:100]}")
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    stop = True
    import subprocess
    fresh = subprocess.run([sys.executable, "-c", "import sys, numpy as np, penny_env.batch as pb; "
                            "S = np.frombuffer(bytes.fromhex(sys.argv[1])).reshape(64, 6); "
                            "print(pb.simulate(S, table={'kind': 'stadium', 'radius': 0.1, 'length': 0.15}, "
                            "law='plastic', t_final=0.2).final_states.tobytes().hex())", S.tobytes().hex()],
                           capture_output=True, text=True)
    same = bytes.fromhex(fresh.stdout.strip()) == run().tobytes()
print(json.dumps({"interrupts": n_int, "refused": refused, "errors": errors, "same_after_reset": bool(same)}))
