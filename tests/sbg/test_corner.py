"""Corner crossing, seed 003 §3.1 Eq. 1–4."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from planners.errors import InvalidInputError
from planners.sbg import corner
from planners.sbg.robot import ClimberParams

ROBOT = ClimberParams()


def test_eq1_eq2_hand_case_345_triangle() -> None:
    # l0 = 40, dg = 60, R = 30 → dg − R = 30, |AB| = sqrt(40² + 30²) = 50 (Eq. 2).
    # θ1 = atan(30/40) = atan(3/4) = 36.8699°.
    # larm = 70 → (larm − R)/|AB| = 40/50 = 0.8 → θ2 = asin(0.8) = 53.1301°.
    # Δθ = θ2 − θ1 = 16.2602° (= atan(4/3) − atan(3/4)).
    assert corner.ab_length(40.0, 60.0, 30.0) == pytest.approx(50.0)
    dtheta, t1, t2 = corner.pitch_change(70.0, 40.0, 60.0, 30.0)
    assert math.degrees(t1) == pytest.approx(36.8699, abs=1e-4)
    assert math.degrees(t2) == pytest.approx(53.1301, abs=1e-4)
    assert math.degrees(dtheta) == pytest.approx(16.2602, abs=1e-4)


def test_eq1_robot_values() -> None:
    # Robot: R = 30, l0 = 100, dg = 60, larm = 90 mm.
    # |AB| = sqrt(100² + 30²) = 104.403; θ1 = atan(0.3) = 16.6992°;
    # θ2 = asin(60/104.403) = asin(0.574696) = 35.0783°; Δθ = 18.3791°.
    dtheta, t1, t2 = corner.pitch_change(0.090, 0.100, 0.060, 0.030)
    assert math.degrees(t1) == pytest.approx(16.6992, abs=1e-4)
    assert math.degrees(t2) == pytest.approx(35.0783, abs=1e-4)
    assert math.degrees(dtheta) == pytest.approx(18.3791, abs=1e-4)


def test_eq1_rejects_arm_that_cannot_stand() -> None:
    # (larm − R)/|AB| = (200 − 30)/50 > 1: arcsin undefined.
    with pytest.raises(InvalidInputError):
        corner.pitch_change(200.0, 40.0, 60.0, 30.0)


def test_eq4_hand_values() -> None:
    # θ = 30°: v1 = 20, v2 = 20·tan30° = 11.547 mm/s.
    # θ = 60°: v2 = 20, v1 = 20/tan60° = 11.547 mm/s.
    # θ = 45°: both branches give 20 and 20.  θ = 0 and 90°: both 20.
    th = np.radians([0.0, 30.0, 45.0, 60.0, 90.0])
    v1, v2 = corner.wheel_speeds(th, 20.0)
    np.testing.assert_allclose(v1, [20.0, 20.0, 20.0, 11.547005, 20.0], atol=1e-6)
    np.testing.assert_allclose(v2, [20.0, 11.547005, 20.0, 20.0, 20.0], atol=1e-6)


@given(st.floats(0.001, math.pi / 2 - 0.001))
def test_eq4_respects_caps_and_eq3_ratio(theta: float) -> None:
    v1, v2 = corner.wheel_speeds(theta, 0.02)
    assert max(float(v1), float(v2)) == pytest.approx(0.02)
    assert float(v2) == pytest.approx(float(v1) * math.tan(theta), rel=1e-9)  # Eq. 3


def test_eq4_rejects_pitch_out_of_range() -> None:
    with pytest.raises(InvalidInputError):
        corner.wheel_speeds(-0.1)


@given(st.floats(0.0, math.pi / 2))
@settings(max_examples=50)
def test_wheel_centres_keep_contact_and_wheelbase(theta: float) -> None:
    L, R = ROBOT.wheelbase_m, ROBOT.wheel_radius_m
    F, B = corner.wheel_centres(theta, L, R)
    assert F[0] == pytest.approx(-R)  # front wheel on the new wall (s = −R)
    assert B[1] == pytest.approx(R)  # rear wheel on the old wall (h = R)
    assert np.linalg.norm(F - B) == pytest.approx(L)


def test_eq3_from_geometry_by_finite_differences() -> None:
    # Differentiate the wheel centres: front speed along the new wall over
    # rear speed along the old wall equals 1/tan θ, i.e. v2 = v1 tan θ.
    L, R, th, h = 0.17, 0.03, math.radians(35.0), 1e-7
    F0, B0 = corner.wheel_centres(th, L, R)
    F1, B1 = corner.wheel_centres(th + h, L, R)
    v1 = (F1[1] - F0[1]) / h
    v2 = (B1[0] - B0[0]) / h
    assert v2 == pytest.approx(v1 * math.tan(th), rel=1e-5)
    assert float(corner.pitch_rate(th, v1, v2, L)) == pytest.approx(1.0, rel=1e-5)


def test_base_pose_ends_on_each_wall() -> None:
    L, R = ROBOT.wheelbase_m, ROBOT.wheel_radius_m
    o, x, z = corner.base_pose(np.array([0.0, math.pi / 2]), L, R)
    # θ = 0: on the old wall (h = 0), half the robot length before the corner.
    np.testing.assert_allclose(o[0], [-(R + L / 2), 0.0], atol=1e-12)
    # θ = 90°: on the new wall (s = 0), half the length past the corner.
    np.testing.assert_allclose(o[1], [0.0, R + L / 2], atol=1e-12)
    np.testing.assert_allclose(x[1], [0.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(z[1], [-1.0, 0.0], atol=1e-12)


def test_arm_is_perpendicular_at_full_lift() -> None:
    # At θ = Δθ (Eq. 1) the pivot height equals larm: the arm stands
    # perpendicular to the wall, so its body angle q equals θ.
    amap = corner.ArmPitchMap(ROBOT)
    assert float(corner.pivot_height(amap.delta_theta, ROBOT)) == pytest.approx(ROBOT.arm_length_m)
    assert amap.q_top == pytest.approx(amap.delta_theta, abs=1e-9)
    # At θ = 0 the pivot is dg above the wall and q = acos(dg/larm) = acos(60/90) = 48.19°.
    assert math.degrees(amap.q_contact) == pytest.approx(48.1897, abs=1e-3)
    assert np.all(np.diff(amap.q) < 0)
    assert float(amap.pitch(amap.q_contact)) == pytest.approx(0.0, abs=1e-9)


def test_min_jerk_endpoints() -> None:
    t = np.array([0.0, 0.5, 1.0])
    np.testing.assert_allclose(corner.min_jerk(t), [0.0, 0.5, 1.0])
    # Zero slope at the ends (finite difference).
    assert float(corner.min_jerk(1e-4)) < 1e-10


@pytest.mark.parametrize("profile", corner.PROFILES)
def test_crossing_reaches_90_deg_within_caps(profile: str) -> None:
    rec = corner.cross_corner(ROBOT, profile=profile)
    assert rec.theta[-1] == pytest.approx(math.pi / 2)
    assert np.all(np.diff(rec.theta) >= -1e-12)  # pitch never goes back
    # Eq. 4 caps both wheels at 20 mm/s; the lift drags the wheels per Eq. 3
    # and is timed to stay under the cap too.
    speeds = np.abs(np.r_[rec.v1, rec.v2])
    assert speeds.max() <= ROBOT.max_speed_m_s * (1 + 1e-9)
    assert rec.delta_theta == pytest.approx(math.radians(18.3791), abs=1e-6)
    # The arm lifts to the perpendicular (q = Δθ) and folds back.
    assert rec.arm.min() == pytest.approx(rec.delta_theta, abs=1e-9)
    assert rec.arm[-1] == pytest.approx(ROBOT.arm_stowed_rad)


def test_smooth_profile_removes_the_rate_steps_of_the_printed_one() -> None:
    dt = 0.05
    printed = corner.cross_corner(ROBOT, profile=corner.PRINTED, dt=dt)
    smooth = corner.cross_corner(ROBOT, profile=corner.SMOOTH, dt=dt)
    sp, ss = corner.smoothness(printed.theta, dt), corner.smoothness(smooth.theta, dt)
    # Printed: the pitch rate steps when the servo starts, when Eq. 4 takes
    # over (to v1/(L cos Δθ) = 20/(170·cos 18.38°) rad/s = 7.1°/s) and at landing (v2/L = 6.7°/s).
    assert sp["max_rate_jump_deg_s"] > 5.0
    assert ss["max_rate_jump_deg_s"] < 1.0
    assert ss["max_accel_deg_s2"] < sp["max_accel_deg_s2"] / 5


def test_smoothness_of_a_kink() -> None:
    # θ(t) = 0 then rising at 1 rad/s: one rate jump of 1 rad/s = 57.30°/s.
    dt = 0.1
    th = np.r_[np.zeros(5), np.arange(1, 6) * dt]
    sm = corner.smoothness(th, dt)
    assert sm["max_rate_jump_deg_s"] == pytest.approx(57.2958, abs=1e-3)
    assert sm["max_accel_deg_s2"] == pytest.approx(572.958, abs=1e-2)


def test_noisy_crossing_is_reproducible() -> None:
    a = corner.cross_corner(ROBOT, rng=np.random.default_rng(3), wheel_sigma=0.02)
    b = corner.cross_corner(ROBOT, rng=np.random.default_rng(3), wheel_sigma=0.02)
    c = corner.cross_corner(ROBOT, rng=np.random.default_rng(4), wheel_sigma=0.02)
    np.testing.assert_array_equal(a.theta, b.theta)
    assert not np.array_equal(a.theta, c.theta)


def test_bad_profile() -> None:
    with pytest.raises(InvalidInputError, match="profile"):
        corner.cross_corner(ROBOT, profile="fast")
