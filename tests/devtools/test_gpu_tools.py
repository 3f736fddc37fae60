"""The GPU tools without a GPU: devtools/throughput_gpu.py runs its whole like-for-like table under numba's CUDA
simulator (--quick), devtools/rare_share.py measures the rare path's share on the CPU, and devtools/gpu_session.sh
needs nothing outside the repository (its wheels come from devtools/gpu_wheels.sh, carried in .whl/)."""
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _run(args, **env):
    return subprocess.run([sys.executable, "-m", *args], cwd=ROOT, capture_output=True, text=True, timeout=900,
                          env=dict(os.environ, PYTHONPATH=str(ROOT), **env))


@pytest.mark.slow
def test_throughput_gpu_quick_steps_every_column_on_the_same_work(tmp_path):
    pytest.importorskip("torch", reason="the policy and PPO columns need torch")
    out = tmp_path / "tg.md"
    r = _run(["devtools.throughput_gpu", "--quick", "--out", str(out)], NUMBA_ENABLE_CUDASIM="1")
    assert r.returncode == 0, r.stderr[-3000:]
    text = out.read_text()
    assert "CUDA simulator" in text and "nothing about a GPU" in text
    rows = [ln for ln in text.splitlines() if ln.startswith("| Penny")]
    # two windows per id, each named in its own row, and every column ended in the same states as env.step
    assert rows and len(rows) % 2 == 0
    assert sum("fresh:" in r for r in rows) == sum("steady:" in r for r in rows) == len(rows) // 2
    assert all(r.rstrip().endswith("| yes |") for r in rows), rows
    for r in rows:
        share = float(re.search(r"\| ([0-9.]+) % \|", r).group(1))
        assert 0.0 <= share <= 100.0


def test_throughput_gpu_quick_never_writes_into_docs():
    before = (ROOT / "docs" / "throughput_gpu.md").read_bytes()
    r = _run(["devtools.throughput_gpu", "--quick", "--out", "docs/throughput_gpu.md"], NUMBA_ENABLE_CUDASIM="1")
    assert r.returncode != 0 and "docs" in r.stderr
    assert (ROOT / "docs" / "throughput_gpu.md").read_bytes() == before


def test_rare_share_quick_splits_the_rare_path(tmp_path):
    out = tmp_path / "rs.md"
    r = _run(["devtools.rare_share", "--quick", "--policy-kinds", "random", "--out", str(out)])
    assert r.returncode == 0, r.stderr[-3000:]
    rows = [ln.split("|")[1:-1] for ln in out.read_text().splitlines() if ln.startswith("| Penny")]
    assert {row[2].strip() for row in rows} == {"fresh", "steady"}
    for row in rows:
        rare, reset, impact, waste = (float(x) for x in row[4:8])
        # the rare share is its three parts: pending resets, periods with an impact, certificate failures without one
        assert rare == pytest.approx(reset + impact + waste, abs=0.02) and min(reset, impact, waste) >= 0


def test_gpu_session_needs_nothing_outside_the_repository():
    script = (ROOT / "devtools" / "gpu_session.sh").read_text()
    assert subprocess.run(["bash", "-n", str(ROOT / "devtools" / "gpu_session.sh")]).returncode == 0
    assert "gpu_wheels.sh" in script and ".whl" in (ROOT / ".gitignore").read_text()
    code = "\n".join(ln for ln in script.splitlines() if not ln.lstrip().startswith("#"))
    assert "/work" not in code and "../" not in code and "http" not in code
    for module in re.findall(r"python3 -m ([a-z_.]+)", code):
        if module.split(".")[0] in ("studies", "devtools", "training"):
            assert (ROOT / (module.replace(".", "/") + ".py")).is_file(), module
    for path in re.findall(r"(configs/[\w/]+\.yaml|tests/[\w/]+\.py)", code):
        assert (ROOT / path).is_file(), path
    # without the wheels it stops at once and says what to run
    if not list((ROOT / ".whl").glob("*.whl")):
        r = subprocess.run(["bash", "devtools/gpu_session.sh"], cwd=ROOT, capture_output=True, text=True, timeout=60,
                           env=dict(os.environ, OUT=str(ROOT / "runs" / "gpu_session_test")))
        assert r.returncode == 2 and "gpu_wheels.sh" in r.stdout
