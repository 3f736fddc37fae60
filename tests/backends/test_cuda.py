"""The GPU backend without a GPU (backends/builder.py, target "cuda"; backends/cuda_env.py; docs/gpu.md).

* Every CUDA kernel, for every registered table kind (and the open plane), compiles to PTX for compute
  capability 9.0 (H100) and 8.0 (A100) with numba-cuda's compile_ptx; the law dispatch inside each kernel
  compiles the built-in laws. numba-cuda looks up the current device when it compiles device
  functions: the fixture below answers with a stand-in (this file only). Where ptxas is installed, the fast
  step kernel's registers stay within their budget.
* Under numba's CUDA simulator (NUMBA_ENABLE_CUDASIM=1, in a subprocess: the variable must be set before
  numba.cuda is imported) the CUDA backend of the vector env and of penny_env.batch equals the CPU backend
  over rollouts with impacts and autoresets in all three modes on every scene preset (tests/backends/cuda_sim_check.py):
  bitwise in the simulator, which runs the kernels' Python on the CPU; resets drawn on the device equal the
  CPU's; and a spy shows that a warm step allocates no device array, copies nothing to the host and never
  synchronizes.
* On a real GPU (``gpu`` marker, skipped without one): torch tensors out zero-copy, device tensors in, a
  non-finite action ending its env's episode (LIMIT_ACTION) and the host's error with numpy outputs,
  agreement with the CPU over a short rollout (a GPU's FMA contraction and libdevice sin/cos differ from the
  CPU in the last bits, docs/gpu.md), and the step replayed from a CUDA graph.
"""
import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from penny_env.physics.tables import COMPILED_FORMULAS

ROOT = Path(__file__).resolve().parents[2]
HAS_NUMBA_CUDA = importlib.util.find_spec("numba_cuda") is not None
needs_numba_cuda = pytest.mark.skipif(not HAS_NUMBA_CUDA, reason="numba-cuda is not installed (penny-env[cuda])")
KINDS = [-1] + list(range(len(COMPILED_FORMULAS)))


def _gpu_present():
    if not HAS_NUMBA_CUDA or os.environ.get("NUMBA_ENABLE_CUDASIM") == "1":
        return False
    from penny_env.backends.builder import cuda_available
    return cuda_available()


gpu = pytest.mark.gpu
needs_gpu = pytest.mark.skipif(not _gpu_present(), reason="no CUDA GPU here (numba-cuda finds no device)")


@pytest.fixture
def device_stand_in(monkeypatch):
    """numba-cuda's current-device look-up answered by a stand-in of the compute capability asked for."""
    def use(cc):
        from numba.cuda import dispatcher

        class StandIn:
            compute_capability = tuple(cc)
        monkeypatch.setattr(dispatcher, "get_current_device", StandIn)
    return use


def _ptx_toolchain():
    try:
        from numba import cuda
        from numba import float64
        cuda.compile_ptx(lambda a: None, (float64[:],), cc=(9, 0))
        return True
    except Exception:  # noqa: BLE001 (no NVVM / NVRTC: the wheel is missing)
        return False


# every table kind for the GPUs the step runs on (sm_90: H100, H200), and the A100's sm_80 for one kind with an event
# loop: what a compute capability can refuse (atomics, intrinsics, the register cap) is in the kernels' frame, which
# every kind shares; the kinds differ by their tables' float formulas (each compile takes minutes on a busy machine)
PTX_CASES = [pytest.param(kind, (9, 0), id=f"{kind}-sm_90") for kind in KINDS] + [pytest.param(0, (8, 0), id="0-sm_80")]


@needs_numba_cuda
@pytest.mark.slow
@pytest.mark.parametrize("kind, cc", PTX_CASES)
def test_every_kernel_compiles_to_ptx(kind, cc, device_stand_in):
    if not _ptx_toolchain():
        pytest.skip("numba-cuda cannot compile PTX here: it needs libNVVM (a CUDA toolkit, as /usr/local/cuda on the "
                    "project's machine, or the nvidia-cuda-nvcc wheel) and NVRTC (nvidia-cuda-nvrtc-cu12)")
    from devtools.cuda_kernels import compile_kernels
    from penny_env.physics.laws import builtin_law_indices
    device_stand_in(cc)
    out = compile_kernels(kind, cc)
    laws = out.pop("laws")
    assert set(out) == {"step_envs", "fast_step_envs", "rare_step_envs", "clear_work_count", "observe_rows", "reset_rows",
                        "advance_batch", "first_impact_batch"}
    for name, (ptx, _) in out.items():
        assert f".target sm_{cc[0]}{cc[1]}" in ptx and ptx.count(".entry") == 1, name
    # the event loop's kernels carry the law dispatch: the built-in laws compiled for the device (a user's law
    # enters only the builds that run it, compiled.build_laws; the plane's build has no event loop, hence no law)
    assert len(laws) == len(builtin_law_indices()) >= 2
    assert all(k >= 1 for k in laws) if kind >= 0 else all(k == 0 for k in laws)


