"""Properties of ParameterBox (hypothesis): unit-cube round trips, staying inside, dict round trips, and
bad input always rejected with a one-line ValueError that names the parameter and the value."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from vbl_robust import ParameterBox
from vbl_robust.space import MIN_RELATIVE_WIDTH, MIN_WIDTH

# deterministic in CI, no example database written into the shared working tree
PROPS = settings(max_examples=100, deadline=None, derandomize=True, database=None)
EPS = np.finfo(np.float64).eps

names = st.text(min_size=1, max_size=12).filter(lambda s: s.strip() != "")
finite = st.floats(allow_nan=False, allow_infinity=False)
#: a mix of everyday magnitudes and the whole float range
coords = st.one_of(st.floats(-1e3, 1e3, allow_nan=False), finite, st.integers(-(10**6), 10**6))


def valid(a: float, b: float) -> bool:
    """The documented acceptance rule for one parameter's bounds (finite bounds are given)."""
    w = b - a
    return a < b and np.isfinite(w) and w >= max(MIN_RELATIVE_WIDTH * max(abs(a), abs(b)), MIN_WIDTH)


@st.composite
def boxes(draw, max_dim=4):
    keys = draw(st.lists(names, min_size=1, max_size=max_dim, unique=True))
    bounds = {}
    for k in keys:
        a, b = sorted((float(draw(coords)), float(draw(coords))))
        assume(valid(a, b))
        bounds[k] = (a, b)
    return ParameterBox(bounds)


def unit_points(d: int):
    return st.lists(st.lists(st.floats(0.0, 1.0), min_size=d, max_size=d), min_size=1, max_size=6).map(np.array)


@st.composite
def box_and_unit_points(draw):
    box = draw(boxes())
    return box, draw(unit_points(box.dim))


def roundtrip_tol(box: ParameterBox) -> np.ndarray:
    """|to_unit(from_unit(u)) − u| bound: a few ulps of the bounds' magnitude, in units of the width."""
    mag = np.maximum(np.abs(box.lower), np.abs(box.upper))
    return 4 * EPS * (1.0 + mag / box.width)


# -- mappings ---------------------------------------------------------------------------------------------
@PROPS
@given(box_and_unit_points())
def test_unit_points_land_inside_and_round_trip(bu):
    box, u = bu
    x = box.from_unit(u)
    assert x.shape == u.shape and x.dtype == np.float64
    assert np.all(x >= box.lower) and np.all(x <= box.upper)  # exactly, not only within contains()'s tolerance
    assert box.contains(x).all()
    back = box.to_unit(x)
    assert np.all(np.abs(back - u) <= roundtrip_tol(box))
    assert np.all((back >= 0.0) & (back <= 1.0))


@PROPS
@given(boxes())
def test_corners_of_the_cube_map_to_the_bounds_exactly(box):
    np.testing.assert_array_equal(box.from_unit(np.zeros(box.dim)), box.lower[None])
    np.testing.assert_array_equal(box.from_unit(np.ones(box.dim)), box.upper[None])
    np.testing.assert_array_equal(box.to_unit(box.lower), np.zeros((1, box.dim)))
    np.testing.assert_array_equal(box.to_unit(box.upper), np.ones((1, box.dim)))
    np.testing.assert_array_equal(box.from_unit(np.full(box.dim, 0.5)), box.lower[None] + 0.5 * box.width[None])


@PROPS
@given(box_and_unit_points())
def test_from_unit_is_monotone_per_parameter(bu):
    box, u = bu
    order = np.argsort(u, axis=0, kind="stable")
    x = box.from_unit(np.take_along_axis(u, order, axis=0))
    assert np.all(np.diff(x, axis=0) >= 0)


@PROPS
@given(box_and_unit_points())
def test_real_points_inside_map_into_the_cube_and_back(bu):
    box, u = bu
    x = box.from_unit(u)
    v = box.to_unit(x)
    assert np.all((v >= 0.0) & (v <= 1.0))
    mag = np.maximum(np.abs(box.lower), np.abs(box.upper))
    assert np.all(np.abs(box.from_unit(v) - x) <= 4 * EPS * mag)


@PROPS
@given(boxes(), st.data())
def test_clip_always_lands_inside(box, data):
    x = np.array(data.draw(st.lists(st.lists(finite, min_size=box.dim, max_size=box.dim), min_size=1, max_size=5)))
    c = box.clip(x)
    assert box.contains(c).all()
    inside = box.contains(x)
    np.testing.assert_array_equal(c[inside], np.clip(x[inside], box.lower, box.upper))


@PROPS
@given(boxes(), st.lists(st.integers(0, 4), min_size=0, max_size=3))
def test_wrong_shapes_are_a_value_error_naming_the_shape(box, shape):
    shape = tuple(shape)
    assume(not (len(shape) == 2 and shape[1] == box.dim) and not (len(shape) == 1 and shape[0] == box.dim))
    for f in (box.from_unit, box.to_unit, box.contains, box.clip):
        with pytest.raises(ValueError, match=rf"shape \(N, {box.dim}\)"):
            f(np.zeros(shape))


@pytest.mark.parametrize("bad", ["abc", [["x", "y"]], [[object(), 1.0]], {"a": 1}])
def test_non_numeric_points_are_a_value_error(bad):
    box = ParameterBox({"roll_deg": (-1, 1), "contrast": (0.5, 1.5)})
    with pytest.raises(ValueError, match="ParameterBox"):
        box.from_unit(bad)


