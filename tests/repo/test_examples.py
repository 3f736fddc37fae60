"""The worked example (examples/train_and_plot.py: install, train a small agent, plot) runs in its quick form."""
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def test_train_and_plot_quick(tmp_path):
    pytest.importorskip("stable_baselines3", reason="Stable-Baselines3 (the penny-env[train] extra) is not installed")
    pytest.importorskip("matplotlib", reason="matplotlib (the penny-env[plot] extra) is not installed")
    script = ROOT / "examples" / "train_and_plot.py"
    env = dict(os.environ, PYTHONPATH=str(ROOT), MPLBACKEND="Agg")
    run = subprocess.run([sys.executable, str(script), "--quick", "--out", str(tmp_path / "out")], cwd=tmp_path,
                         env=env, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    assert "trained PPO: success" in run.stdout and "uniformly random actions" in run.stdout
    figure = tmp_path / "out" / "train_and_plot.png"
    assert figure.is_file() and figure.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # nothing written elsewhere
    # the docstring's install lines are the README's (from a clone, torch from PyTorch's CPU index)
    doc = script.read_text()
    assert 'pip install -e ".[train,plot]"' in doc and "pip install torch --index-url https://download.pytorch.org/whl/cpu" in doc
