"""Bad input gets a clear error naming the field; nothing silent."""
import math

import numpy as np
import pytest

import penny_env as pe


@pytest.mark.parametrize("field", ["R", "m", "I", "J"])
@pytest.mark.parametrize("value", [0.0, -1.0, math.nan, math.inf])
def test_params_reject_non_positive_or_non_finite(field, value):
    with pytest.raises(ValueError, match=field):
        pe.PennyParams(**{field: value})


def test_params_reject_strings():
    with pytest.raises(TypeError, match="R"):
        pe.PennyParams(R="big")


def test_paper_defaults():
    p = pe.PennyParams()
    assert (p.R, p.m, p.I, p.J) == (0.01, 0.0025, 1.25e-7, 6.25e-8)


@pytest.mark.parametrize("make, field", [
    (lambda: pe.Ellipse(-1.0, 0.2), "a"), (lambda: pe.Ellipse(0.2, math.nan), "b"),
    (lambda: pe.Circle(0.0), "r"), (lambda: pe.Stadium(0.0, 0.1), "radius"),
    (lambda: pe.Stadium(0.1, -0.1), "length"), (lambda: pe.Stadium(0.1, math.inf), "length"),
])
def test_invalid_table_geometry(make, field):
    with pytest.raises(ValueError, match=field):
        make()


@pytest.mark.parametrize("table", [pe.Circle(0.009), pe.Ellipse(0.5, 0.01), pe.Stadium(0.005, 1.0)])
def test_table_too_small_for_the_penny(table, paper_state):
    s = paper_state
    s[:2] = 0
    with pytest.raises(ValueError, match="too small"):
        pe.simulate(s, table=table, law="elastic", t_final=1.0)


@pytest.mark.parametrize("state, match", [
    ([0, 0, 0, 0, 1], "shape"), (np.zeros((2, 6)), "shape"), ([0, 0, 0, math.nan, 1, 0], "phi"),
    ([0, 0, math.inf, 0, 1, 0], "theta"), ([0, 0, 0, 0, 1, -math.inf], "phi_dot"),
    ([0.195, 0, 0, 0, 1, 0], "front end is outside"), ([-0.195, 0, 0, 0, 1, 0], "back end is outside"),
    ([1.0, 1.0, 0, 0, 1, 0], "outside"),
])
def test_bad_states(state, match):
    with pytest.raises(ValueError, match=match):
        pe.simulate(state, table=pe.Circle(0.2), law="elastic", t_final=1.0)


def test_state_of_wrong_type():
    with pytest.raises(TypeError, match="state"):
        pe.simulate(["a", 0, 0, 0, 0, 0], table=pe.Circle(0.2), t_final=1.0)


@pytest.mark.parametrize("law, exc", [("bouncy", ValueError), (1.5, ValueError), (-0.1, ValueError),
                                      (math.nan, ValueError), (None, TypeError), (True, TypeError)])
def test_bad_law(law, exc, paper_state):
    with pytest.raises(exc, match="law"):
        pe.simulate(paper_state, table=pe.Circle(0.2), law=law, t_final=1.0)


@pytest.mark.parametrize("kwargs, match", [
    ({}, "t_final or n_impacts"), ({"t_final": -1.0}, "t_final"), ({"t_final": math.nan}, "t_final"),
    ({"n_impacts": 0}, "n_impacts"), ({"n_impacts": 2.5}, "n_impacts"),
    ({"controls": [[0, 0]], "control_dt": 0.0}, "control_dt"), ({"controls": [[0, 0]]}, "control_dt"),
    ({"controls": [[0, 0, 0]], "control_dt": 0.1}, "controls"), ({"controls": [[0, math.nan]], "control_dt": 0.1}, "controls"),
    ({"controls": [[0, 0]], "control_dt": 0.1, "t_final": 5.0}, "t_final"), ({"control_dt": 0.1, "t_final": 1.0}, "control_dt"),
])
def test_bad_horizons_and_controls(kwargs, match, paper_state):
    with pytest.raises((ValueError, TypeError), match=match):
        pe.simulate(paper_state, table=pe.Circle(0.2), law="elastic", **kwargs)


def test_n_impacts_needs_a_table(paper_state):
    with pytest.raises(ValueError, match="n_impacts needs a table"):
        pe.simulate(paper_state, table=None, n_impacts=3)


def test_impact_map_requires_the_end_on_the_wall():
    s = [0.0, 0.0, 0.0, 0.0, 1.0, 0.0]
    with pytest.raises(ValueError, match="front end is not on the wall"):
        pe.impact_map(s, table=pe.Circle(0.2), end=1, law="elastic")
    with pytest.raises(ValueError, match="end must be"):
        pe.impact_map([0.19, 0, 0, 0, 1, 0], table=pe.Circle(0.2), end=0, law="elastic")


