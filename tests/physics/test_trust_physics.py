"""Simulator trust (issue 12): caps bound work, never the physics; bounded work and memory per call;
honest Trajectory fields; simulate and batch.simulate bitwise equal on the same intervals."""

import numpy as np
import pytest

import penny_env as pe
import penny_env.batch as pb
from penny_env.backends.choice import available as numba_available
from penny_env.physics.flows import kinetic_energy
from penny_env.physics.laws import make_law
from penny_env.physics.params import MAX_ANGULAR_SPEED, MAX_CONTROL_DT, MIN_GAP
from penny_env.physics.scalar import (NO_ARC, advance_listing, advance_through_into, advance_through_listing, impact_buffers,
                                      impacts_of, overflowed, scalar_model)

PARAMS = pe.PennyParams()
ELASTIC = make_law("elastic")
BUILT_IN = [pe.Ellipse(0.15, 0.2), pe.Circle(0.15), pe.Stadium(0.1, 0.2)]
BACKENDS = ["python"] + (["numba"] if numba_available() else [])


def energy(states):
    return kinetic_energy(np.atleast_2d(states).T, PARAMS)


# -- item 1: the per-call event cap never changes the motion --------------------------------------
def test_elastic_penny_keeps_its_energy_past_10000_impacts():
    # the case: the free chunk (2 pi / phi_dot = 6e6 s) holds more than max_events_per_interval
    # impacts; the cap used to bring the penny to rest at impact 10000
    s0 = [0, 0, 0, 0.3, 10, 1e-6]
    tr = pe.simulate(s0, table=pe.Circle(0.15), law="elastic", n_impacts=10050)
    assert tr.n_impacts == 10050 and tr.complete
    assert len(tr.rest_times) == 0
    # round-off: each elastic impact keeps the energy to a few ulps
    rtol = 2.2e-16 * tr.n_impacts
    np.testing.assert_allclose(tr.energies(), energy(s0)[0], rtol=rtol)
    np.testing.assert_allclose(energy(tr.final_state), energy(s0), rtol=rtol)


@pytest.mark.parametrize("table", BUILT_IN + [None], ids=lambda t: type(t).__name__)
def test_elastic_energy_over_1e5_seconds_with_a_small_event_cap(table):
    """Every built-in table (and a user table through the protocol): 1e5 s, the cap hit hundreds of
    times (7 impacts per call), the energy kept to round-off and the run reaching t_final."""
    if table is None:  # a protocol object: the plain-Python OTHER path of the event loop
        table = _ProtocolEllipse(0.15, 0.2)
    s0 = [0.0, 0.0, 0.0, 0.3, 0.5, 1e-3]
    settings = pe.SolverSettings(max_events_per_interval=7)
    tr = pe.simulate(s0, table=table, law="elastic", t_final=1e5, n_impacts=50_000, settings=settings)
    assert tr.final_time == 1e5 and tr.complete
    assert tr.n_impacts > 500 and len(tr.rest_times) == 0
    np.testing.assert_allclose(tr.energies(), energy(s0)[0], rtol=1e-12)
    np.testing.assert_allclose(energy(tr.final_state), energy(s0), rtol=1e-12)


class _ProtocolEllipse:
    """A user table through the protocol (no Table subclass), same formulas as Ellipse."""

    def __init__(self, a, b):
        self._e = pe.Ellipse(a, b)
        self.grad_bound, self.hessian_bound = 1.0, 1.0 / min(a, b)
        self.inradius, self.extent = min(a, b), (-a, a, -b, b)

    def h(self, x, y):
        return self._e.h(x, y)

    def grad(self, x, y):
        return self._e.grad(x, y)


