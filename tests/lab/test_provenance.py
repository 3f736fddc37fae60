"""No committed report goes stale silently (issue 24.8): each records a hash of the sources that
make its numbers (studies/provenance.py), and this test compares it with the current
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
    assert got is not None, f"{report} records no sources hash; regenerate it: {REPORTS[report][0]}"
    now = provenance.sources_hash(report)
    assert got == now, (f"{report} is older than the code that makes it (recorded {got}, sources now {now}); "
                        f"regenerate it: {REPORTS[report][0]} (or, for an hours-long study whose numbers the change "
                        "does not reach: python -m lab.provenance --stamp REPORT --reason ...)")


def test_every_report_with_a_command_is_tracked():
    # a new report in docs/ (a Markdown file naming its command) must be listed in REPORTS
    for path in sorted((ROOT / "docs").glob("*.md")):
        head = path.read_text().splitlines()[:12]
        if any(re.match(r"^- commands?: `", line) for line in head):
            assert f"docs/{path.name}" in REPORTS or f"docs/{path.name}" in provenance.ARCHIVED, \
                f"docs/{path.name} has a command but no entry in provenance.REPORTS"
    for report, why in provenance.ARCHIVED.items():  # kept only while a command reads it, and says which
        assert report not in REPORTS and (ROOT / report).exists() and "reads" in why, report
    for report, (command, sources) in REPORTS.items():
        assert (ROOT / report).exists(), report
        for rel in sources:
            assert (ROOT / rel).is_file(), f"{report}: source {rel} does not exist"


def _copy_tree(tmp_path, report):
    for rel in (report, *REPORTS[report][1]):
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(ROOT / rel, tmp_path / rel)


def test_an_edited_source_makes_its_report_stale(tmp_path, monkeypatch):
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
    # a report without the line is stale too
    (tmp_path / report).write_text("# x\n")
    assert provenance.stale(tmp_path)[0][1] == "records no sources hash"


def test_check_command_exit_status(monkeypatch, capsys):
    monkeypatch.setattr(provenance, "stale", lambda root=ROOT: [("docs/x.md", "records no sources hash")])
    monkeypatch.setitem(provenance.REPORTS, "docs/x.md", ("python -m make_x", ()))
    assert provenance.main(["--check"]) == 1
    out = capsys.readouterr().out
    assert "STALE docs/x.md" in out and "regenerate: python -m make_x" in out
    monkeypatch.setattr(provenance, "stale", lambda root=ROOT: [])
    assert provenance.main(["--check"]) == 0


def test_report_header_carries_the_sources_line(tmp_path):
    from lab import common
    lines = common.header("t", "studies.stability", ["--quick"])
    assert any(line.startswith("- sources: sha256 " + provenance.sources_hash("docs/stability.md")) for line in lines)
    assert any(line.startswith("- load when this header was written:") for line in lines)
    assert not any("sources" in line for line in common.header("t", "some.other.module", []))


def test_stability_expects_the_documented_refusal():
    # tables narrower than R (1 + MIN_GAP) are refused with a ValueError naming MIN_GAP; the harness
    # counted that refusal as a failure (3 of 64 checks)
    from studies import stability
    from penny_env.physics import Circle, PennyParams
    P = PennyParams()
    s0 = [0.0, 0.0, 0.0, 0.7, 2.0, 1.0]
    narrow = stability.sim_case(s0, P, Circle(P.R * (1 + 1e-8)), "elastic", t_final=0.1)
    assert narrow["passed"] and "MIN_GAP" in narrow["measured"]["refused"]
    wide = stability.sim_case(s0, P, Circle(P.R * (1 + 1e-3)), "elastic", t_final=0.1)
    assert "refused" not in wide["measured"] and wide["measured"]["impacts"] > 0
    accepted = stability.refused_case(lambda: None, "MIN_GAP")
    assert not accepted["passed"] and "accepted" in accepted["reasons"][0]
