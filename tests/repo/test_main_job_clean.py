"""The README's main job leaves the checkout clean (issue 21.3): its commands write into git-ignored
output folders (runs/), never over a tracked file; so do the README's RL Zoo commands (logs/)."""
import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
README = (ROOT / "README.md").read_text()

pytestmark = pytest.mark.skipif(shutil.which("git") is None or not (ROOT / ".git").exists(),
                                reason="needs git and a git checkout")

# the main job's training, shortened (the commands and their default output folders stay as written)
SHORTEN = {"training.train": ["--set", "total_timesteps=4096", "--set", "eval_episodes=4", "--set", "curve_points=1",
                              "--set", "curve_episodes=2", "--progress-seconds", "5"]}


def main_job_commands() -> list[str]:
    """The `python -m ...` commands of the README's main job (after its install steps)."""
    block = re.search(r"Install and run the main job.*?```bash\n(.*?)```", README, re.S).group(1)
    return [c.strip() for c in block.strip().split("&&") if c.strip().startswith("python -m")]


def git(cwd, *args):
    return subprocess.run(["git", *args], cwd=cwd, capture_output=True, text=True, check=True).stdout


@pytest.fixture
def checkout_copy(tmp_path):
    """A fresh git repository holding the checkout's files (tracked and not ignored), committed."""
    files = git(ROOT, "ls-files", "-z", "--cached", "--others", "--exclude-standard").split("\0")
    copy = tmp_path / "checkout"
    for f in filter(None, files):
        src = ROOT / f
        if src.is_file():
            (copy / f).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, copy / f)
    git(copy, "init", "-q")
    git(copy, "add", "-A")
    git(copy, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "copy")
    return copy


def test_main_job_is_two_commands_with_their_extras():
    cmds = main_job_commands()
    assert [shlex.split(c)[2] for c in cmds] == ["studies.paper_figures", "training.train"]
    install = re.search(r"Install and run the main job.*?```bash\n(.*?)```", README, re.S).group(1)
    assert 'pip install -e ".[train,plot]"' in install  # not [all]: the main job needs SB3 and matplotlib only


@pytest.mark.slow
def test_main_job_leaves_the_checkout_clean(checkout_copy):
    for module in ("stable_baselines3", "matplotlib"):
        pytest.importorskip(module, reason=f"{module}: an extra of the main job")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
               MPLBACKEND="Agg")
    for cmd in main_job_commands():
        argv = shlex.split(cmd)
        run = subprocess.run([sys.executable, *argv[1:], *SHORTEN.get(argv[2], [])], cwd=checkout_copy, env=env,
                             capture_output=True, text=True, timeout=600)
        assert run.returncode == 0, run.stderr[-3000:]
    assert (checkout_copy / "runs" / "reports" / "paper_figures.md").is_file()
    assert (checkout_copy / "runs" / "ppo_reach_ellipse" / "model.zip").is_file()
    assert git(checkout_copy, "status", "--porcelain", "--untracked-files=all") == ""


def test_readme_command_outputs_are_ignored(checkout_copy):
    """What the README's other commands write by default: RL Zoo's logs/, training runs, videos."""
    for path in ("logs/ppo/PennyReach-Ellipse-v0_1/PennyReach-Ellipse-v0.zip", "runs/study/x/result.json",
                 "runs/reports/dynamics.md", "videos/episode-0.mp4"):
        (checkout_copy / path).parent.mkdir(parents=True, exist_ok=True)
        (checkout_copy / path).write_text("x")
    assert git(checkout_copy, "status", "--porcelain", "--untracked-files=all") == ""
    assert "-f logs/" in README and "--no-render" in re.search(r"rl_zoo3\.enjoy[^\n]*", README).group(0)