@pytest.mark.parametrize("table", BUILT_IN, ids=lambda t: type(t).__name__)
def test_event_loop_resumes_after_the_cap(table):
    """advance_listing stops at the cap right after an impact (speeds untouched, elapsed < dt);
    advance_through_listing resumes to the interval's end with the same impacts as one uncapped call."""
    s0 = (0.0, 0.0, 0.0, 0.3, 10.0, 0.2)
    capped = scalar_model(PARAMS, table, ELASTIC, pe.SolverSettings(max_events_per_interval=3))
    s, impacts, rests, elapsed = advance_listing(s0, 0.0, 0.0, 5.0, capped, 0)
    assert len(impacts) == 3 and elapsed < 5.0 and not rests
    assert elapsed == impacts[-1][0] and s == impacts[-1][2]
    assert energy(s)[0] == pytest.approx(energy(s0)[0], rel=1e-13)
    s, impacts, rests, elapsed = advance_through_listing(s0, 0.0, 0.0, 5.0, capped)
    free = advance_listing(s0, 0.0, 0.0, 5.0, scalar_model(PARAMS, table, ELASTIC, pe.SolverSettings()), 0)
    assert elapsed == 5.0 and len(impacts) == len(free[1]) > 3
    np.testing.assert_allclose([i[0] for i in impacts], [i[0] for i in free[1]], rtol=0, atol=1e-12)
    np.testing.assert_allclose(s, free[0], rtol=0, atol=1e-10)
    assert energy(s)[0] == pytest.approx(energy(s0)[0], rel=1e-13)


@pytest.mark.parametrize("backend", BACKENDS)
def test_batch_and_env_paths_resume_after_the_cap(backend):
    """Siblings: penny_env.batch.simulate (both backends) and the single penny's loop (plain and compiled)."""
    s0 = np.array([0.0, 0.0, 0.0, 0.3, 10.0, 0.2])
    settings = pe.SolverSettings(max_events_per_interval=2)
    table = pe.Ellipse(0.15, 0.2)
    res = pb.simulate(np.stack([s0, s0 * [1, 1, 1, 1, 0.5, 1]]), table=table, law="elastic", t_final=20.0,
                      settings=settings, backend=backend)
    np.testing.assert_allclose(energy(res.final_states), energy(np.stack([s0, s0 * [1, 1, 1, 1, 0.5, 1]])), rtol=1e-12)
    assert res.impact_counts.min() > 4
    if backend == "numba":  # the compiled batch equals simulate() bitwise (same intervals, same resumption)
        tr = pe.simulate(s0, table=table, law="elastic", t_final=20.0, settings=settings)
        assert np.array_equal(tr.impact_times, res.times_of(0)) and np.array_equal(tr.final_state, res.final_states[0])
    # the single penny's loop, plain or compiled (the env step resumes the same way: tests/envs/test_env_step.py)
    advance = advance_through_into
    model = scalar_model(PARAMS, table, ELASTIC, settings)
    if backend == "numba":
        from penny_env.backends import batch_entry_points
        advance = batch_entry_points("cpu", model.kind).functions["advance_through_into"]
    buf = impact_buffers(1, 64)
    s, elapsed = advance(tuple(s0), 0.0, 0.0, 5.0, model, 0, buf, 0, NO_ARC)
    impacts, rests = impacts_of(buf, 0)
    assert elapsed == 5.0 and len(impacts) > 2 and not rests and not overflowed(buf)[0]
    assert energy(s)[0] == pytest.approx(energy(s0)[0], rel=1e-13)


def test_table_barely_wider_than_the_penny_is_refused():
    """inradius R (1 + 1e-9): the two ends' impacts follow each other within the search's time
    resolution; the elastic penny used to lose all its energy after 16 impacts."""
    tight = pe.Circle(PARAMS.R * (1 + 1e-9))
    s0 = [0, 0, 0, 0.3, 1.0, 0.0]
    with pytest.raises(ValueError, match="table.*MIN_GAP"):
        pe.simulate(s0, table=tight, law="elastic", n_impacts=100)
    with pytest.raises(ValueError, match="table.*MIN_GAP"):
        pb.simulate(np.array([s0]), table=tight, law="elastic", t_final=1.0)
    from penny_env.envs.scene import ConfigError, Scene
    with pytest.raises(ConfigError, match="table.*MIN_GAP"):
        Scene(table={"kind": "circle", "radius": PARAMS.R * (1 + 1e-9)}, init={"spawn_fraction": 0.0})


def test_elastic_penny_just_above_the_gap_limit_keeps_its_energy():
    table = pe.Circle(PARAMS.R * (1 + 2 * MIN_GAP))
    s0 = [0, 0, 0, 0.3, 1.0, 0.0]
    tr = pe.simulate(s0, table=table, law="elastic", n_impacts=2000)
    assert tr.n_impacts == 2000 and len(tr.rest_times) == 0
    np.testing.assert_allclose(tr.energies(), energy(s0)[0], rtol=1e-12)


