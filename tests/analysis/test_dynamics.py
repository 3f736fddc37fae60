"""Batched dynamics studies: reachable sets, Lyapunov exponents, the controllability study."""
from __future__ import annotations

import numpy as np
import pytest

from penny_env.analysis.dynamics import lyapunov_exponents, random_controls, reachable_set

START = np.array([0.0, 0.0, 0.0, np.pi / 2, 10.0, 0.2])
STADIUM = {"kind": "stadium", "radius": 0.1, "length": 0.1}


@pytest.mark.parametrize("actuation, conserved", [("steer", 4), ("drive", 5)])
def test_one_control_on_the_plane_conserves_the_other_speed(actuation, conserved):
    # between impacts J phi'' = u1 and (I + m R^2) theta'' = u2: the unactuated speed never changes
    rs = reachable_set(START, 2.0, table=None, actuation=actuation, n_samples=40, seed=3)
    assert np.all(rs.final_states[:, conserved] == START[conserved])
    assert np.ptp(rs.final_states[:, 9 - conserved]) > 0.1  # the actuated one moves
    assert np.all(rs.impact_counts == 0)


@pytest.mark.parametrize("actuation, conserved", [("steer", 4), ("drive", 5)])
def test_impacts_change_the_unactuated_speed(actuation, conserved):
    rs = reachable_set(START, 1.5, table=STADIUM, actuation=actuation, n_samples=40, seed=3)
    hit = rs.impact_counts > 0
    assert hit.any() and (~hit).any()
    assert np.all(rs.final_states[~hit, conserved] == START[conserved])  # no impact: still conserved
    assert np.any(rs.final_states[hit, conserved] != START[conserved])
    lo, hi = rs.speed_ranges()["theta_dot" if conserved == 4 else "phi_dot"]
    assert hi - lo > 1.0


def test_random_controls_and_reachable_set_errors():
    u = random_controls(5, 3, actuation="steer", torque_limits=(2.0, 3.0), seed=0)
    assert u.shape == (3, 5, 2) and set(np.unique(u[..., 0])) <= {-2.0, 2.0} and np.all(u[..., 1] == 0)
    with pytest.raises(ValueError, match="actuation"):
        random_controls(2, 2, actuation="fly")
    with pytest.raises(ValueError, match="torque_limits"):
        random_controls(2, 2, torque_limits=(1.0, np.nan))
    with pytest.raises(ValueError, match="n_samples"):
        reachable_set(START, 1.0, table=None, n_samples=0)
    with pytest.raises(ValueError, match="horizon"):
        reachable_set(START, -1.0, table=None)
    with pytest.raises(ValueError, match="state"):
        reachable_set(START[:5], 1.0, table=None)
    with pytest.raises(ValueError, match="states"):  # outside the table: named by the batch API
        reachable_set(np.array([0.5, 0, 0, 0, 1, 0]), 1.0, table=STADIUM, n_samples=2)


def test_lyapunov_exponents_separate_integrable_from_chaotic():
    rng = np.random.default_rng(0)
    S = np.zeros((4, 6))
    S[:, 2:4] = rng.uniform(-np.pi, np.pi, (4, 2))
    S[:, 4] = rng.uniform(6, 12, 4)
    S[:, 5] = rng.uniform(-1, 1, 4)
    circle = lyapunov_exponents(S, 100.0, table={"kind": "circle", "radius": 0.2}, n_checkpoints=100)
    stadium = lyapunov_exponents(S, 100.0, table=STADIUM, n_checkpoints=100)
    assert circle.log_distance.shape == (100, 4) and np.all(np.isfinite(circle.exponents))
    assert np.all(circle.exponents < 0.05)  # linear separation: the fitted rate falls like log(t) / t
    assert np.nanmedian(stadium.exponents) > 3 * np.max(circle.exponents)
    with pytest.raises(ValueError, match="eps"):
        lyapunov_exponents(S, 1.0, table=None, eps=0.1)
    with pytest.raises(ValueError, match="states"):
        lyapunov_exponents(np.zeros((3, 5)), 1.0, table=None)


def test_dynamics_report_quick(reports_untouched):
    pytest.importorskip("matplotlib")
    from studies import dynamics
    tmp_path = reports_untouched
    out = tmp_path / "dynamics.md"
    dynamics.main(["--quick", "--out", "dynamics.md"])
    text = out.read_text()
    assert "| circle r = 0.2 |" in text and (tmp_path / "dynamics_reachable.png").exists()


def test_controllability_study_quick(reports_untouched):
    pytest.importorskip("matplotlib")
    from studies import controllability
    tmp_path = reports_untouched
    out = tmp_path / "controllability.md"
    rows = controllability.main(["--quick", "--out", "controllability.md"])
    plane = [r for r in rows if r["scene"] == "open plane"]
    assert plane and all(r["spread"] == 0.0 for r in plane)
    assert any(r["spread"] > 0 for r in rows if r["scene"] != "open plane")
    text = out.read_text()
    assert "exactly (spread 0 in every sample)" in text and (tmp_path / "controllability.png").exists()
