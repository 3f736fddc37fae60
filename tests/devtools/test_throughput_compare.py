"""The side-by-side throughput comparison runs on two trees (here the same tree twice) in --quick mode."""
import json
from pathlib import Path

import pytest

from devtools import throughput_compare

ROOT = Path(__file__).resolve().parents[2]


def test_compare_quick_writes_ratios(tmp_path):
    out = tmp_path / "cmp.md"
    report = throughput_compare.main(["--before", str(ROOT), "--after", str(ROOT), "--quick", "--ids",
                                      "PennyReach-Plane-v0", "--sizes", "1", "--out", str(out)])
    assert out.read_text() == report
    assert "| PennyReach-Plane-v0 | 1 |" in report
    assert "speed ratio after / before" in report
    assert "- beside: nothing added" in report


def test_compare_busy_runs_a_spinner_beside_and_says_so(tmp_path, monkeypatch):
    """--busy: one spinning process beside the measurement (killed afterwards), named in the header, with
    the busy report's sources line."""
    started = []
    real = throughput_compare.subprocess.Popen

    def popen(*a, **kw):
        started.append(real(*a, **kw))
        return started[-1]
    monkeypatch.setattr(throughput_compare.subprocess, "Popen", popen)
    out = tmp_path / "busy.md"
    report = throughput_compare.main(["--busy", "--before", str(ROOT), "--after", str(ROOT), "--quick", "--ids",
                                      "PennyReach-Plane-v0", "--sizes", "1", "--out", str(out)])
    assert "- beside: one spinning Python process for the whole run" in report
    assert "| PennyReach-Plane-v0 | 1 |" in report
    spinners = [p for p in started if "while True" in str(p.args[-1])]  # (the workers start through Popen too)
    assert len(spinners) == 1 and len(started) == 3
    assert spinners[0].poll() is not None  # the spinner is gone


def test_compare_refuses_a_tree_without_the_package(tmp_path):
    with pytest.raises(SystemExit):
        throughput_compare.main(["--before", str(tmp_path), "--after", str(ROOT), "--quick"])


def test_speed_ratios_best_of_rounds_and_median_of_paired_rounds():
    # single: us per step (lower is faster); vector: env-steps per second (higher is faster)
    runs = {"before": [{"single": {"A": 10.0}, "vector": {"A|4": 100.0}},
                       {"single": {"A": 8.0}, "vector": {"A|4": 200.0}},
                       {"single": {"A": 9.0}, "vector": {"A|4": 150.0}}],
            "after": [{"single": {"A": 5.0}, "vector": {"A|4": 90.0}},
                      {"single": {"A": 8.0}, "vector": {"A|4": 100.0}},
                      {"single": {"A": 6.0}, "vector": {"A|4": 150.0, "B|1": 1.0}}]}
    b, a, best, med = throughput_compare.speed_ratios(runs, "single")["A"]
    assert (b, a, best) == (8.0, 5.0, 8.0 / 5.0)
    assert med == 1.5  # rounds: 2.0, 1.0, 1.5
    vector = throughput_compare.speed_ratios(runs, "vector")
    assert list(vector) == ["A|4"]  # B|1: not in every run
    b, a, best, med = vector["A|4"]
    assert (b, a, best) == (200.0, 150.0, 0.75)
    assert med == 0.9  # rounds: 0.9, 0.5, 1.0


def _worker_order(capsys, seed):
    ids = ["PennyReach-Plane-v0", "PennySteer-Plane-v0", "PennyReach-Ellipse-v0", "PennyPark-Circle-v0"]
    throughput_compare.main(["--worker", "--order-seed", str(seed), "--ids", *ids, "--sizes", "1", "2",
                             "--single-steps", "3", "--vector-budget", "6"])
    data = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    return list(data["single"]), list(data["vector"])


def test_each_round_measures_in_its_own_order(capsys):
    # a measurement depends on what ran before it in the process: each round shuffles the order, the
    # same way for both trees (the worker records its measurements in the order taken)
    first = _worker_order(capsys, 0)
    assert _worker_order(capsys, 0) == first
    others = [_worker_order(capsys, seed) for seed in (1, 2)]
    assert any(o[0] != first[0] for o in others) and any(o[1] != first[1] for o in others)
    assert all(sorted(o[1]) == sorted(first[1]) for o in others)
