"""The type/value matrix of the public physics API (issue 12 item 5), with hypothesis: a wrong type
is a TypeError and a bad value a ValueError, both naming the field. Numeric strings, complex
numbers, booleans and None are wrong types, in scalars and inside arrays."""
import math

import numpy as np
import pytest

import penny_env as pe

pytest.importorskip("hypothesis", reason="the type/value matrix draws its inputs with hypothesis")
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
    if field == "Circle.radius":
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
                 "max_events_per_interval", "max_impacts", "Ellipse.a", "Ellipse.b", "Circle.radius", "Stadium.radius",
                 "Stadium.length", "t_final", "n_impacts", "control_dt", "batch t_final", "batch control_dt"]


def _name(field):
    return field.split(".")[-1].split(" ")[-1]


@pytest.mark.fast
@hyp_settings(max_examples=300, deadline=None)
@given(field=st.sampled_from(SCALAR_FIELDS), value=WRONG_TYPES)
def test_scalar_fields_refuse_wrong_types(field, value):
    if value is None and field in ("t_final", "n_impacts", "control_dt", "batch control_dt"):
        return  # optional arguments: None means not given
    with pytest.raises(TypeError, match=_name(field)):
        _call_scalar(field, value)


@pytest.mark.fast
@hyp_settings(max_examples=200, deadline=None)
@given(field=st.sampled_from(SCALAR_FIELDS), value=BAD_VALUES)
def test_scalar_fields_refuse_bad_values(field, value):
    if field == "Stadium.length" and value == 0.0:
        return  # a stadium of length 0 is a circle
    if field in ("zeno_impacts", "max_search_steps", "max_events_per_interval", "max_impacts", "n_impacts"):
        value = int(-1 if not math.isfinite(value) else value)  # integer fields: bad integers
    with pytest.raises(ValueError, match=_name(field)):
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
