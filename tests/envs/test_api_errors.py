"""Bad input gets a clear error naming the field; nothing silent."""
import math

import numpy as np
import pytest

import penny_env as pe
import penny_env.batch as pb


@pytest.mark.fast
@pytest.mark.parametrize("field", ["R", "m", "I", "J"])
@pytest.mark.parametrize("value", [0.0, -1.0, math.nan, math.inf])
def test_params_reject_non_positive_or_non_finite(field, value):
    with pytest.raises(ValueError, match=field):
        pe.PennyParams(**{field: value})


@pytest.mark.fast
def test_params_reject_strings():
    with pytest.raises(TypeError, match="R"):
        pe.PennyParams(R="big")


@pytest.mark.fast
def test_paper_defaults():
    p = pe.PennyParams()
    assert (p.R, p.m, p.I, p.J) == (0.01, 0.0025, 1.25e-7, 6.25e-8)


@pytest.mark.fast
@pytest.mark.parametrize("make, field", [
    (lambda: pe.Ellipse(-1.0, 0.2), "a"), (lambda: pe.Ellipse(0.2, math.nan), "b"),
    (lambda: pe.Circle(0.0), "radius"), (lambda: pe.Stadium(0.0, 0.1), "radius"),
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


@pytest.mark.fast
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


# -- types and extreme values (issue 12 item 5; the hypothesis matrix is in test_input_types.py) --
@pytest.mark.parametrize("field, value", [("Ellipse.a", 1e-300), ("Ellipse.b", 1e300), ("Circle.radius", 5e-324),
                                          ("Stadium.radius", 1e-200), ("Stadium.length", 1e200)])
def test_extreme_table_sizes_are_value_errors(field, value):
    make = {"Ellipse.a": lambda v: pe.Ellipse(v, 1.0), "Ellipse.b": lambda v: pe.Ellipse(1.0, v),
            "Circle.radius": pe.Circle, "Stadium.radius": lambda v: pe.Stadium(v, 0.1),
            "Stadium.length": lambda v: pe.Stadium(0.1, v)}[field]
    with pytest.raises(ValueError, match=field.split(".")[1]):  # was ZeroDivisionError for Ellipse(1e-300, 1)
        make(value)


@pytest.mark.parametrize("call", [
    lambda: pe.simulate([0.0, 0.0, 0.0, 0.3, 1.0, 0.2], table=pe.Circle(0.2), t_final=1.0, settings={"zeno_impacts": 3}),
    lambda: pb.simulate([[0.0, 0.0, 0.0, 0.3, 1.0, 0.2]], table=pe.Circle(0.2), t_final=1.0, settings="fast"),
    lambda: pe.simulate([0.0, 0.0, 0.0, 0.3, 1.0, 0.2], params={"R": 0.01}, table=pe.Circle(0.2), t_final=1.0),
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