def test_dissipative_accumulation_still_comes_to_rest():
    tr = pe.simulate([0, 0, 0, 0.3, 1.0, 0.0], table=pe.Circle(PARAMS.R * 1.0001), law="plastic", n_impacts=2000)
    assert len(tr.rest_times) >= 1 and not tr.complete
    assert tr.final_state[4] == 0.0 and tr.final_state[5] == 0.0


# -- item 3: dense output of a penny at rest ---------------------------------------------------------
@pytest.mark.parametrize("kw", [dict(n_impacts=2), dict(t_final=3.0), dict(t_final=3.0, n_impacts=2)])
def test_states_at_for_a_penny_at_rest(kw):
    s0 = [0, 0, 0, 0.3, 0, 0]
    tr = pe.simulate(s0, table=pe.Ellipse(0.15, 0.2), **kw)
    out = tr.states_at([0.0, tr.final_time])
    np.testing.assert_array_equal(out, [s0, s0])


def test_states_at_matches_the_impacts_and_the_final_state():
    tr = pe.simulate([0, 0, 0, 0.3, 10, 0.2], table=pe.Stadium(0.1, 0.2), law="elastic", t_final=7.3)
    np.testing.assert_allclose(tr.states_at(tr.impact_times), tr.impact_states, rtol=0, atol=1e-12)
    np.testing.assert_allclose(tr.states_at([tr.final_time])[0], tr.final_state, rtol=0, atol=1e-12)


# -- item 4: bounded work and memory per call ---------------------------------------------------------
def _count_intervals(monkeypatch, limit=None):
    """Count the event loop's intervals simulate() runs (and the batch API's steps), failing past ``limit``: the
    work of a call measured by counts, not by wall time (issue 40, item 12)."""
    from penny_env.physics import simulation
    calls = {"simulate": 0, "batch": 0}
    run = simulation.run_interval

    def counted(*args, **kwargs):
        calls["simulate"] += 1
        assert limit is None or calls["simulate"] <= limit, f"simulate ran more than {limit} intervals"
        return run(*args, **kwargs)
    monkeypatch.setattr(simulation, "run_interval", counted)
    stepper = pb._stepper

    def counted_stepper(*args, **kwargs):
        step = stepper(*args, **kwargs)

        def counted_step(*a, **kw):
            calls["batch"] += 1
            return step(*a, **kw)
        return counted_step
    monkeypatch.setattr(pb, "_stepper", counted_stepper)
    return calls


@pytest.mark.parametrize("u1", [1.0, 1e3])
def test_huge_torques_are_refused_fast(u1, monkeypatch):
    calls = _count_intervals(monkeypatch)
    with pytest.raises(ValueError, match=r"controls\[0\].*MAX_ANGULAR_SPEED"):
        pe.simulate([0, 0, 0, 0, 1, 0], table=pe.Circle(0.2), controls=[[u1, 0.0]], control_dt=0.1)
    with pytest.raises(ValueError, match=r"controls\[0\].*MAX_ANGULAR_SPEED"):
        pb.simulate(np.array([[0, 0, 0, 0, 1, 0]]), table=pe.Circle(0.2), controls=[[u1, 0.0]], control_dt=0.1,
                    t_final=0.1)
    assert calls == {"simulate": 0, "batch": 0}  # refused before any interval ran


def test_steered_phase_limit():
    # a modest torque over a long interval at high spin: the quadrature's work grows with the phase
    with pytest.raises(ValueError, match="MAX_STEERED_PHASE"):
        pe.simulate([0, 0, 0, 0, 0, 5e3], table=None, controls=[[1e-8, 0.0]], control_dt=10.0)


def test_spin_beyond_the_limit_is_refused():
    with pytest.raises(ValueError, match="phi_dot.*MAX_ANGULAR_SPEED"):
        pe.simulate([0, 0, 0, 0, 0, 2 * MAX_ANGULAR_SPEED], table=pe.Circle(0.2), t_final=1.0)
    with pytest.raises(ValueError, match=r"states\[1\].*theta_dot"):
        pb.flow(np.array([[0, 0, 0, 0, 0, 0], [0, 0, 0, 0, -2 * MAX_ANGULAR_SPEED, 0]]), (0, 0), 1.0)


