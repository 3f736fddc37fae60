"""Run under numba's CUDA simulator (NUMBA_ENABLE_CUDASIM=1) by tests/backends/test_cuda.py: after warm-up steps, a spy on
numba-cuda's allocating, host-transferring and synchronizing functions (and on device arrays' copies to and from
the host) counts what a step of the device-resident vector env (outputs "device", actions on the device) calls.
Prints one JSON line per case: the calls seen (none expected; a control case with numpy outputs must show its
copies)."""
import json
from collections import Counter

import numpy as np
from gymnasium.vector import AutoresetMode
from numba import cuda

from penny_env import PennyVectorEnv

SPIED = ("device_array", "device_array_like", "to_device", "pinned_array", "pinned_array_like", "mapped_array",
         "synchronize")


def spy_on(calls):
    """Patch numba.cuda's functions above and the device arrays' copy_to_host to count their calls."""
    cls = type(cuda.to_device(np.zeros(1)))  # (the device array class, before the spy counts)
    saved = {}
    for name in SPIED:
        f = getattr(cuda, name)
        saved[name] = f

        def counted(*a, _name=name, _f=f, **k):
            calls[_name] += 1
            return _f(*a, **k)
        setattr(cuda, name, counted)
    saved_host = cls.copy_to_host

    def copy_to_host(self, *a, **k):
        calls["copy_to_host"] += 1
        return saved_host(self, *a, **k)
    cls.copy_to_host = copy_to_host
    saved_to_device = cls.copy_to_device

    def copy_to_device(self, source, *a, **k):
        if isinstance(source, np.ndarray):  # (a copy from the host; from another device array it stays there)
            calls["copy_to_device from the host"] += 1
        return saved_to_device(self, source, *a, **k)
    cls.copy_to_device = copy_to_device
    return saved, cls, (saved_host, saved_to_device)


def restore(saved, cls, saved_methods):
    for name, f in saved.items():
        setattr(cuda, name, f)
    cls.copy_to_host, cls.copy_to_device = saved_methods


def case(scene, task, mode, kernels, outputs="device"):
    n = 8
    env = PennyVectorEnv(n, scene, task, backend="cuda", outputs=outputs, autoreset_mode=mode, max_episode_steps=4,
                         cuda_options={"kernels": kernels})
    env.reset(seed=3)
    actions = cuda.to_device(np.random.default_rng(0).uniform(-1, 1, (n, env.single_action_space.shape[0])))
    for _ in range(3):  # warm-up: both output sets used, the kernels compiled
        env.step(actions)
    calls = Counter()
    spied = spy_on(calls)
    try:
        steps = 0
        for _ in range(6):  # (episodes of 4 steps: resets on the device inside these steps)
            out = env.step(actions)
            steps += 1
    finally:
        restore(*spied)
    on_device = all(hasattr(x, "copy_to_host") and not isinstance(x, np.ndarray) for x in out[:4])
    return {"case": f"{scene} {task} {mode.value} {kernels} {outputs}", "calls": dict(calls), "steps": steps,
            "outputs_on_device": bool(on_device), "control": outputs != "device"}


def main():
    for mode in (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP, AutoresetMode.DISABLED):
        print(json.dumps(case("stadium", "impacts", mode, "split")), flush=True)
    print(json.dumps(case("ellipse", "reach", AutoresetMode.NEXT_STEP, "one")), flush=True)
    # the control: numpy outputs copy every output to the host, which the spy must see
    print(json.dumps(case("ellipse", "reach", AutoresetMode.NEXT_STEP, "split", "numpy")), flush=True)


if __name__ == "__main__":
    main()
