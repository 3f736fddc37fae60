"""The per-penny event loop (single env, simulate) and its batch runs (advance_pennies, plain Python
and compiled) agree bitwise."""
import numpy as np
from hypothesis import given, strategies as st

import penny_env as pe
from penny_env.backends.pennies import advance_pennies
from penny_env.physics import flow
from penny_env.physics.laws import make_law
from penny_env.backends.choice import available
from penny_env.physics.params import SolverSettings
from penny_env.physics.scalar import advance_interval, flow_penny
from conftest import random_inside_state, random_pennies

TABLES = [pe.Circle(0.2), pe.Ellipse(0.15, 0.2), pe.Stadium(0.08, 0.15), pe.Ellipse(0.03, 0.011),
          pe.RoundedRectangle(0.3, 0.2, 0.05)]
LAWS = ["elastic", "plastic", 0.4]
# the batch runs compiled where numba is installed (the plain-Python batch is advance_interval in a loop)
BACKEND = "numba" if available() else "python"


@given(seed=st.integers(0, 2**31 - 1), table=st.sampled_from(TABLES), law=st.sampled_from(LAWS),
       steer=st.booleans(), dt=st.sampled_from([0.05, 0.5, 3.0]))
def test_advance_scalar_equals_batch(seed, table, law, steer, dt):
    n = 5
    rng, params, law, S, acc1, acc2 = random_pennies(seed, table, law, n, steer)
    settings = SolverSettings()
    batch, log, elapsed = advance_pennies(S, acc1, acc2, dt, params, table, law, settings, backend=BACKEND)
    for i in range(n):
        s1, impacts, rests, el = advance_interval(tuple(S[:, i]), acc1[i], acc2[i], dt, params, table, law, settings)
        assert np.array_equal(np.array(s1), batch[:, i])
        mine = log.env == i
        assert [t for t, _, _ in impacts] == list(log.time[mine])
        assert [e for _, e, _ in impacts] == list(log.end[mine])
        assert np.array_equal(np.array([p for _, _, p in impacts]).reshape(-1, 6), log.state[mine])
        assert el == elapsed[i]


@given(seed=st.integers(0, 2**31 - 1), steer=st.booleans())
def test_flow_scalar_equals_batch(seed, steer):
    rng = np.random.default_rng(seed)
    n = 6
    S = rng.normal(size=(6, n)) * np.array([1, 1, 3, 3, 100, 50])[:, None]
    acc1 = rng.normal(0, 10, n) * steer
    acc2 = rng.normal(0, 10, n)
    t = rng.uniform(0, 5, n)
    batch = flow(S, acc1, acc2, t, 0.01)
    for i in range(n):
        assert np.array_equal(np.array(flow_penny(tuple(S[:, i]), acc1[i], acc2[i], t[i], 0.01)), batch[:, i])


def test_batch_result_independent_of_batch_composition():
    rng = np.random.default_rng(3)
    params, table, law = pe.PennyParams(), pe.Ellipse(0.15, 0.2), make_law("elastic")
    S = np.stack([random_inside_state(rng, params, table) for _ in range(8)], axis=1)
    acc1, acc2 = rng.normal(0, 2, 8), rng.normal(0, 2, 8)
    full, _, _ = advance_pennies(S, acc1, acc2, 1.0, params, table, law, SolverSettings(), backend=BACKEND)
    part, _, _ = advance_pennies(S[:, 2:5], acc1[2:5], acc2[2:5], 1.0, params, table, law, SolverSettings(), backend=BACKEND)
    assert np.array_equal(full[:, 2:5], part)
