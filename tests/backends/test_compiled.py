"""The compiled backend (numba) runs physics/scalar.py's functions: it must give the plain-Python
per-penny loop's results bitwise (advance_pennies(backend="python") and advance_interval), impacts included,
and refuse what it cannot compile."""
import math

import numpy as np
import pytest
from hypothesis import given, settings as hsettings, strategies as st

import penny_env as pe
from penny_env.backends.pennies import advance_pennies
from penny_env.physics import flow
from penny_env.backends import batch_entry_points
from penny_env.backends.batch import IMPACT_CAPACITY, CompiledBatch
from penny_env.backends.choice import available
from penny_env.physics.kernels import MEDIUM_ANGLE, SMALL_ANGLE, cis_medium, cis_small
from penny_env.physics.laws import make_law
from penny_env.physics.params import SolverSettings
from penny_env.physics.scalar import advance_interval, flow_penny
from conftest import random_inside_state, random_pennies

pytestmark = pytest.mark.skipif(not available(), reason="numba is not installed")

TABLES = [pe.Circle(0.2), pe.Ellipse(0.15, 0.2), pe.Stadium(0.08, 0.15), pe.Ellipse(0.03, 0.011), pe.Stadium(0.05, 0.0),
          pe.RoundedRectangle(0.3, 0.2, 0.05), pe.RoundedRectangle(0.06, 0.025, 0.012)]
LAWS = ["elastic", "plastic", 0.4]
SET = SolverSettings()


@hsettings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), table=st.sampled_from(TABLES), law=st.sampled_from(LAWS),
       steer=st.booleans(), dt=st.sampled_from([0.05, 0.5, 3.0]))
def test_compiled_equals_python_loop_and_scalar(seed, table, law, steer, dt):
    n = 6
    rng, params, law, S, acc1, acc2 = random_pennies(seed, table, law, n, steer)
    ref, log, _ = advance_pennies(S, acc1, acc2, dt, params, table, law, SET, backend="python")
    trig = np.empty((4, n))
    out, clog = CompiledBatch(params, table, law, SET).states_and_impacts(S, acc1, acc2, dt, trig)
    assert np.array_equal(out, ref)
    assert np.array_equal(trig, np.stack([np.cos(ref[2]), np.sin(ref[2]), np.cos(ref[3]), np.sin(ref[3])]))
    if log.env.size == 0:
        assert clog is None
    else:
        env, times, ends, posts = clog
        assert np.array_equal(env, log.env) and np.array_equal(times, log.time)
        assert np.array_equal(ends, log.end) and np.array_equal(posts, log.state)
    i = int(rng.integers(n))
    s1, impacts, _, _ = advance_interval(tuple(S[:, i]), acc1[i], acc2[i], dt, params, table, law, SET)
    assert np.array_equal(np.array(s1), out[:, i])


def test_impact_buffer_overflow_is_complete():
    # long intervals in a small table: far more impacts per penny than the per-call buffer holds
    rng = np.random.default_rng(3)
    params, table, law = pe.PennyParams(), pe.Ellipse(0.03, 0.011), make_law("elastic")
    S = np.stack([random_inside_state(rng, params, table) for _ in range(5)], axis=1)
    acc1, acc2 = rng.normal(0, 3, 5), rng.normal(0, 3, 5)
    ref, log, _ = advance_pennies(S, acc1, acc2, 3.0, params, table, law, SET, backend="python")
    out, (env, times, ends, posts) = CompiledBatch(params, table, law, SET).states_and_impacts(S, acc1, acc2, 3.0)
    assert np.bincount(log.env).max() > IMPACT_CAPACITY
    assert np.array_equal(out, ref) and np.array_equal(times, log.time) and np.array_equal(posts, log.state)


@given(seed=st.integers(0, 2**31 - 1), steer=st.booleans())
def test_compiled_flow_on_the_plane_equals_numpy_flow(seed, steer):
    rng = np.random.default_rng(seed)
    S = rng.normal(size=(6, 7)) * np.array([0.1, 0.1, 1, 3, 20, 10])[:, None]
    acc1, acc2 = rng.normal(0, 10, 7) * steer, rng.normal(0, 40, 7)
    out, log = CompiledBatch(pe.PennyParams(), None, make_law("elastic"), SET).states_and_impacts(S, acc1, acc2, 0.37)
    assert log is None
    assert np.array_equal(out, flow(S, acc1, acc2, 0.37, 0.01))
    fns = batch_entry_points("cpu", -1).functions  # the open plane's variant
    s0 = tuple(S[:, 0])
    assert fns["flow_penny"](s0, acc1[0], acc2[0], 0.37, 0.01) == flow_penny(s0, acc1[0], acc2[0], 0.37, 0.01)