# the fast step kernel's register budget per thread (ptxas -v, sm_90): at most 80, so that at least 37.5 % of
# an SM's threads are resident (twice the 18.75 % of the one-kernel step at 933b537: 156 registers); the
# backend compiles it with numba-cuda's max_registers (docs/gpu.md)
FAST_REGISTER_BUDGET = 80


@needs_numba_cuda
@pytest.mark.slow
def test_the_fast_kernel_keeps_its_register_budget(device_stand_in):
    from devtools.cuda_kernels import compile_kernels, find_ptxas, occupancy, ptxas_usage
    from penny_env.backends.env import FAST_MAX_REGISTERS
    if not _ptx_toolchain():
        pytest.skip("numba-cuda cannot compile PTX here (libNVVM and NVRTC)")
    ptxas = find_ptxas()
    if ptxas is None:
        pytest.skip("ptxas (the CUDA toolkit's PTX assembler) is not installed: set CUDA_HOME or put it on PATH")
    device_stand_in((9, 0))
    ptx = compile_kernels(0, (9, 0), names={"fast_step_envs"})["fast_step_envs"][0]
    used = ptxas_usage(ptx, (9, 0), ptxas, FAST_MAX_REGISTERS)
    assert used["registers"] <= FAST_REGISTER_BUDGET and occupancy(used["registers"]) >= 2 * occupancy(156)


def test_kernels_are_generated_from_the_loops_and_refuse_other_shapes():
    from penny_env.backends import env
    from penny_env.backends.builder import loop_parts
    from penny_env.step import functional
    from penny_env.physics import batch_loops
    assert loop_parts(functional.step_envs) == ("step_env", "st.S.shape[1]")
    assert loop_parts(env.fast_step_envs) == ("fast_step_env", "st.S.shape[1]")
    assert loop_parts(batch_loops.advance_batch) == ("advance_penny", "S.shape[1]")

    def not_a_loop(S, out):
        for i in range(S.shape[1]):
            out[i] = 2 * S[0, i]
    with pytest.raises(ValueError, match="a loop over pennies must be"):
        loop_parts(not_a_loop)


def test_cuda_backend_errors_name_the_cause():
    from penny_env import PennyVectorEnv
    import penny_env.batch as pb
    from penny_env.physics import Ellipse
    if not HAS_NUMBA_CUDA or not _gpu_present():
        with pytest.raises(ValueError, match="backend='cuda'"):
            PennyVectorEnv(2, backend="cuda")
        with pytest.raises(ValueError, match="backend='cuda'"):
            pb.simulate(np.zeros((1, 6)), table=Ellipse(0.15, 0.2), t_final=0.1, backend="cuda")
    with pytest.raises(ValueError, match="backend must be"):
        PennyVectorEnv(2, backend="gpu")
    with pytest.raises(ValueError, match="outputs must be"):
        PennyVectorEnv(2, outputs="jax")
    with pytest.raises(ValueError, match="cuda_options"):
        PennyVectorEnv(2, cuda_options={"threads": 64})
    with pytest.raises(ValueError, match="need backend='cuda'"):
        PennyVectorEnv(2, backend="numba", outputs="torch")


def _simulator(script, *args, timeout=900):
    env = dict(os.environ, NUMBA_ENABLE_CUDASIM="1", PYTHONPATH=str(ROOT))
    r = subprocess.run([sys.executable, str(ROOT / "tests" / "backends" / script), *args], capture_output=True, text=True,
                       env=env, timeout=timeout, cwd=ROOT)
    assert r.returncode == 0, r.stderr[-3000:]
    return [json.loads(line) for line in r.stdout.splitlines() if line.startswith("{")]


@needs_numba_cuda
@pytest.mark.slow
def test_cuda_backend_equals_cpu_under_the_simulator():
    rows = _simulator("cuda_sim_check.py", "60")
    assert len(rows) == 13
    # Short episodes (12 steps) rarely reach a wall; the long rollouts on walled tables must all bounce.
    walled = [row for row in rows if "plane" not in row["case"] and row.get("episode_steps") is None]
    assert all(row["bitwise"] for row in rows)
    assert sum(row["impacts"] for row in walled) > 150 and all(row["impacts"] > 0 for row in walled)
    modes = {row["case"].split()[4] for row in rows if row["case"].startswith("vector")}
    assert modes == {"NextStep", "SameStep", "Disabled"}
    # every step whole in itself: the same output set step after step (a CUDA graph of one step, replayed)
    (pinned,) = [row for row in rows if row["case"].endswith("one-set")]
    assert pinned["impacts"] > 10
    short = [row for row in rows if row.get("episode_steps") == 12]  # (episodes of 12 steps: many device resets)
    assert len(short) == 4 and all(row["resets"] > 6 for row in short)


