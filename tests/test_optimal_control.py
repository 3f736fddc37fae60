"""Trajectory optimisation with and without impacts (training/optimal_control.py)."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("scipy", reason="the optimal-control study solves with scipy.optimize")

from training import optimal_control as oc  # noqa: E402

START = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0])


def test_bad_inputs_name_the_field():
    with pytest.raises(ValueError, match="target"):
        oc.Problem("ellipse", "reach", START, [0.2, 0.0], impacts=True)
    with pytest.raises(ValueError, match="margin"):
        oc.Problem("ellipse", "reach", START, [0.0, 0.05], impacts=False, margin=0.2)
    with pytest.raises(ValueError, match="margin"):
        oc.Problem("ellipse", "reach", START, [0.0, 0.05], impacts=False, margin=-0.001)
    with pytest.raises(TypeError, match="margin"):
        oc.Problem("ellipse", "reach", START, [0.0, 0.05], impacts=False, margin="0.01")
    with pytest.raises(ValueError, match="start"):
        oc.Problem("ellipse", "reach", [0.0, 0.185, 0.0, np.pi / 2, 0.0, 0.0], [0.0, 0.05], impacts=False)
    with pytest.raises(ValueError, match="scene"):
        oc.Problem("moon", "reach", START, [0.0, 0.05], impacts=True)
    prob = oc.Problem("ellipse", "reach", START, [0.0, 0.05], impacts=True)
    with pytest.raises(ValueError, match="rows"):
        oc.solve_rows(prob, 0)
    with pytest.raises(ValueError, match="rows"):
        oc.solve_rows(prob, oc.MAX_ROWS + 1)
    with pytest.raises(TypeError, match="rows"):
        oc.solve_rows(prob, 2.5)


def test_solution_is_verified_and_failures_are_kept():
    s, target = oc.draw_pairs("ellipse", "reach", 2, seed=0)[1]
    for impacts in (True, False):
        sol = oc.solve_rows(oc.Problem("ellipse", "reach", s, target, impacts=impacts), oc.EFFORT_ROWS, maxiter=100)
        assert sol.ok, sol.status
        assert sol.distance <= 0.015 * (1 + 1e-6) and np.all(np.abs(sol.controls) <= oc.Problem(
            "ellipse", "reach", s, target, impacts=True).limits * (1 + 1e-9))
        if not impacts:
            assert sol.impacts == 0
    # one row of 0.05 s cannot carry the penny 0.1 m from rest: reported as failed, not dropped
    far = oc.solve_rows(oc.Problem("ellipse", "reach", START, [0.0, 0.1], impacts=True), 1, maxiter=50)
    assert not far.ok and far.status.startswith("failed")
    rows = [{"scene": "ellipse", "task": "reach", "objective": "effort", "pair": 0, "with": far, "without": far}]
    summary = oc.summarise(rows)
    assert summary[0]["pairs"] == 1 and summary[0]["ok_with"] == 0 and summary[0]["both"] == 0


def test_minimum_time_is_the_fewest_rows():
    prob = oc.Problem("ellipse", "park", START, [0.0, 0.0], impacts=False)
    sol = oc.minimum_time(prob, max_rows=4, maxiter=50)
    assert sol.ok and sol.rows == 1  # already parked at the target: one row of zero torque


def test_quick_run_writes_report_outside_docs(tmp_path):
    out = oc.main(["--quick", "--workers", "2", "--out", str(tmp_path / "oc.md")])
    text = out.read_text()
    assert "| ellipse | reach | effort | both | 2 |" in text and "Failed solves" in text
    with pytest.raises(SystemExit):
        oc.main(["--quick", "--out", str(oc.Path(oc.__file__).resolve().parents[1] / "docs" / "x.md")])
    with pytest.raises(SystemExit):
        oc.main(["--pairs", "0"])
