"""No committed report goes stale silently: each records a hash of the sources that make its numbers, computed from
its command's import closure and the data it reads (lab/provenance.py), and this test compares it with the current
sources, naming the report and the command that regenerates it."""
import re
import shutil

import pytest

from lab import provenance
from lab.provenance import REPORTS, ROOT

if not (ROOT / "docs").is_dir() or not (ROOT / "training").is_dir():
    pytest.skip("not a source checkout (no docs/ or training/)", allow_module_level=True)


@pytest.mark.parametrize("report", sorted(REPORTS))
def test_committed_report_matches_its_sources(report):
    got = provenance.recorded_hash(ROOT / report)
    assert got is not None, f"{report} records no sources hash; regenerate it: {REPORTS[report]}"
    now = provenance.sources_hash(report)
    assert got == now, (f"{report} is older than the code that makes it (recorded {got}, sources now {now}); "
                        f"regenerate it: {REPORTS[report]} (or, for an hours-long study whose numbers the change "
                        "does not reach: python -m lab.provenance --stamp REPORT --reason ...)")


def test_every_report_with_a_command_is_tracked():
    # a new report in docs/ (a Markdown file naming its command) must be listed in REPORTS
    for path in sorted((ROOT / "docs").glob("*.md")):
        head = path.read_text().splitlines()[:12]
        if any(re.match(r"^- commands?: `", line) for line in head):
            assert f"docs/{path.name}" in REPORTS or f"docs/{path.name}" in provenance.ARCHIVED, \
                f"docs/{path.name} has a command but no entry in provenance.REPORTS"
    for report in REPORTS:
        assert (ROOT / report).exists(), report
        assert provenance.module_file(provenance.module_of(report), ROOT) is not None, report
    for report, why in provenance.ARCHIVED.items():  # kept only while a command reads it, and says which
        assert report not in REPORTS and (ROOT / report).exists() and "reads" in why, report


def test_the_sources_are_the_import_closure_and_the_data_it_reads():
    """Nothing is listed by hand: the command's module, what it imports inside functions too (baselines imports
    training.train in main), the packages' __init__.py on the way, the presets the scene module names
    (CONFIG_DIR), the config its command line names, the modules a config names (the ladder's agents); never
    the report machinery."""
    base = set(provenance.sources("docs/baselines.md"))
    assert {"studies/baselines.py", "training/train.py", "training/__init__.py", "penny_env/__init__.py",
            "penny_env/physics/laws.py", "penny_env/presets/envs.yaml", "penny_env/presets/scenes/ellipse.yaml"} <= base
    assert not base & set(provenance.MACHINERY) and not any(p.startswith(("docs/", "tests/")) for p in base)
    gpu = set(provenance.sources("docs/ppo_torch_gpu.md"))
    assert {"configs/train/ppo_torch_gpu.yaml", "training/ppo_torch.py", "studies/ppo_torch_report.py"} <= gpu
    ladder = set(provenance.sources("docs/ladder.md"))
    assert {"configs/ladder/cpu.yaml", "training/ppo_heading.py", "training/her_sac.py", "lab/jobs.py"} <= ladder
    assert "studies/reference_data/paper_scenes.json" in provenance.sources("docs/bench_solvers.md")
    assert provenance.sources("docs/throughput_compare.md") == ["devtools/throughput_compare.py"]  # other trees
    assert provenance.MODULE_REPORTS["devtools.throughput_compare"] == "docs/throughput_compare.md"


def _copy_tree(tmp_path, report):
    for rel in (report, *provenance.sources(report)):
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(ROOT / rel, tmp_path / rel)


def test_an_edited_source_or_a_new_import_makes_its_report_stale(tmp_path, monkeypatch):
    report = "docs/paper_figures.md"
    _copy_tree(tmp_path, report)
    monkeypatch.setattr(provenance, "REPORTS", {report: REPORTS[report]})
    (tmp_path / report).write_text("# r\n\n- command: `x`\n" + provenance.stamp_line(report, root=tmp_path) + "\n")
    assert provenance.stale(tmp_path) == []
    src = tmp_path / "penny_env/physics/laws.py"
    src.write_text(src.read_text() + "\n# an edit\n")
    [(name, why)] = provenance.stale(tmp_path)
    assert name == report and "other sources" in why
    # --stamp records the current hash with its reason, without a rerun
    with pytest.raises(ValueError, match="reason"):
        provenance.stamp(report, "  ", tmp_path)
    provenance.stamp(report, "the edit is a comment", tmp_path)
    assert provenance.stale(tmp_path) == []
    text = (tmp_path / report).read_text()
    assert text.count("- sources: sha256") == 1 and "without a rerun: the edit is a comment" in text
    # a module the command starts to import, inside a function, joins its sources
    (tmp_path / "studies/helper.py").write_text("X = 1\n")
    assert "studies/helper.py" not in provenance.sources(report, tmp_path)
    cmd = tmp_path / "studies/paper_figures.py"
    cmd.write_text(cmd.read_text() + "\n\ndef _more():\n    from studies import helper\n    return helper.X\n")
    assert "studies/helper.py" in provenance.sources(report, tmp_path)
    assert provenance.stale(tmp_path)[0][0] == report
    # a report without the line is stale too
    (tmp_path / report).write_text("# x\n")
    assert provenance.stale(tmp_path)[0][1] == "records no sources hash"


def test_check_command_exit_status(monkeypatch, capsys):
    monkeypatch.setattr(provenance, "stale", lambda root=ROOT: [("docs/x.md", "records no sources hash")])
    monkeypatch.setitem(provenance.REPORTS, "docs/x.md", "python -m make_x")
    assert provenance.main(["--check"]) == 1
    out = capsys.readouterr().out
    assert "STALE docs/x.md" in out and "regenerate: python -m make_x" in out
    monkeypatch.setattr(provenance, "stale", lambda root=ROOT: [])
    assert provenance.main(["--check"]) == 0
    assert provenance.main(["--sources", "docs/stability.md"]) == 0
    assert "studies/stability.py" in capsys.readouterr().out.splitlines()


def test_report_header_carries_the_sources_line(tmp_path):
    from lab import common
    lines = common.header("t", "studies.stability", ["--quick"])
    assert any(line.startswith("- sources: sha256 " + provenance.sources_hash("docs/stability.md")) for line in lines)
    assert any(line.startswith("- load when this header was written:") for line in lines)
    assert not any("sources" in line for line in common.header("t", "some.other.module", []))
