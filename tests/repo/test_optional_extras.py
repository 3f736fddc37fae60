"""The suite passes with skips when optional extras are missing (checked here by hiding them from a fresh
interpreter; the full check is a venv with only the core: numpy gymnasium pyyaml numba pytest)."""
import os
import subprocess
import sys
import warnings
from pathlib import Path

REPO = Path(__file__).parents[2]
EXTRAS = ("hypothesis", "mpmath", "scipy", "matplotlib", "stable_baselines3", "torch", "pygame", "moviepy", "tqdm", "rich")

RUNNER = """
import sys
HIDDEN = set(sys.argv[1].split(","))
class Hide:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in HIDDEN:
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
sys.meta_path.insert(0, Hide())
import importlib.util
_find_spec = importlib.util.find_spec
importlib.util.find_spec = lambda name, *a: None if name.split(".")[0] in HIDDEN else _find_spec(name, *a)
import pytest
sys.exit(pytest.main(["-q", "-rs", "-p", "no:cacheprovider", *sys.argv[2:]]))
"""


def test_tests_skip_with_their_reason_without_the_extras(tmp_path):
    selection = ["tests/physics/test_laws.py", "tests/physics/test_flow.py", "tests/envs/test_env_render.py",
                 "tests/training/test_training.py::test_config_errors_name_the_field", "tests/envs/test_sb3.py",
                 "tests/studies/test_analysis.py::test_matching_counts_missed_and_spurious",
                 "tests/studies/test_analysis.py::test_integrators_find_first_impacts_of_paper_elastic_circle",
                 "tests/repo/test_readme.py::test_ppo_snippet_runs",
                 "tests/analysis/test_dynamics.py::test_dynamics_report_quick"]
    env = dict(os.environ, PYTEST_DISABLE_PLUGIN_AUTOLOAD="1", PYTHONPATH=str(REPO))

    def run_selection():
        return subprocess.run([sys.executable, "-X", "faulthandler", "-c", RUNNER, ",".join(EXTRAS), *selection],
                              cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    run = run_selection()
    if run.returncode < 0:
        # killed by a signal: seen once in CI (SIGSEGV, -11) and never here; once more, with where it crashed kept
        # for the report (faulthandler's "Fatal Python error" section names the test and the line)
        first = run.stdout + run.stderr
        crash = first[first.find("Fatal Python error"):][:4000] if "Fatal Python error" in first else first[-4000:]
        warnings.warn(f"the selection died with signal {-run.returncode} and was run again; where:\n{crash}")
        run = run_selection()
    out = run.stdout + run.stderr
    crash = out[out.find("Fatal Python error"):][:4000] if "Fatal Python error" in out else ""
    assert run.returncode == 0, crash + out[-3000:]
    assert " passed" in out and " failed" not in out and " error" not in out
    for reason in ("hypothesis is not installed", "mpmath", "pygame-ce", "moviepy", "stable_baselines3",
                   "scipy (the penny-env[bench] extra)", "Stable-Baselines3", "matplotlib"):
        assert reason in out, (reason, out[-3000:])