def test_long_runs_stop_at_the_impact_limit(monkeypatch):
    """t_final = 1e9 rolling between the walls (the issue's run grew past 500 MB): stops at
    SolverSettings.max_impacts with an error naming it (a small limit keeps the test fast)."""
    settings = pe.SolverSettings(max_impacts=300)
    calls = _count_intervals(monkeypatch)
    with pytest.raises(ValueError, match="t_final=1000000000.0.*max_impacts = 300"):
        pe.simulate([0, 0, 0, 0, 10, 0], table=pe.Ellipse(0.15, 0.2), t_final=1e9, settings=settings)
    with pytest.raises(ValueError, match="n_impacts=301.*max_impacts = 300"):
        pe.simulate([0, 0, 0, 0, 10, 0], table=pe.Ellipse(0.15, 0.2), n_impacts=301, settings=settings)
    with pytest.raises(ValueError, match="10 x SolverSettings.max_impacts = 3000"):
        pb.simulate(np.zeros((40, 6)) + [0, 0, 0, 0, 10, 0], table=pe.Ellipse(0.15, 0.2), t_final=500.0,
                    controls=np.zeros((50, 2)), control_dt=10.0, settings=settings)
    assert calls["simulate"] <= 300 and calls["batch"] <= 50  # at most one interval per impact, one step per control
    assert pe.SolverSettings().max_impacts <= 100_000  # memory: about 0.7 kB per recorded impact


def test_a_run_that_cannot_finish_is_refused_at_its_first_impact(monkeypatch):
    # simulate(t_final=1e12) recorded 100,000 impacts in plain Python (87 s) before its error; an elastic penny that
    # hits the wall hits it again within elastic_impact_period, so the run is refused at its first impact
    calls = _count_intervals(monkeypatch, limit=50)
    with pytest.raises(ValueError, match=r"t_final=1000000000000.0: an elastic penny that hits the wall hits it again "
                                         r"at least every .* s .*needs at least .* impacts, beyond "
                                         r"SolverSettings.max_impacts = 100000"):
        pe.simulate([0, 0, 0, 0, 10, 0], table=pe.Ellipse(0.15, 0.2), t_final=1e12)
    assert calls["simulate"] <= 2
    # a dissipative penny comes to rest: not refused, and its run is short
    tr = pe.simulate([0, 0, 0, 0, 10, 0], table=pe.Ellipse(0.15, 0.2), law="plastic", t_final=1e12)
    assert tr.final_time == 1e12 and tr.complete


@pytest.mark.parametrize("table", [pe.Ellipse(0.15, 0.2), pe.Stadium(0.1, 0.15), pe.RoundedRectangle(0.3, 0.2, 0.04),
                                   pe.Circle(0.12)], ids=repr)
def test_elastic_impact_period_bounds_the_time_between_impacts(table):
    from penny_env.physics.simulation import elastic_impact_period
    rng = np.random.default_rng(3)
    gaps = 0
    for _ in range(6):
        s0 = [rng.uniform(-0.03, 0.03), rng.uniform(-0.03, 0.03), 0.0, rng.uniform(-np.pi, np.pi),
              rng.uniform(-20, 20), rng.uniform(-5, 5)]
        times = pe.simulate(s0, table=table, t_final=20.0).impact_times  # (a penny spinning in place has none)
        # the geometric bound: half the returned period, which doubles it for round-off
        assert np.all(np.diff(times) <= 0.5 * elastic_impact_period(s0, pe.PennyParams(), table))
        gaps += max(0, len(times) - 1)
    assert gaps > 20


def test_long_impact_free_runs_are_cheap(monkeypatch):
    calls = _count_intervals(monkeypatch)
    for s0, table in (([0, 0, 0, 0, 0, 1e-6], pe.Ellipse(0.15, 0.2)), ([0, 0, 0, 0, 0, 0], pe.Circle(0.2)),
                      ([0, 0, 0, 0, 1, 1], None)):
        tr = pe.simulate(s0, table=table, t_final=1e9)
        assert tr.final_time == 1e9 and tr.complete and tr.n_impacts == 0
    assert calls["simulate"] <= 3  # one free period each, then one flow to t_final