# -- dict round trip --------------------------------------------------------------------------------------
@PROPS
@given(boxes(), st.data())
def test_dict_round_trip_also_through_json(box, data):
    units = {n: data.draw(st.text(max_size=5)) for n in box.names if data.draw(st.booleans())}
    box = ParameterBox(box.bounds(), units=units)
    d = box.to_dict()
    again = ParameterBox.from_dict(d)
    assert again == box and hash(again) == hash(box) and again.units == box.units
    assert ParameterBox.from_dict(json.loads(json.dumps(d))) == box
    assert again.names == box.names  # order is kept


json_like = st.recursive(
    st.none() | st.booleans() | st.floats() | st.integers() | st.text(max_size=4),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=4), inner, max_size=3),
    max_leaves=8,
)


@PROPS
@given(st.one_of(json_like, st.fixed_dictionaries({"bounds": json_like}),
                 st.fixed_dictionaries({"bounds": st.dictionaries(names, json_like, max_size=3), "units": json_like})))
def test_from_dict_of_anything_is_a_box_or_a_value_error(d):
    try:
        box = ParameterBox.from_dict(d)
    except ValueError as exc:
        assert "\n" not in str(exc) and str(exc).startswith("ParameterBox")
    else:
        assert box.dim == len(d["bounds"])


# -- bad bounds -------------------------------------------------------------------------------------------
anything = st.one_of(
    st.floats(), st.integers(), st.integers(min_value=10**309, max_value=10**400), st.booleans(), st.none(),
    st.text(max_size=3), st.binary(max_size=2),
)
pairs = st.one_of(
    st.tuples(st.floats(), st.floats()),
    st.tuples(coords, coords),
    st.lists(anything, max_size=3),
    st.tuples(anything, anything),
    st.text(max_size=3),  # "12" must not be read as (1, 2)
    st.dictionaries(st.integers(), st.integers(), max_size=2),
    anything,
)


@PROPS
@given(names, pairs)
def test_any_bounds_give_a_box_or_a_value_error_naming_parameter_and_value(name, pair):
    try:
        box = ParameterBox({name: pair})
    except ValueError as exc:
        msg = str(exc)
        assert "\n" not in msg and msg.startswith("ParameterBox")
        assert repr(name) in msg
        try:
            a, b = (float(v) for v in pair)
            assert (repr(a) in msg and repr(b) in msg) or repr(pair) in msg
        except Exception:
            assert repr(pair) in msg
    else:
        # accepted: exactly two real numbers, finite, ordered, with a width float64 can resolve
        assert not isinstance(pair, str | bytes | dict) and len(pair) == 2
        assert not any(isinstance(v, bool) for v in pair)
        a, b = float(pair[0]), float(pair[1])
        assert valid(a, b)
        assert box.names == (name,) and box.lower[0] == a and box.upper[0] == b


@PROPS
@given(names, st.floats(-1e300, 1e300))
def test_reversed_empty_and_non_finite_bounds_name_parameter_and_value(name, a):
    for pair, match in [((a, a), "lower < upper"), ((a, np.nextafter(a, -np.inf)), "lower < upper"),
                        ((a, np.inf), "finite"), ((-np.inf, a), "finite"), ((np.nan, a), "finite")]:
        with pytest.raises(ValueError, match=match) as err:
            ParameterBox({name: pair})
        assert repr(name) in str(err.value) and repr(float(pair[1])) in str(err.value)


@pytest.mark.parametrize("bounds", [(-1e308, 1e308), (1e10, 1e10 + 1e-3), (1.0, float(np.nextafter(1.0, 2.0))),
                                    (0.0, 5e-324)])
def test_unresolvable_widths_are_rejected(bounds):
    with pytest.raises(ValueError, match=r"'a' = .* width .* cannot map to the unit cube"):
        ParameterBox({"a": bounds})


@pytest.mark.parametrize("bounds, match", [
    ([("roll_deg", (0, 1)), ("roll_deg", (2, 3))], "non-empty mapping"),  # duplicate names cannot be given
    ({}, "non-empty mapping"),
    (None, "non-empty mapping"),
    ({"": (0, 1)}, "non-empty string"),
    ({"  ": (0, 1)}, "non-empty string"),
    ({3: (0, 1)}, "non-empty string"),
    ({"roll_deg": "12"}, r"'roll_deg' must be two numbers .*'12'"),
    ({"roll_deg": (True, 2)}, r"'roll_deg' must be two numbers"),
    ({"roll_deg": (0, 10**400)}, r"'roll_deg' must be two numbers"),
    ({"roll_deg": (0, 1, 2)}, r"'roll_deg' must be two numbers"),
])
def test_bad_bounds_examples(bounds, match):
    with pytest.raises(ValueError, match=match):
        ParameterBox(bounds)


@pytest.mark.parametrize("units, match", [
    ({"contrast": "factor"}, r"unit given for 'contrast'"),
    ({"roll_deg": 3}, r"unit of 'roll_deg' must be a string"),
    ("deg", "units must be a mapping"),
])
def test_bad_units(units, match):
    with pytest.raises(ValueError, match=match):
        ParameterBox({"roll_deg": (-1, 1)}, units=units)
