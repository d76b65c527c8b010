"""Surface frame (DESIGN §5) and the nozzle model (seed Eq. 3.1, Table 3.1)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from planners.blasting import Surface
from planners.blasting.nozzle import NOZZLES, blast_radius_m, check_stream_length, get_nozzle
from planners.errors import EmptyInputError, InvalidInputError, StreamLengthError

SQUARE = np.array([[-0.1, -0.1], [0.1, -0.1], [0.1, 0.1], [-0.1, 0.1]])
unit = st.lists(st.floats(-1, 1), min_size=3, max_size=3).filter(lambda v: np.linalg.norm(v) > 0.1)


def test_frame_rule_of_design_5():
    s = Surface([0, 0, 1.7], [0, 0, -1], SQUARE)
    np.testing.assert_allclose(s.x_axis, [1, 0, 0])
    np.testing.assert_allclose(s.y_axis, np.cross([0, 0, -1], [1, 0, 0]))
    # normal parallel to world x: x axis is world y (projected)
    s = Surface([0, 0.5, 1.5], [1, 0, 0], SQUARE)
    np.testing.assert_allclose(s.x_axis, [0, 1, 0])
    np.testing.assert_allclose(s.y_axis, [0, 0, 1])
    # explicit x_axis is projected onto the plane
    s = Surface([0, 0, 0], [0, 0, 1], SQUARE, x_axis=[1, 1, 5])
    np.testing.assert_allclose(s.x_axis, np.array([1, 1, 0]) / np.sqrt(2))


@settings(max_examples=60, deadline=None)
@given(unit, st.lists(st.floats(-2, 2), min_size=3, max_size=3), st.integers(0, 10_000))
def test_plane_round_trip(n, o, seed):
    s = Surface(o, n, SQUARE)
    R = s.rotation
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-9)
    assert np.linalg.det(R) == pytest.approx(1.0)
    uv = np.random.default_rng(seed).normal(size=(20, 2))
    w = s.to_world(uv)
    np.testing.assert_allclose((w - s.origin) @ s.normal, 0, atol=1e-9)
    np.testing.assert_allclose(s.to_plane(w), uv, atol=1e-9)


def test_from_points_recovers_plane_and_outline():
    rng = np.random.default_rng(0)
    uv = rng.uniform([-0.3, -0.2], [0.3, 0.2], size=(3000, 2))
    truth = Surface([0.2, 0.5, 1.6], [0.2, -0.3, -1.0], SQUARE)
    pts = truth.to_world(uv) + rng.normal(scale=0.001, size=(3000, 3))
    s = Surface.from_points(pts, toward=[0.5, 0.4, 0.4])
    assert abs(s.normal @ truth.normal) > np.cos(np.deg2rad(0.5))
    assert (np.array([0.5, 0.4, 0.4]) - s.origin) @ s.normal > 0
    assert s.area == pytest.approx(0.24, rel=0.05)


def test_surface_input_errors_name_the_input():
    with pytest.raises(InvalidInputError, match="normal"):
        Surface([0, 0, 0], [0, 0, 0], SQUARE)
    with pytest.raises(InvalidInputError, match="boundary"):
        Surface([0, 0, 0], [0, 0, 1], np.zeros((4, 3)))
    with pytest.raises(EmptyInputError):
        Surface([0, 0, 0], [0, 0, 1], [[0, 0], [1, 1]])
    with pytest.raises(InvalidInputError, match="origin"):
        Surface([0, np.nan, 0], [0, 0, 1], SQUARE)


def test_holes_are_not_surface():
    hole = SQUARE * 0.5
    s = Surface([0, 0, 0], [0, 0, 1], SQUARE, holes=[hole])
    assert s.area == pytest.approx(0.04 - 0.01)


def test_eq_3_1_by_hand():
    # Rc = ds (dmax − dmin) / 2L + dmax / 2
    assert get_nozzle("medium").radius_mm(300) == pytest.approx(300 * 7 / 224 + 6.5)
    assert get_nozzle("small").radius_mm(100) == pytest.approx(100 * 2.5 / 150 + 3.5)
    assert get_nozzle("large").radius_mm(500) == pytest.approx(500 * 8 / 290 + 7.5)
    assert blast_radius_m("medium", 300) == pytest.approx(0.015875)
    assert {n: (z.d_max_mm, z.d_min_mm, z.cone_length_mm) for n, z in NOZZLES.items()} == {
        "small": (7, 4.5, 75),
        "medium": (13, 6, 112),
        "large": (15, 7, 145),
    }
    # the radius grows with the stream length (Fig. 3.4)
    r = [get_nozzle("medium").radius_mm(d) for d in (100, 200, 300, 400, 500)]
    assert np.all(np.diff(r) > 0)


@pytest.mark.parametrize("ds", [99.9, 500.1, 0, -300, float("nan"), float("inf")])
def test_stream_length_outside_window_is_refused(ds):
    with pytest.raises(StreamLengthError, match="100–500 mm"):
        check_stream_length(ds)


def test_unknown_nozzle():
    with pytest.raises(InvalidInputError, match="small, medium, large"):
        get_nozzle("huge")
