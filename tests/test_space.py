import numpy as np
import pytest

from vbl_robust import ParameterBox


def test_box_maps_unit_cube_round_trip():
    box = ParameterBox({"roll_deg": (-15, 15), "contrast": (0.7, 1.4)})
    assert box.names == ("roll_deg", "contrast")
    assert box.units == ("deg", "factor")
    rng = np.random.default_rng(0)
    u = rng.random((50, 2))
    x = box.from_unit(u)
    assert box.contains(x).all()
    np.testing.assert_allclose(box.to_unit(x), u, atol=1e-15)
    np.testing.assert_allclose(box.from_unit([[0, 0], [1, 1]]), [[-15, 0.7], [15, 1.4]])
    assert box.volume == pytest.approx(30 * 0.7)


@pytest.mark.parametrize(
    "bounds, match",
    [
        ({"roll_deg": (5, 5)}, "lower < upper"),
        ({"roll_deg": (5, -5)}, "lower < upper"),
        ({"roll_deg": (0, float("inf"))}, "finite"),
        ({"roll_deg": (0, float("nan"))}, "finite"),
        ({"roll_deg": ("a", 1)}, "two numbers"),
        ({}, "non-empty"),
    ],
)
def test_box_rejects_bad_bounds_with_named_error(bounds, match):
    with pytest.raises(ValueError, match=match):
        ParameterBox(bounds)


def test_box_shape_errors_and_dict_round_trip():
    box = ParameterBox({"roll_deg": (-2, 2)})
    with pytest.raises(ValueError, match=r"shape \(N, 1\)"):
        box.from_unit(np.zeros((3, 2)))
    assert ParameterBox.from_dict(box.to_dict()) == box
    assert box.index("roll_deg") == 0
    with pytest.raises(KeyError, match="contrast"):
        box.index("contrast")
