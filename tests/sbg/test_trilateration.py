"""Trilateration of d and δ, seed 003 §3.2 Eq. 5 and Table 1."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from planners.sbg.robot import ClimberParams
from planners.sbg.trilateration import side_ranges, trilaterate

R = ClimberParams()
GEOM = {"a": R.rf_a_m, "b": R.rf_b_m, "c": R.rf_c_m, "n": R.rf_n_m}


def test_eq5_hand_case() -> None:
    # a = 115, b = 150, c = 190, n = 230 mm → n − a − c = −75 mm.
    # l2 = 60, l3 = 45, l4 = 70 mm:
    # δ = atan((60 − 45)/150) = atan(0.1) = 5.7106°; cos δ = 1/sqrt(1.01) = 0.99503719, sin δ = 0.099503719
    # d = ((70 − 45)·0.99503719 + (−75)·0.099503719)/2 = (24.8759297 − 7.4627789)/2 = 8.7065754 mm.
    d, delta = trilaterate(60.0, 45.0, 70.0, a=115.0, b=150.0, c=190.0, n=230.0)
    assert math.degrees(float(delta)) == pytest.approx(5.7106, abs=1e-4)
    assert float(d) == pytest.approx(8.7065754, abs=1e-6)


def test_table1_signs() -> None:
    # Robot right of the centreline (d > 0) heading left (δ > 0): the right
    # wall is near (l3 small), the left far (l4 large), and the front right
    # sensor l2 is farther from the right wall than l3.
    l2, l3, l4 = side_ranges(
        0.004,
        math.radians(1.0),
        half_width_right=0.16,
        half_width_left=0.16,
        side=0.105,
        x2=0.075,
        x3=-0.075,
        x4=0.0,
    )
    assert l4 > l3 and l2 > l3
    d, de = trilaterate(l2, l3, l4, **GEOM)
    assert d > 0 and de > 0


def test_centred_robot_reads_equal_sides() -> None:
    l2, l3, l4 = side_ranges(
        0.0,
        0.0,
        half_width_right=0.16,
        half_width_left=0.16,
        side=0.105,
        x2=0.075,
        x3=-0.075,
        x4=0.0,
    )
    assert (
        float(l2) == pytest.approx(0.055)
        and float(l3) == pytest.approx(0.055)
        and float(l4) == pytest.approx(0.055)
    )


@given(
    st.floats(-0.03, 0.03),
    st.floats(-0.2, 0.2),
    st.floats(0.13, 0.2),
    st.floats(-0.01, 0.01),
)
def test_round_trip_with_forward_model(
    d: float, delta: float, half_width: float, asym: float
) -> None:
    # Eq. 5 inverts the beam geometry exactly when the walls are parallel to
    # the centreline, whatever the lane width and even if the lane is
    # asymmetric about it (then d is measured from the mid-line of the walls).
    x2, x3, x4 = R.sensor_x()
    l2, l3, l4 = side_ranges(
        d,
        delta,
        half_width_right=half_width + asym,
        half_width_left=half_width - asym,
        side=R.rf_side_m,
        x2=x2,
        x3=x3,
        x4=x4,
    )
    d_hat, de_hat = trilaterate(l2, l3, l4, **GEOM)
    assert float(de_hat) == pytest.approx(delta, abs=1e-12)
    assert float(d_hat) == pytest.approx(d - asym, abs=1e-12)


def test_vectorised() -> None:
    rd = np.array([[0.06, 0.05], [0.05, 0.05], [0.05, 0.06]])
    d, de = trilaterate(rd[0], rd[1], rd[2], **GEOM)
    assert d.shape == (2,) and de.shape == (2,)
    assert float(de[1]) == 0.0 and float(d[1]) == pytest.approx(0.005)
