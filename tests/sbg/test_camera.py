"""Camera footprint and weld-line margin."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planners.errors import InvalidInputError
from planners.sbg.camera import Footprint, footprint, max_yaw_for_margin, weld_margin
from planners.sbg.robot import CameraParams


def test_footprint_hand_case() -> None:
    # tilt 40°, vfov 40°, hfov 70°, h = 0.24 m, x = 0.06 m.
    # Near ray (v = −1): r_z = −sin40 − tan20·cos40 = −0.642788 − 0.278817 = −0.921605,
    # s = 0.24/0.921605 = 0.260415, x = 0.06 + s·(cos40 − tan20·sin40) = 0.06 + 0.260415·0.532089 = 0.198564,
    # half width = s·tan35 = 0.182345.
    # Far ray (v = +1): r_z = −0.642788 + 0.278817 = −0.363970, s = 0.24/0.363970 = 0.659395,
    # x = 0.06 + s·(0.766044 + 0.233956) = 0.06 + s·1.000000 = 0.719395, half width = s·tan35 = 0.461713.
    fp = footprint(CameraParams())
    assert fp.x_near == pytest.approx(0.198564, abs=1e-6)
    assert fp.w_near == pytest.approx(0.182345, abs=1e-6)
    assert fp.x_far == pytest.approx(0.719395, abs=1e-6)
    assert fp.w_far == pytest.approx(0.461713, abs=1e-6)


def test_camera_looking_at_horizon_rejected() -> None:
    with pytest.raises(InvalidInputError, match="horizon"):
        footprint(CameraParams(tilt_rad=math.radians(10), vfov_rad=math.radians(40)))


def test_margin_hand_cases() -> None:
    fp = Footprint(x_near=0.2, w_near=0.18, x_far=0.7, w_far=0.46)
    # Centred, welds at ±0.15: the near edge binds, 0.18 − 0.15 = 0.03.
    assert float(weld_margin(0.0, 0.0, 0.15, -0.15, fp)) == pytest.approx(0.03)
    # d = 10 mm right: the left weld is 0.16 from the robot axis → 0.02.
    assert float(weld_margin(0.01, 0.0, 0.15, -0.15, fp)) == pytest.approx(0.02)
    # Yaw 2° left, d = 0 (sin2° = 0.0348995, cos2° = 0.9993908): a weld at y_w crosses
    # robot x at y = (y_w − x sin δ)/cos δ.  Near edge x = 0.2: y_left = 0.1431073,
    # y_right = (−0.15 − 0.0069799)/0.9993908 = −0.1570755 → 0.18 − 0.1570755 = 0.0229245.
    # Far edge x = 0.7: y_right = −0.1745360 → 0.46 − 0.1745360 = 0.2854640.  Minimum 0.0229245.
    assert float(weld_margin(0.0, math.radians(2.0), 0.15, -0.15, fp)) == pytest.approx(
        0.0229245, abs=1e-6
    )


def test_margin_clipped_by_deck_end() -> None:
    fp = Footprint(x_near=0.2, w_near=0.18, x_far=0.7, w_far=0.46)
    m = weld_margin(
        np.array([0.0, 0.0]), np.array([0.0, 0.0]), 0.15, -0.15, fp, x_limit=np.array([0.5, 0.1])
    )
    assert m[0] == pytest.approx(0.03)
    assert np.isnan(m[1])


def test_max_yaw_for_margin() -> None:
    fp = Footprint(x_near=0.2, w_near=0.18, x_far=0.7, w_far=0.46)
    # On the centreline the near edge binds: 0.18 − (0.15 + 0.2 sin ψ)/cos ψ = 0.005.
    psi = max_yaw_for_margin(fp, 0.15, 0.005)
    assert (0.15 + 0.2 * math.sin(psi)) / math.cos(psi) == pytest.approx(0.175, abs=1e-9)
    assert float(weld_margin(0.0, psi, 0.15, -0.15, fp)) == pytest.approx(0.005, abs=1e-9)
    assert max_yaw_for_margin(fp, 0.15, 0.04) == 0.0  # 30 mm is all there is
