"""Report commands write where --out says, from any working directory, and --quick never writes over the
committed reports (docs/) or the README: without --out a quick run writes into a temporary directory."""
import importlib
import importlib.util
import os
import re
import tempfile
from pathlib import Path

import pytest

from lab import provenance
from lab.common import report_path

REPO = Path(__file__).parents[2]


def test_report_path(reports_untouched):
    cwd = reports_untouched
    assert report_path("a/b.md", quick=True, name="x.md") == cwd / "a" / "b.md"
    assert report_path("a/b.md", quick=False, name="x.md") == cwd / "a" / "b.md"
    assert report_path(None, quick=False, name="x.md") == cwd / "runs" / "reports" / "x.md"  # never a tracked file
    quick = report_path(None, quick=True, name="x.md")
    assert quick.name == "x.md" and quick.parent.is_dir()
    assert Path(tempfile.gettempdir()).resolve() in quick.resolve().parents and cwd not in quick.parents


# report commands whose quick run is cheap enough to run here without --out
DEFAULTED = [("studies.dynamics", "matplotlib"), ("studies.paper_figures", "matplotlib"),
             ("studies.controllability", "matplotlib"), ("studies.baselines", "stable_baselines3")]


@pytest.mark.parametrize("module, needs", DEFAULTED)
def test_quick_without_out_writes_to_a_temporary_directory(reports_untouched, capsys, module, needs):
    if importlib.util.find_spec(needs) is None:
        pytest.skip(f"{needs} (an optional extra of {module}) is not installed")
    importlib.import_module(module).main(["--quick"])
    wrote = re.findall(r"^wrote (\S+?\.md)", capsys.readouterr().out, re.M)
    assert len(wrote) == 1, "the command says where it wrote"
    out = Path(wrote[0])
    assert out.exists() and out.stat().st_size > 0
    assert Path(tempfile.gettempdir()).resolve() in out.resolve().parents
    assert REPO.resolve() not in out.resolve().parents and reports_untouched not in out.parents
    assert list(reports_untouched.iterdir()) == []  # nothing in the working directory either


def test_train_output_folder(reports_untouched, monkeypatch):
    from training import train
    seen = []
    monkeypatch.setattr(train, "train", lambda cfg, out, quick=False, **kw: seen.append((out, quick)))
    config = str(REPO / "configs" / "train" / "ppo_reach_ellipse.yaml")
    train.main(["--config", config, "--quick", "--out", "runs/mine"])
    train.main(["--config", config, "--quick"])
    train.main(["--config", config])
    (given, _), (quick, _), (full, _) = seen
    assert given == reports_untouched / "runs" / "mine"
    assert Path(tempfile.gettempdir()).resolve() in quick.resolve().parents and quick.name == "ppo_reach_ellipse"
    assert full == reports_untouched / "runs" / "ppo_reach_ellipse"


def test_throughput_quick_refuses_to_write_the_readme(reports_untouched):
    from devtools import throughput
    readme = reports_untouched / "README.md"
    readme.write_text("<!-- throughput:start -->\n<!-- throughput:end -->\n")
    with pytest.raises(SystemExit):
        throughput.main(["--quick", "--readme", str(readme)])
    assert readme.read_text() == "<!-- throughput:start -->\n<!-- throughput:end -->\n"


# every report command starts with lab.common.report_command; the commands with --quick that do not, and why
REPORT_COMMANDS = ["studies.baselines", "studies.bench_solvers", "studies.billiards", "studies.billiards_answer",
                   "studies.controllability", "studies.dynamics", "studies.impact_oc", "studies.lyapunov_spread",
                   "studies.measure_readme",
                   "studies.optimal_control", "studies.paper_figures", "studies.ppo_torch_report", "studies.stability",
                   "studies.work_precision", "devtools.compile_time", "devtools.contention", "devtools.cuda_kernels",
                   "devtools.ppo_speed", "devtools.rare_share", "devtools.throughput", "devtools.throughput_compare",
                   "devtools.throughput_gpu"]
NOT_REPORT_COMMANDS = {"studies.ladder": "its report goes to --out; the ladder's own refusal (its author converts it)",
                       "studies.witness_study": "its report folder is --out-dir, refused with --quick in docs/",
                       "devtools.action_path": "prints one step's path, writes no file",
                       "devtools.motion_dump": "writes a .npz dump, not a report",
                       "devtools.step_work": "prints the step's work counters, writes no file"}


def test_every_command_with_quick_is_a_report_command_or_says_why_not():
    for folder in ("studies", "devtools"):
        for path in sorted((REPO / folder).glob("*.py")):
            module, text = f"{folder}.{path.stem}", path.read_text()
            if '"--quick"' in text or "report_command(" in text:
                assert (module in REPORT_COMMANDS) == ("report_command(" in text), module
                assert module in REPORT_COMMANDS or module in NOT_REPORT_COMMANDS, module
    for command in provenance.REPORTS.values():  # every committed report's command
        assert command.split()[2] in REPORT_COMMANDS or command.split()[2] in NOT_REPORT_COMMANDS, command


@pytest.mark.parametrize("module", REPORT_COMMANDS)
def test_quick_never_overwrites_a_committed_report(module, capsys):
    """--quick into docs/ (or onto the README) is refused before any work, by every report command."""
    root = Path(__file__).resolve().parents[2]
    for target in (root / "docs" / "quick_must_not_exist.md", root / "README.md"):
        before = target.read_bytes() if target.exists() else None
        flag = "--report" if module == "studies.ppo_torch_report" else "--out"
        with pytest.raises(SystemExit, match="never writes into docs/"):
            importlib.import_module(module).main(["--quick", flag, str(target)])
        assert (target.read_bytes() if target.exists() else None) == before


def test_the_refusal_is_the_command_line_s(tmp_path):
    """As users run it: exit status 1 and the reason on stderr."""
    import subprocess
    import sys
    root = Path(__file__).resolve().parents[2]
    target = root / "docs" / "quick_must_not_exist.md"
    r = subprocess.run([sys.executable, "-m", "studies.dynamics", "--quick", "--out", str(target)], cwd=tmp_path,
                       capture_output=True, text=True, timeout=600, env=dict(os.environ, PYTHONPATH=str(root)))
    assert r.returncode == 1 and "never writes into docs/" in r.stderr, (r.stdout[-500:], r.stderr[-1500:])
    assert not target.exists()