@pytest.mark.parametrize("cis, limit", [(cis_small, SMALL_ANGLE), (cis_medium, MEDIUM_ANGLE)])
@hsettings(max_examples=300)
@given(u=st.floats(-1.0, 1.0))
def test_small_angle_polynomials_match_libm(cis, limit, u):
    z = u * limit
    c, s = cis(z, pe.physics.kernels.SCALAR)
    assert abs(c - math.cos(z)) <= 2.3e-16 and abs(s - math.sin(z)) <= 2 * math.ulp(max(abs(z), 1e-300)) + 1e-300
    arr = np.array([z, -z, 0.5 * z])
    ca, sa = cis(arr)
    assert ca[0] == c and sa[0] == s  # numpy and floats: the same operations
    cc, sc = batch_entry_points("cpu", -1).functions[cis.__name__](z)
    assert cc == c and sc == s  # and compiled


def test_batch_refuses_tables_that_do_not_compile():
    # (the environments' backend tests moved to tests/envs/test_env_step.py)
    table = pe.ConvexTable(lambda x, y: (x * x + y * y - 0.01) / 0.2, lambda x, y: (x / 0.1, y / 0.1), grad_bound=1.0,
                           hessian_bound=10.0, extent=(-0.11, 0.11, -0.11, 0.11))
    with pytest.raises(ValueError, match="table"):
        CompiledBatch(pe.PennyParams(), table, make_law("elastic"), SET)


@pytest.mark.parametrize("table, law", [({"kind": "stadium", "radius": 0.1, "length": 0.1}, "elastic"),
                                        ({"kind": "ellipse", "a": 0.15, "b": 0.2}, "plastic"), (None, "elastic")])
def test_batch_simulate_backends_agree(table, law):
    import penny_env.batch as pb
    rng = np.random.default_rng(5)
    S = np.zeros((40, 6))
    S[:, 2:4] = rng.uniform(-3, 3, (40, 2))
    S[:, 4] = rng.uniform(-15, 15, 40)
    S[:, 5] = rng.uniform(-2, 2, 40)
    u = rng.choice((-1.0, 1.0), (30, 40, 2)) * np.array([6.25e-7, 1.5e-5])
    out = [pb.simulate(S, table=table, law=law, t_final=1.5, controls=u, control_dt=0.05, backend=b)
           for b in ("numba", "python")]
    for field in ("final_states", "impact_counts", "impact_env", "impact_times", "impact_ends", "impact_states"):
        assert np.array_equal(getattr(out[0], field), getattr(out[1], field)), field
    assert table is None or out[0].impact_counts.sum() > 0
    with pytest.raises(ValueError, match="backend"):
        pb.simulate(S, table=table, t_final=1.0, backend="gpu")


@pytest.mark.parametrize("table", TABLES, ids=repr)
def test_first_impacts_compiled_equal_python(table):
    # the batch API's first_impact: the per-penny certified search, compiled in parallel and plain, bitwise
    import penny_env.batch as pb
    rng = np.random.default_rng(8)
    params = pe.PennyParams()
    S = np.stack([random_inside_state(rng, params, table) for _ in range(12)])
    u = rng.normal(0, 1, (12, 2)) * np.array([params.J, params.rolling_inertia]) * 3
    u[:4, 0] = 0.0
    horizon = rng.uniform(0.01, 5.0, 12)
    a = pb.first_impact(S, u, horizon, table=table, backend="numba")
    b = pb.first_impact(S, u, horizon, table=table, backend="python")
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    assert np.isfinite(a[0]).any()


def test_compiled_functions_take_a_table_kind_and_name_each_variant_apart():
    from penny_env.backends import physics as compiled
    from penny_env.physics.tables import COMPILED_FORMULAS
    with pytest.raises(TypeError, match="kind"):
        batch_entry_points("cpu", True)
    with pytest.raises(ValueError, match="kind"):
        batch_entry_points("cpu", len(COMPILED_FORMULAS))
    with pytest.raises(ValueError, match="kind"):
        batch_entry_points("cpu", -2)
    # numba's cache files are named after the variant: one name per kind, not the registry's index
    names = [compiled.variant_name(k) for k in range(-1, len(COMPILED_FORMULAS))]
    assert len(set(names)) == len(names) and "stadium_stadium_terms" in names