@needs_numba_cuda
def test_a_warm_step_allocates_nothing_copies_nothing_to_the_host_and_never_synchronizes():
    """A spy on numba-cuda's allocation, transfer and synchronization functions under the simulator (outputs
    "device": the device path without torch)."""
    rows = _simulator("cuda_sim_spy.py", timeout=600)
    device = [row for row in rows if not row["control"]]
    control = [row for row in rows if row["control"]]
    assert len(device) == 4 and all(row["calls"] == {} for row in device), rows
    assert all(row["steps"] >= 5 and row["outputs_on_device"] for row in device)
    # the spy sees what it watches: numpy outputs copy each step's outputs to the host
    assert control and all(row["calls"].get("copy_to_host", 0) >= 10 * row["steps"] for row in control)


# -- on a real GPU ----------------------------------------------------------------------------------
@gpu
@needs_gpu
def test_gpu_outputs_are_device_tensors_and_match_the_cpu():
    torch = pytest.importorskip("torch")
    from penny_env import PennyVectorEnv
    from penny_env.backends.cuda_env import CudaGraphStep
    from penny_env.step.functional import LIMIT_ACTION
    n = 64
    cpu = PennyVectorEnv(n, "stadium", "impacts", backend="numba")
    dev = PennyVectorEnv(n, "stadium", "impacts", backend="cuda")
    oc, _ = cpu.reset(seed=2)
    og, _ = dev.reset(seed=2)
    assert isinstance(og, torch.Tensor) and og.is_cuda
    rng = np.random.default_rng(0)
    for _ in range(5):
        a = rng.uniform(-1, 1, (n, 2))
        rc = cpu.step(a)
        rg = dev.step(torch.as_tensor(a, device="cuda"))
        assert rg[0].is_cuda and rg[1].is_cuda and rg[4]["impact_times"].is_cuda
        np.testing.assert_allclose(rg[0].cpu().numpy(), rc[0], rtol=1e-5, atol=1e-6)
    bad = torch.zeros((n, 2), device="cuda")
    bad[3, 1] = float("nan")
    before = dev.states
    out = dev.step(bad)
    assert bool(out[3][3]) and int(out[4]["limit"][3]) == LIMIT_ACTION and np.array_equal(dev.states[3], before[3])
    host = PennyVectorEnv(n, "stadium", "impacts", backend="cuda", outputs="numpy")
    host.reset(seed=2)
    with pytest.raises(ValueError, match=r"non-finite action in sub-env\(s\) \[3\]"):
        host.step(bad)
    # the step replayed from a CUDA graph gives what the eager step gives (bitwise: the same kernels)
    eager = PennyVectorEnv(n, "stadium", "impacts", backend="cuda", max_episode_steps=20)
    graphed = PennyVectorEnv(n, "stadium", "impacts", backend="cuda", max_episode_steps=20)
    eager.reset(seed=5)
    graphed.reset(seed=5)
    step = CudaGraphStep(graphed, warmup=2)  # two warm-up steps with zero actions, then the capture
    zeros = torch.zeros((n, 2), device="cuda")
    for _ in range(2):
        eager.step(zeros)
    for a in torch.as_tensor(rng.uniform(-1, 1, (30, n, 2)), device="cuda", dtype=torch.float32):
        e, g = eager.step(a), step(a)
        for x, y in zip(e[:4], g[:4]):
            assert torch.equal(x, y)
        assert torch.equal(e[4]["impact_times"].nan_to_num(-1.0), g[4]["impact_times"].nan_to_num(-1.0))
    assert np.array_equal(eager.states, graphed.states)


def test_throughput_gpu_measures_nothing_and_writes_no_report_without_a_gpu(tmp_path, capsys):
    """A full run needs a GPU: without one it says so and writes nothing (--quick runs the table under the CUDA
    simulator instead: tests/devtools/test_gpu_tools.py)."""
    if _gpu_present():
        pytest.skip("a GPU is here: the command would measure it")
    from devtools import throughput_gpu
    out = tmp_path / "throughput_gpu.md"
    assert throughput_gpu.main(["--ids", "PennyReach-Ellipse-v0", "--sizes", "8", "--out", str(out)]) == 0
    assert not out.exists() and "no CUDA GPU here" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        throughput_gpu.main(["--sizes", "0"])
