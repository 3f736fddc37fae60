"""The worked examples (examples/train_and_plot.py, and the notebook examples/first_hour.py: install, train a small
agent, plot) run in their quick forms."""
import importlib.util
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


def test_the_first_hour_notebook_runs_in_its_quick_form(tmp_path, monkeypatch):
    # issue 40, item 16: one notebook from install to a trained agent and a plot (a jupytext percent script)
    pytest.importorskip("stable_baselines3", reason="Stable-Baselines3 (the penny-env[train] extra) is not installed")
    pytest.importorskip("matplotlib", reason="matplotlib (the penny-env[plot] extra) is not installed")
    script = ROOT / "examples" / "first_hour.py"
    text = script.read_text()
    # a notebook in jupytext's percent format: its header, markdown cells and code cells
    assert text.startswith("# ---\n# jupyter:\n#   jupytext:") and "format_name: percent" in text
    assert text.count("# %% [markdown]") >= 4 and text.count("\n# %%\n") >= 4
    assert 'pip install -e ".[train,plot]"' in text and "pip install torch --index-url" in text
    out = tmp_path / "out"
    env = dict(os.environ, PYTHONPATH=str(ROOT), MPLBACKEND="Agg", PENNY_ENV_QUICK="1", PENNY_ENV_OUT=str(out))
    run = subprocess.run([sys.executable, str(script)], cwd=tmp_path, env=env, capture_output=True, text=True,
                         timeout=1800)  # (a hang detector: ten times the quick run on a busy 2-core machine)
    assert run.returncode == 0, run.stderr[-3000:]
    assert "a random episode:" in run.stdout and "impacts, the first at" in run.stdout
    assert "trained: success" in run.stdout and f"wrote {out / 'first_hour.png'}" in run.stdout
    figure = out / "first_hour.png"
    assert figure.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and (out / "run" / "model.zip").is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # nothing written elsewhere
    # where jupytext and a Jupyter kernel are installed, it runs as a notebook too
    if all(importlib.util.find_spec(m) for m in ("jupytext", "nbclient", "ipykernel")):
        import jupytext
        import nbclient
        nb = jupytext.read(script)
        for key, value in dict(PENNY_ENV_QUICK="1", PENNY_ENV_OUT=str(tmp_path / "nb"), MPLBACKEND="Agg").items():
            monkeypatch.setenv(key, value)
        nbclient.NotebookClient(nb, timeout=1800, resources={"metadata": {"path": str(tmp_path)}}).execute()
        assert (tmp_path / "nb" / "first_hour.png").is_file()
