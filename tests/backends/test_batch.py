"""penny_env.batch: batched physics API against the single-trajectory simulate()."""
import numpy as np
import pytest

import penny_env as pe
import penny_env.batch as pb
from penny_env.physics import PennyParams, simulate

CIRCLE = {"kind": "circle", "radius": 0.2}
STATES = np.array([[0.0, 0.0, 0.0, np.pi / 2, 10.0, 0.2],
                   [0.05, -0.02, 1.0, 0.3, -8.0, 1.0],
                   [-0.1, 0.05, 0.0, 2.0, 12.0, -0.5]])


def test_simulate_matches_single_simulate():
    res = pb.simulate(STATES, table=CIRCLE, law="elastic", t_final=8.0)
    assert res.final_states.shape == (3, 6)
    for i, s in enumerate(STATES):
        tr = simulate(s, table=pb.make_table(CIRCLE), law="elastic", t_final=8.0)
        assert res.impact_counts[i] == tr.n_impacts > 0
        assert np.allclose(res.times_of(i), tr.impact_times, rtol=1e-9, atol=1e-12)
        assert np.allclose(res.final_states[i], tr.final_state, rtol=1e-8, atol=1e-10)


def test_simulate_with_controls_and_doctest_doc():
    u = np.zeros((40, 3, 2))
    u[:, :, 1] = 1e-6
    res = pb.simulate(STATES, table=CIRCLE, law="plastic", t_final=2.0, controls=u, control_dt=0.05)
    tr = simulate(STATES[1], table=pb.make_table(CIRCLE), law="plastic", controls=u[:, 1], control_dt=0.05)
    assert res.impact_counts[1] == tr.n_impacts
    assert np.allclose(res.final_states[1], tr.final_state, rtol=1e-8, atol=1e-10)
    shared = pb.simulate(STATES, table=None, t_final=1.0, controls=[[1e-7, 0.0]] * 20, control_dt=0.05)
    assert (shared.impact_counts == 0).all()


def test_flow_first_impact_impact_map():
    P = PennyParams()
    out = pb.flow(STATES, [0.0, 0.0], 0.5)
    assert out.shape == (3, 6)
    t_hit, end = pb.first_impact(STATES, [0.0, 0.0], 5.0, table=CIRCLE)
    assert np.all(np.isfinite(t_hit)) and set(end.tolist()) <= {1, -1}
    pre = pb.flow(STATES, [0.0, 0.0], t_hit)
    post = pb.impact_map(pre, end, table=CIRCLE, law="elastic")
    def ke(s):
        return 0.5 * (P.rolling_inertia * s[:, 4] ** 2 + P.J * s[:, 5] ** 2)
    assert np.allclose(ke(post), ke(pre), rtol=1e-12)


@pytest.mark.fast
def test_errors_name_field_and_row():
    bad = STATES.copy()
    bad[1, 3] = np.nan
    with pytest.raises(ValueError, match=r"states\[1\] has a non-finite phi"):
        pb.flow(bad, [0, 0], 1.0)
    with pytest.raises(ValueError, match="shape"):
        pb.flow(STATES[:, :5], [0, 0], 1.0)
    with pytest.raises(ValueError, match=r"controls\[2\]"):
        pb.flow(STATES, [[0, 0], [0, 0], [np.inf, 0]], 1.0)
    with pytest.raises(ValueError, match=r"t\[0\]"):
        pb.flow(STATES, [0, 0], [-1.0, 1.0, 1.0])
    far = STATES.copy()
    far[2, 0] = 0.5
    with pytest.raises(ValueError, match=r"states\[2\].*outside"):
        pb.simulate(far, table=CIRCLE, t_final=1.0)
    with pytest.raises(ValueError, match=r"ends\[0\]"):
        pb.impact_map(STATES, [0, 1, 1], table=CIRCLE)
    with pytest.raises(ValueError, match=r"states\[0\].*not on the wall"):
        pb.impact_map(STATES, 1, table=CIRCLE)
    with pytest.raises(ValueError, match="table"):
        pb.simulate(STATES, table={"kind": "hexagon"}, t_final=1.0)
    with pytest.raises(ValueError, match="horizon"):
        pb.simulate(STATES, table=CIRCLE, t_final=2.0, controls=np.zeros((3, 2)), control_dt=0.05)


def test_first_impact_resumes_after_its_step_budget():
    # a search cut short by max_search_steps resumes from the time it certified: same impacts
    from penny_env import batch
    rng = np.random.default_rng(5)
    table = pe.Ellipse(0.15, 0.2)
    S = np.array([[rng.uniform(-0.05, 0.05), rng.uniform(-0.05, 0.05), 0, rng.uniform(0, 6), rng.uniform(5, 20),
                   rng.uniform(-0.5, 0.5)] for _ in range(12)])
    t0, e0 = batch.first_impact(S, [0.0, 0.0], 60.0, table=table)
    t1, e1 = batch.first_impact(S, [0.0, 0.0], 60.0, table=table, settings=pe.SolverSettings(max_search_steps=2))
    assert np.array_equal(e0, e1) and np.isfinite(t0).sum() >= 6
    np.testing.assert_allclose(t1, t0, rtol=1e-12)
