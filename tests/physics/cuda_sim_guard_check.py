"""Run under numba's CUDA simulator (NUMBA_ENABLE_CUDASIM=1) by tests/physics/test_runtime_guard.py: the event loop's
run-time guard on the CUDA backend against the plain-Python backend (the same functions), with the sneaky law
of that test. Prints one JSON line per case; exits non-zero on the first mismatch."""
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import penny_env as pe  # noqa: E402
import penny_env.batch as pb  # noqa: E402
from test_runtime_guard import S_NAN, S_PUMP, TARGET, sneaky  # noqa: E402


def vector_case():
    starts = np.array([S_NAN, S_PUMP, [0.0, 0.0, 0.0, 1.0, 0.5, 0.1]])
    envs = [pe.PennyVectorEnv(3, "ellipse", "reach", law="sneaky", backend=b, **kw)
            for b, kw in (("python", {}), ("cuda", {"outputs": "numpy"}))]
    results = []
    for env in envs:
        env.reset(seed=0, options={"state": starts, "target": TARGET})
        for _ in range(100):
            out = env.step(np.zeros((3, 2)))
            if out[3].any():
                break
        results.append(out)
    (o1, r1, _, t1, i1), (o2, r2, _, t2, i2) = results
    same = (np.array_equal(o1, o2) and np.array_equal(r1, r2) and np.array_equal(t1, t2)
            and np.array_equal(i1["limit"], i2["limit"]) and list(i2["limit"]) == [3, 4, 0])
    return {"case": "vector", "limits": [int(v) for v in i2["limit"]], "same": bool(same)}


def batch_case():
    S = np.array([[0.0, 0.0, 0.0, 1.0, 5.0, 0.2], S_PUMP])
    messages = []
    for backend in ("python", "cuda"):
        try:
            pb.simulate(S, table=pe.Ellipse(0.15, 0.2), law="sneaky", t_final=1.0, backend=backend)
            messages.append(None)
        except ValueError as exc:
            messages.append(str(exc))
    same = messages[0] is not None and messages[0] == messages[1] and "law 'sneaky' added kinetic energy" in messages[0]
    return {"case": "batch", "message": messages[1], "same": bool(same)}


def main():
    pe.register_law("sneaky", sneaky)
    for case in (vector_case, batch_case):
        row = case()
        print(json.dumps(row), flush=True)
        if not row["same"]:
            sys.exit(1)


if __name__ == "__main__":
    main()
