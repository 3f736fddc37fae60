"""lab.common.report_command: what every report command repeats, in one place: --quick and --out, the refusal of
--quick into docs/ and onto the README, the default paths, the header with the command line, the writes."""
import tempfile
from pathlib import Path

import pytest

from lab.common import report_command

ROOT = Path(__file__).resolve().parents[2]


def test_paths_and_the_refusal(reports_untouched):
    rep = report_command("studies.x", "x.md", "doc", [], quick="q")
    assert rep.out == reports_untouched / "runs" / "reports" / "x.md" and not rep.quick
    assert report_command("studies.x", "x.md", "doc", [], quick="q", docs_default=True).out == ROOT / "docs" / "x.md"
    quick = report_command("studies.x", "x.md", "doc", ["--quick"], quick="q", docs_default=True)
    assert Path(tempfile.gettempdir()).resolve() in quick.out.resolve().parents and quick.out.name == "x.md"
    assert report_command("studies.x", "x.md", "doc", ["--out", "a/b.md"], quick="q").out == reports_untouched / "a/b.md"
    for target in (ROOT / "docs" / "x.md", ROOT / "docs", ROOT / "README.md"):
        with pytest.raises(SystemExit, match="never writes into docs/"):
            report_command("studies.x", "x.md", "doc", ["--quick", "--out", str(target)], quick="q")
    with pytest.raises(SystemExit, match="never writes into docs/"):  # a report flag of another name is held alike
        report_command("studies.x", "x.md", "doc", ["--quick", "--report", str(ROOT / "docs" / "x.md")], quick="q",
                       out_flag="--report")


def test_options_rest_header_and_writes(reports_untouched, capsys):
    rep = report_command("studies.stability", "x.md", "doc", ["--quick", "--n", "3", "--other", "1"], quick="q",
                         options=lambda ap: ap.add_argument("--n", type=int), rest=True)
    assert rep.args.n == 3 and rep.rest == ["--other", "1"]
    head = rep.header("Title")
    assert head[0] == "# Title" and "- command: `python -m studies.stability --quick --n 3 --other 1`" in head
    assert any(line.startswith("- sources: sha256 ") for line in head)  # a committed report's module: its hash
    assert rep.beside("_a.png") == rep.out.with_name("x_a.png")
    assert rep.write(["a", "b", ""]) == rep.out and rep.out.read_text() == "a\nb\n"
    assert f"wrote {rep.out}" in capsys.readouterr().out
    readme = reports_untouched / "README.md"
    readme.write_text("<!-- b -->\nold\n<!-- e -->\n")
    with pytest.raises(SystemExit, match="never writes"):
        rep.readme(readme, "<!-- b -->", "<!-- e -->", "new")
    full = report_command("studies.stability", "x.md", "doc", [], quick="q")
    assert full.readme(readme, "<!-- b -->", "<!-- e -->", "new") and "new" in readme.read_text()
    with pytest.raises(SystemExit):
        rep.error("--n must be positive")
    assert "--n must be positive" in capsys.readouterr().err
