"""The GPU backend without a GPU (physics/builder.py, target "cuda"; envs/cuda_step.py; docs/gpu.md).

* Every CUDA kernel, for every registered table kind (and the open plane), compiles to PTX for compute
  capability 9.0 (H100) and 8.0 (A100) with numba-cuda's compile_ptx; the law dispatch inside each kernel
  compiles the built-in laws. numba-cuda looks up the current device when it compiles device
  functions: the fixture below answers with a stand-in (this file only).
* Under numba's CUDA simulator (NUMBA_ENABLE_CUDASIM=1, in a subprocess: the variable must be set before
  numba.cuda is imported) the CUDA backend of the vector env and of penny_env.batch equals the CPU backend
  over rollouts with impacts on every scene preset (tests/cuda_sim_check.py): the same impact counts and
  ends, states within 1e-12 relative (bitwise in the simulator, which runs the kernels' Python on the CPU).
* On a real GPU (``gpu`` marker, skipped without one): torch tensors out zero-copy, device tensors in, the
  NaN-action error, and agreement with the CPU over a short rollout (a GPU's FMA contraction and libdevice
  sin/cos differ from the CPU in the last bits, docs/gpu.md).
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

ROOT = Path(__file__).resolve().parents[1]
HAS_NUMBA_CUDA = importlib.util.find_spec("numba_cuda") is not None
needs_numba_cuda = pytest.mark.skipif(not HAS_NUMBA_CUDA, reason="numba-cuda is not installed (penny-env[cuda])")
KINDS = [-1] + list(range(len(COMPILED_FORMULAS)))


def _gpu_present():
    if not HAS_NUMBA_CUDA or os.environ.get("NUMBA_ENABLE_CUDASIM") == "1":
        return False
    from penny_env.physics.builder import cuda_available
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


@needs_numba_cuda
@pytest.mark.slow
@pytest.mark.parametrize("cc", [(9, 0), (8, 0)], ids=["sm_90", "sm_80"])
@pytest.mark.parametrize("kind", KINDS)
def test_every_kernel_compiles_to_ptx(kind, cc, device_stand_in):
    if not _ptx_toolchain():
        pytest.skip("numba-cuda cannot compile PTX here: it needs libNVVM (a CUDA toolkit, as /usr/local/cuda on the "
                    "project's machine, or the nvidia-cuda-nvcc wheel) and NVRTC (nvidia-cuda-nvrtc-cu12)")
    from penny_env.analysis.cuda_ptx import compile_kernels
    from penny_env.physics.laws import builtin_law_indices
    device_stand_in(cc)
    out = compile_kernels(kind, cc)
    laws = out.pop("laws")
    assert set(out) == {"step_envs", "observe_rows", "reset_rows", "advance_batch", "first_impact_batch"}
    for name, (ptx, _) in out.items():
        assert f".target sm_{cc[0]}{cc[1]}" in ptx and ptx.count(".entry") == 1, name
    # the event loop's kernels carry the law dispatch: the built-in laws compiled for the device (a user's law
    # enters only the builds that run it, compiled.build_laws; the plane's build has no event loop, hence no law)
    assert len(laws) == len(builtin_law_indices()) >= 2
    assert all(k >= 1 for k in laws) if kind >= 0 else all(k == 0 for k in laws)


def test_kernels_are_generated_from_the_loops_and_refuse_other_shapes():
    from penny_env.envs import functional
    from penny_env.physics import compiled
    from penny_env.physics.builder import loop_parts
    assert loop_parts(functional.step_envs) == ("step_env", "st.S.shape[1]")
    assert loop_parts(compiled.advance_batch) == ("advance_penny", "S.shape[1]")

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
    with pytest.raises(ValueError, match="need backend='cuda'"):
        PennyVectorEnv(2, backend="numba", outputs="torch")


@needs_numba_cuda
@pytest.mark.slow
def test_cuda_backend_equals_cpu_under_the_simulator():
    env = dict(os.environ, NUMBA_ENABLE_CUDASIM="1", PYTHONPATH=str(ROOT))
    r = subprocess.run([sys.executable, str(ROOT / "tests" / "cuda_sim_check.py"), "60"], capture_output=True, text=True,
                       env=env, timeout=900, cwd=ROOT)
    assert r.returncode == 0, r.stderr[-3000:]
    rows = [json.loads(line) for line in r.stdout.splitlines() if line.startswith("{")]
    assert len(rows) == 8
    walled = [row for row in rows if "plane" not in row["case"]]
    assert all(row["bitwise"] for row in rows)
    assert sum(row["impacts"] for row in walled) > 150 and all(row["impacts"] > 0 for row in walled)


# -- on a real GPU ----------------------------------------------------------------------------------
@gpu
@needs_gpu
def test_gpu_outputs_are_device_tensors_and_match_the_cpu():
    torch = pytest.importorskip("torch")
    from penny_env import PennyVectorEnv
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
        assert rg[0].is_cuda and rg[1].is_cuda
        np.testing.assert_allclose(rg[0].cpu().numpy(), rc[0], rtol=1e-5, atol=1e-6)
    bad = torch.zeros((n, 2), device="cuda")
    bad[3, 1] = float("nan")
    with pytest.raises(ValueError, match=r"non-finite action in sub-env\(s\) \[3\]"):
        dev.step(bad)


def test_throughput_gpu_measures_nothing_and_writes_no_report_without_a_gpu(tmp_path, capsys):
    if _gpu_present():
        pytest.skip("a GPU is here: the command would measure it")
    from penny_env.analysis import throughput_gpu
    out = tmp_path / "throughput_gpu.md"
    assert throughput_gpu.main(["--quick", "--out", str(out)]) == 0
    assert not out.exists() and "no CUDA GPU here" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        throughput_gpu.main(["--sizes", "0"])
