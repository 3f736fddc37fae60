"""The side-by-side throughput comparison runs on two trees (here the same tree twice) in --quick mode."""
from pathlib import Path

import pytest

from penny_env.analysis import throughput_compare

ROOT = Path(__file__).resolve().parent.parent


def test_compare_quick_writes_ratios(tmp_path):
    out = tmp_path / "cmp.md"
    report = throughput_compare.main(["--before", str(ROOT), "--after", str(ROOT), "--quick", "--ids",
                                      "PennyReach-Plane-v0", "--sizes", "1", "--out", str(out)])
    assert out.read_text() == report
    assert "| PennyReach-Plane-v0 | 1 |" in report
    assert "speed ratio after / before" in report


def test_compare_refuses_a_tree_without_the_package(tmp_path):
    with pytest.raises(SystemExit):
        throughput_compare.main(["--before", str(tmp_path), "--after", str(ROOT), "--quick"])
