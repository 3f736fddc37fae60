"""The quick lane `pytest -m fast` (issue 29.8) is not empty and spans the layers: at least 30 tests from
at least 6 test files (physics, backends, envs, tasks, registries and config errors, the training commands'
argument checks), none of them also marked slow or gpu."""
import os
import re
import subprocess
import sys
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
TESTS = re.compile(r"^(tests/[\w/]+\.py)::\S+", re.M)


def _collect(marker):
    """The ids `pytest --collect-only -q -m MARKER` selects, by test file."""
    env = {k: v for k, v in os.environ.items() if k != "PYTEST_ADDOPTS"}  # (a caller's -n, -m, ... left out)
    run = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:cacheprovider", "-m", marker,
                          "tests"], cwd=ROOT, capture_output=True, text=True, timeout=600, env=env)
    assert run.returncode in (0, 5), run.stdout[-3000:] + run.stderr[-3000:]  # 5: nothing selected
    return Counter(TESTS.findall(run.stdout))


def test_fast_lane_spans_the_layers():
    files = _collect("fast")
    assert sum(files.values()) >= 30 and len(files) >= 6, files
    assert _collect("fast and (slow or gpu)") == Counter()  # the lane holds no test marked slow or gpu
