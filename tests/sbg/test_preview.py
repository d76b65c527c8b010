"""Preview-follow tracking, seed 003 §3.2 Eq. 6–9 (Fig. 8)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from planners.errors import InvalidInputError
from planners.sbg import preview


def test_eq7_eq8_hand_case_straight_heading() -> None:
    # d = 10 mm right of the centreline, δ = 0, Lx = 20 mm:
    # Rc = (20² + 10²)/(2·(10·1 − 20·0)) = 500/20 = 25 mm (Eq. 7), a left turn.
    # δ2 = acos((25·cos0 − 10)/25) = acos(0.6) = 53.1301° (Eq. 8).
    Rc = preview.turning_radius(10.0, 0.0, 20.0)
    assert Rc == pytest.approx(25.0)
    assert math.degrees(preview.arrival_angle(10.0, 0.0, Rc)) == pytest.approx(53.1301, abs=1e-4)
    # Geometry check: with δ = 0, tan(δ2/2) = d/Lx = 0.5 → δ2 = 2·atan(0.5) = 53.1301°.
    assert math.degrees(preview.arrival_heading(10.0, 0.0, 20.0, Rc)) == pytest.approx(
        53.1301, abs=1e-4
    )


def test_eq7_eq8_hand_case_with_yaw() -> None:
    # d = 10, δ = 5°, Lx = 20: d cos δ − Lx sin δ = 9.961947 − 1.743115 = 8.218832;
    # Rc = 500/(2·8.218832) = 30.4180 mm;  (Rc cos δ − d)/Rc = (30.30225 − 10)/30.4180 = 0.667442;
    # δ2 = acos(0.667442) = 48.1294°.
    Rc = preview.turning_radius(10.0, math.radians(5.0), 20.0)
    assert Rc == pytest.approx(30.4180, abs=1e-4)
    assert math.degrees(preview.arrival_angle(10.0, math.radians(5.0), Rc)) == pytest.approx(
        48.1294, abs=1e-3
    )


def test_eq6_preview_point_hand_case() -> None:
    # δ = 90°: xe = d sin δ + Lx cos δ = d, ye = d cos δ − Lx sin δ = −Lx.
    xe, ye = preview.preview_point(3.0, math.pi / 2, 7.0)
    assert xe == pytest.approx(3.0) and ye == pytest.approx(-7.0)


def _integrate_arc(plan: preview.ArcPlan, d: float, delta: float) -> tuple[float, float, float]:
    """End of the arc in the lane frame (X along, Y left; Oc starts at (0, −d))."""
    if math.isinf(plan.radius_m):
        return plan.length_m * math.cos(delta), -d + plan.length_m * math.sin(delta), delta
    R = plan.radius_m
    cx, cy = -R * math.sin(delta), -d + R * math.cos(delta)
    psi = delta + plan.sweep_rad
    return cx + R * math.sin(psi), cy - R * math.cos(psi), psi


@given(st.floats(-0.02, 0.02), st.floats(-0.3, 0.3), st.floats(0.0, 0.2))
def test_arc_ends_at_preview_point_with_eq8_heading(d: float, delta: float, Lx: float) -> None:
    assume(abs(d) > 1e-5 or Lx > 1e-5)
    plan = preview.plan_arc(d, delta, Lx)
    X, Y, psi = _integrate_arc(plan, d, delta)
    # P is on the centreline, Lx ahead of Oc's foot point (Eq. 6).
    assert pytest.approx(Lx, abs=1e-9) == X
    assert pytest.approx(0.0, abs=1e-9) == Y
    assert math.remainder(psi - plan.arrival_rad, 2 * math.pi) == pytest.approx(0.0, abs=1e-9)
    # |ψ| is Eq. 8's δ2.
    if math.isfinite(plan.radius_m):
        assert abs(plan.arrival_rad) == pytest.approx(
            preview.arrival_angle(d, delta, plan.radius_m), abs=1e-7
        )
    assert plan.length_m == pytest.approx(
        abs(plan.radius_m * plan.sweep_rad) if plan.sweep_rad else plan.length_m
    )


def test_lx_zero_is_a_semicircle() -> None:
    # Lx = 0, δ = 0: Rc = d/2 and the robot arrives heading backwards (δ2 = 180°).
    plan = preview.plan_arc(0.01, 0.0, 0.0)
    assert plan.radius_m == pytest.approx(0.005)
    assert abs(plan.arrival_rad) == pytest.approx(math.pi)
    assert plan.length_m == pytest.approx(math.pi * 0.005)


def test_eq9_signs_and_magnitude() -> None:
    # δ > 0 (heading left): turn right, v_l = +ωB/2, v_r = −ωB/2 = ±0.2·0.18/2 = ±0.018 m/s.
    vl, vr = preview.rotation_wheel_speeds(0.1, 0.2, 0.18)
    assert (vl, vr) == pytest.approx((0.018, -0.018))
    vl, vr = preview.rotation_wheel_speeds(-0.1, 0.2, 0.18)
    assert (vl, vr) == pytest.approx((-0.018, 0.018))


def test_arc_wheel_speeds() -> None:
    # Rc = 0.25 m left, B = 0.18, outer (right) wheel at 0.02 m/s:
    # ω = 0.02/(0.25 + 0.09) = 0.0588235; v_l = ω·0.16 = 0.0094118.
    vl, vr = preview.arc_wheel_speeds(0.25, 0.02, 0.18)
    assert vr == pytest.approx(0.02) and vl == pytest.approx(0.0094118, abs=1e-7)
    vl, vr = preview.arc_wheel_speeds(-0.25, 0.02, 0.18)
    assert vl == pytest.approx(0.02) and vr == pytest.approx(0.0094118, abs=1e-7)
    assert preview.arc_wheel_speeds(math.inf, 0.02, 0.18) == (0.02, 0.02)


def test_preview_for_arrival_bounds_the_yaw() -> None:
    # δ = 0: tan(ψ/2) = d/Lx, so |ψ| ≤ 1.5° needs Lx ≥ d / tan(0.75°) = 0.01/0.0130907 = 0.763903 m.
    lx = preview.preview_for_arrival(0.01, 0.0, 0.02, math.radians(1.5))
    assert lx == pytest.approx(0.763903, rel=1e-5)
    assert preview.preview_for_arrival(1e-5, 0.0, 0.02, math.radians(1.5)) == 0.02  # already fine
    with pytest.raises(InvalidInputError):
        preview.preview_for_arrival(0.01, math.radians(3.0), 0.02, math.radians(1.5))


def test_negative_lx_rejected() -> None:
    with pytest.raises(InvalidInputError, match="Lx"):
        preview.plan_arc(0.01, 0.0, -1.0)


def test_arc_straight_ahead() -> None:
    # P straight ahead: ye = d cos δ − Lx sin δ = 0 → drive straight |OcP|.
    delta = math.atan(0.01 / 0.02)
    plan = preview.plan_arc(0.01, delta, 0.02)
    assert math.isinf(plan.radius_m) or abs(plan.radius_m) > 1e6
    assert plan.length_m == pytest.approx(math.hypot(0.01, 0.02), rel=1e-6)
    assert np.isclose(plan.arrival_rad, delta)