def test_custom_table_with_wrong_gradient_is_refused():
    with pytest.raises(ValueError, match="grad"):
        pe.ConvexTable(lambda x, y: x * x + y * y - 1, lambda x, y: (x, y), grad_bound=2.0, hessian_bound=2.0,
                       extent=(-2, 2, -2, 2))


def test_custom_table_with_too_small_bound_is_refused():
    with pytest.raises(ValueError, match="hessian_bound"):
        pe.ConvexTable(lambda x, y: x * x + y * y - 1, lambda x, y: (2 * x, 2 * y), grad_bound=2.0, hessian_bound=1.0,
                       extent=(-2, 2, -2, 2))
    with pytest.raises(ValueError, match="grad_bound"):
        pe.ConvexTable(lambda x, y: x * x + y * y - 1, lambda x, y: (2 * x, 2 * y), grad_bound=1.0, hessian_bound=2.0,
                       extent=(-2, 2, -2, 2))


def test_non_convex_custom_table_is_refused():
    # an annulus-like wall function: h = (r - 1)^2 - 0.25 on a box: region 0.5 < r < 1.5 is not convex
    h = lambda x, y: (np.hypot(x, y) - 1) ** 2 - 0.25  # noqa: E731
    def grad(x, y):
        r = np.hypot(x, y) + 1e-300
        return 2 * (r - 1) * x / r, 2 * (r - 1) * y / r
    with pytest.raises(ValueError):
        pe.ConvexTable(h, grad, grad_bound=1.0, hessian_bound=50.0, extent=(-2, 2, -2, 2))


# -- the type/value matrix (issue 12 item 5): wrong types are TypeErrors, bad values ValueErrors, both
# naming the field; numeric strings, complex numbers, booleans and None are wrong types -------------
hypothesis = pytest.importorskip("hypothesis", reason="the type/value matrix uses hypothesis")
from hypothesis import given, settings as hyp_settings, strategies as st  # noqa: E402

import penny_env.batch as pb  # noqa: E402

WRONG_TYPES = st.one_of(
    st.booleans(), st.sampled_from([np.True_, np.False_]), st.floats(0.01, 1.0).map(str), st.text(max_size=3),
    st.complex_numbers(min_magnitude=0.01, max_magnitude=1.0, allow_nan=False, allow_infinity=False),
    st.none(), st.builds(object))
BAD_VALUES = st.sampled_from([math.nan, math.inf, -math.inf, -1.0, 0.0, np.float64(-2.0)])
STATE = [0.0, 0.0, 0.0, 0.3, 1.0, 0.2]
CIRCLE = pe.Circle(0.2)


def _call_scalar(field, value):
    """Put value into one scalar field of the public API."""
    if field in ("R", "m", "I", "J"):
        return pe.PennyParams(**{field: value})
    if field in ("contact_tol", "zeno_window", "zeno_impacts", "max_search_steps", "max_events_per_interval",
                 "max_impacts"):
        return pe.SolverSettings(**{field: value})
    if field in ("Ellipse.a", "Ellipse.b"):
        return pe.Ellipse(**{"a": 0.15, "b": 0.2, field[-1]: value})
    if field == "Circle.r":
        return pe.Circle(value)
    if field == "Stadium.radius":
        return pe.Stadium(value, 0.1)
    if field == "Stadium.length":
        return pe.Stadium(0.1, value)
    if field == "t_final":
        return pe.simulate(STATE, table=CIRCLE, t_final=value)
    if field == "n_impacts":
        return pe.simulate(STATE, table=CIRCLE, n_impacts=value)
    if field == "control_dt":
        return pe.simulate(STATE, table=CIRCLE, controls=[[0.0, 0.0]], control_dt=value)
    if field == "batch t_final":
        return pb.simulate([STATE], table=CIRCLE, t_final=value)
    if field == "batch control_dt":
        return pb.simulate([STATE], table=CIRCLE, t_final=0.1, controls=[[0.0, 0.0]], control_dt=value)
    raise AssertionError(field)


SCALAR_FIELDS = ["R", "m", "I", "J", "contact_tol", "zeno_window", "zeno_impacts", "max_search_steps",
                 "max_events_per_interval", "max_impacts", "Ellipse.a", "Ellipse.b", "Circle.r", "Stadium.radius",
                 "Stadium.length", "t_final", "n_impacts", "control_dt", "batch t_final", "batch control_dt"]


def _name(field):
    return field.split(".")[-1].split(" ")[-1]