def test_batch_refuses_too_many_intervals():
    with pytest.raises(ValueError, match="t_final.*MAX_INTERVALS"):
        pb.simulate(np.array([[0, 0, 0, 0, 1, 0]]), table=pe.Circle(0.2), t_final=1e9)


@pytest.mark.parametrize("kw, match", [
    (dict(control_dt=1000.0), "control_dt.*MAX_CONTROL_DT"),
    (dict(torque_limits={"u1": 1e3}), "torque_limits.u1.*MAX_ANGULAR_SPEED"),
    (dict(torque_limits={"u2": 10.0}), "torque_limits.u2.*MAX_ANGULAR_SPEED"),
    (dict(torque_limits={"u1": 1e-4}, control_dt=MAX_CONTROL_DT), "torque_limits.u1.*MAX_STEERED_PHASE"),
])
def test_env_scene_refuses_actuation_beyond_the_limits(kw, match):
    gym = pytest.importorskip("gymnasium", reason="the environments need gymnasium")
    from penny_env.envs.scene import ConfigError
    with pytest.raises(ConfigError, match=match):
        gym.make("PennyReach-Ellipse-v0", **kw)


# -- item 6: complete, and simulate == batch.simulate bitwise -----------------------------------------
def test_complete_is_true_when_t_final_is_reached():
    tr = pe.simulate([0, 0, 0, 0.3, 10, 0.2], table=pe.Ellipse(0.15, 0.2), t_final=3.0)
    assert tr.complete and tr.final_time == 3.0
    # spinning in place clear of the wall: t_final reached, n_impacts never
    tr = pe.simulate([0, 0, 0, 0.3, 0, 1.0], table=pe.Ellipse(0.15, 0.2), t_final=50.0)
    assert tr.complete and tr.final_time == 50.0 and tr.n_impacts == 0
    tr = pe.simulate([0, 0, 0, 0.3, 0, 1.0], table=pe.Ellipse(0.15, 0.2), n_impacts=3)
    assert not tr.complete and tr.n_impacts == 0
    tr = pe.simulate([0, 0, 0, 0.3, 0, 1.0], table=pe.Ellipse(0.15, 0.2), n_impacts=3, t_final=50.0)
    assert tr.complete and tr.final_time == 50.0


@pytest.mark.parametrize("table", BUILT_IN, ids=lambda t: type(t).__name__)
@pytest.mark.parametrize("law, backend", [("elastic", b) for b in BACKENDS] + [("plastic", "auto"), (0.7, "auto")])
def test_simulate_and_batch_are_bitwise_equal(backend, table, law):
    """The README's penny: simulate and batch.simulate take the same intervals (control intervals, or
    FREE_INTERVAL steps for a run to t_final), hence bitwise the same impacts and final state."""
    s0 = np.array([0.0, 0.0, 0.0, np.pi / 2, 10.0, 0.2])
    u = np.random.default_rng(1).normal(size=(140, 2)) * 1e-8
    for kw in (dict(t_final=20.0), dict(controls=u, control_dt=0.15, t_final=20.0)):
        tr = pe.simulate(s0, table=table, law=law, **kw)
        res = pb.simulate(s0[None], table=table, law=law, backend=backend, **kw)
        assert tr.n_impacts > 5
        assert np.array_equal(tr.impact_times, res.impact_times)
        assert np.array_equal(tr.impact_states, res.impact_states)
        assert np.array_equal(tr.final_state, res.final_states[0])


def test_advance1_runs_the_whole_interval_unless_told_to_stop():
    """Callers that take advance_interval's state as the interval's end (analysis.baselines) get the whole
    interval: advance_interval resumes past the event cap unless stop_after is given."""
    from penny_env.physics.scalar import advance_interval
    s0 = (0.0, 0.0, 0.0, 0.3, 10.0, 0.2)
    settings = pe.SolverSettings(max_events_per_interval=2)
    table = pe.Circle(0.15)
    s, impacts, _, elapsed = advance_interval(s0, 0.0, 0.0, 10.0, PARAMS, table, ELASTIC, settings)
    assert elapsed == 10.0 and len(impacts) > 2
    s, impacts, _, elapsed = advance_interval(s0, 0.0, 0.0, 10.0, PARAMS, table, ELASTIC, settings, stop_after=5)
    assert elapsed < 10.0 and len(impacts) == 2  # the cap comes first; the caller resumes