@hyp_settings(max_examples=300, deadline=None)
@given(field=st.sampled_from(SCALAR_FIELDS), value=WRONG_TYPES)
def test_scalar_fields_refuse_wrong_types(field, value):
    if value is None and field in ("t_final", "n_impacts", "control_dt", "batch control_dt"):
        return  # optional arguments: None means not given
    with pytest.raises(TypeError, match=_name(field)):
        _call_scalar(field, value)


@hyp_settings(max_examples=200, deadline=None)
@given(field=st.sampled_from(SCALAR_FIELDS), value=BAD_VALUES)
def test_scalar_fields_refuse_bad_values(field, value):
    if field == "Stadium.length" and value == 0.0:
        return  # a stadium of length 0 is a circle
    if field in ("zeno_impacts", "max_search_steps", "max_events_per_interval", "max_impacts", "n_impacts"):
        value = int(-1 if not math.isfinite(value) else value)  # integer fields: bad integers
    with pytest.raises(ValueError, match=_name(field)):
        _call_scalar(field, value)


@pytest.mark.parametrize("field, value", [("Ellipse.a", 1e-300), ("Ellipse.b", 1e300), ("Circle.r", 5e-324),
                                          ("Stadium.radius", 1e-200), ("Stadium.length", 1e200)])
def test_extreme_table_sizes_are_value_errors(field, value):
    with pytest.raises(ValueError, match=_name(field)):  # was ZeroDivisionError for Ellipse(1e-300, 1)
        _call_scalar(field, value)


ARRAY_INPUTS = {
    "state": lambda v: pe.simulate(v, table=CIRCLE, t_final=0.1),
    "impact_map state": lambda v: pe.impact_map(v, table=CIRCLE, end=1),
    "controls": lambda v: pe.simulate(STATE, table=CIRCLE, controls=[v[:2]], control_dt=0.1),
    "states": lambda v: pb.simulate([STATE, v], table=CIRCLE, t_final=0.1),
    "batch controls": lambda v: pb.simulate([STATE], table=CIRCLE, t_final=0.1, controls=[v[:2]], control_dt=0.1),
    "flow controls": lambda v: pb.flow([STATE], v[:2], 0.1),
    "flow t": lambda v: pb.flow([STATE], (0.0, 0.0), v[:1]),
    "first_impact horizon": lambda v: pb.first_impact([STATE], (0.0, 0.0), v[:1], table=CIRCLE),
}


@hyp_settings(max_examples=300, deadline=None)
@given(where=st.sampled_from(sorted(ARRAY_INPUTS)), index=st.integers(0, 5), value=WRONG_TYPES)
def test_array_inputs_refuse_wrong_entry_types(where, index, value):
    """One entry of a state, a control row, a batch row or a time array of a wrong type."""
    entries = list(STATE)
    entries[index % (2 if "controls" in where else 1 if where.startswith(("flow t", "first")) else 6)] = value
    with pytest.raises(TypeError, match=where.split(" ")[-1]):
        ARRAY_INPUTS[where](entries)


@hyp_settings(max_examples=150, deadline=None)
@given(where=st.sampled_from(sorted(ARRAY_INPUTS)), index=st.integers(0, 5),
       value=st.sampled_from([math.nan, math.inf, -math.inf]))
def test_array_inputs_refuse_non_finite_entries(where, index, value):
    entries = list(STATE)
    entries[index % (2 if "controls" in where else 1 if where.startswith(("flow t", "first")) else 6)] = value
    with pytest.raises(ValueError, match=where.split(" ")[-1]):
        ARRAY_INPUTS[where](entries)


@pytest.mark.parametrize("call", [
    lambda: pe.simulate(STATE, table=CIRCLE, t_final=1.0, settings={"zeno_impacts": 3}),
    lambda: pb.simulate([STATE], table=CIRCLE, t_final=1.0, settings="fast"),
    lambda: pe.simulate(STATE, params={"R": 0.01}, table=CIRCLE, t_final=1.0),
])
def test_params_and_settings_objects_of_the_wrong_type(call):
    with pytest.raises(TypeError, match="settings|params"):
        call()


@pytest.mark.parametrize("end, exc", [(True, TypeError), ("1", TypeError), (None, TypeError), (2, ValueError)])
def test_impact_map_end_types(end, exc):
    with pytest.raises(exc, match="end"):
        pe.impact_map([0.19, 0, 0, 0, 1, 0], table=pe.Circle(0.2), end=end)
    with pytest.raises(exc, match="ends"):
        pb.impact_map([[0.19, 0, 0, 0, 1, 0]], [end], table=pe.Circle(0.2))


def test_penny_params_true_is_not_one():
    with pytest.raises(TypeError, match="R"):  # R=True used to give R = 1.0
        pe.PennyParams(R=True)
