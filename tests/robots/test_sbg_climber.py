"""Box-girder climber description: URDF, parameters, kinematics."""

from __future__ import annotations

import math
import tomllib

import numpy as np
import pytest

from planners.sbg import corner
from planners.sbg.robot import ClimberParams
from robots import load_robot


@pytest.fixture(scope="module")
def model():
    return load_robot("sbg_climber")


def test_joints_and_limits(model) -> None:
    assert model.joint_names == [
        "wheel_fl_joint",
        "wheel_fr_joint",
        "wheel_rl_joint",
        "wheel_rr_joint",
        "lift_arm_joint",
    ]
    assert model.joint_limits.shape == (5, 2)
    assert np.all(np.isinf(model.joint_limits[:4]))  # continuous wheels
    np.testing.assert_allclose(model.joint_limits[4], [0.0, math.radians(100.0)])


def test_every_value_is_marked_seed_or_chosen(model) -> None:
    text = model.urdf_path.with_name("params.toml").read_text()
    for line in text.splitlines():
        if "=" in line and not line.lstrip().startswith("#"):
            assert "# seed:" in line or "# chosen:" in line, line
    params = tomllib.loads(text)
    assert params["body"]["length_mm"] == 230.0 and params["body"]["mass_kg"] == 4.08


def test_params_match_planner_defaults_and_urdf(model) -> None:
    p = ClimberParams.coerce(model)
    assert p == ClimberParams()
    q = np.zeros(5)
    # Wheel centres from the URDF: wheelbase and track of params.toml, axles at R.
    fl = model.fk(q, "wheel_fl")[:3, 3]
    rr = model.fk(q, "wheel_rr")[:3, 3]
    assert fl[0] - rr[0] == pytest.approx(p.wheelbase_m)
    assert fl[1] - rr[1] == pytest.approx(p.track_m)
    assert fl[2] == pytest.approx(p.wheel_radius_m)
    # Lift pivot A: l0 ahead of the rear axle, dg above the wall (Eq. 1–2).
    A = model.fk(np.array([0, 0, 0, 0, 0.0]), "lift_arm")[:3, 3]
    assert A[0] - rr[0] == pytest.approx(p.arm_l0_m) and A[2] == pytest.approx(p.arm_dg_m)
    # Range finders at the Fig. 7 geometry.
    x2, x3, x4 = p.sensor_x()
    assert model.fk(q, "range_l2")[0, 3] == pytest.approx(x2)
    assert model.fk(q, "range_l3")[0, 3] == pytest.approx(x3)
    assert model.fk(q, "range_l4")[0, 3] == pytest.approx(x4)
    assert model.fk(q, "range_l2")[0, 3] - model.fk(q, "range_l3")[0, 3] == pytest.approx(p.rf_b_m)
    cam = model.fk(q, "camera_link")
    assert cam[2, 3] == pytest.approx(p.camera.height_m)
    # The optical axis (camera x) tilts toward the wall by tilt_deg.
    assert math.degrees(math.atan2(-cam[2, 0], cam[0, 0])) == pytest.approx(
        math.degrees(p.camera.tilt_rad)
    )


def test_fk_arm_tip_hand_case(model) -> None:
    # Pivot A at (0.015, 0, 0.060); q = 90° folds the 90 mm arm backward: tip (−0.075, 0, 0.060).
    T = model.fk(np.array([0, 0, 0, 0, math.pi / 2]))
    np.testing.assert_allclose(T[:3, 3], [-0.075, 0.0, 0.060], atol=1e-12)
    # q = Δθ of Eq. 1 at pitch Δθ: the arm is perpendicular to the wall.
    dtheta = corner.pitch_change(0.09, 0.1, 0.06, 0.03)[0]
    T = model.fk(np.array([0, 0, 0, 0, dtheta]))
    arm_dir = (T[:3, 3] - np.array([0.015, 0, 0.06])) / 0.09
    Ry = np.array(
        [
            [math.cos(dtheta), 0, -math.sin(dtheta)],
            [0, 1, 0],
            [math.sin(dtheta), 0, math.cos(dtheta)],
        ]
    )
    # Pitch the body by Δθ (nose away from the wall): the arm points straight at the wall (−z).
    np.testing.assert_allclose(Ry @ arm_dir, [0, 0, -1], atol=1e-12)


def test_jacobian_matches_finite_differences(model) -> None:
    q = np.array([0.3, -0.2, 1.0, 0.5, 0.7])
    J = model.jacobian(q)
    h = 1e-7
    for i in range(5):
        dq = np.zeros(5)
        dq[i] = h
        dp = (model.fk(q + dq)[:3, 3] - model.fk(q - dq)[:3, 3]) / (2 * h)
        np.testing.assert_allclose(J[:3, i], dp, atol=1e-7)
    np.testing.assert_allclose(J[3:, 4], [0, 1, 0])
    assert np.all(J[:, :4] == 0)


@pytest.mark.parametrize("angle", [0.0, 0.3, 1.2, math.radians(100)])
def test_ik_round_trip(model, angle: float) -> None:
    q = np.array([0.1, 0.2, 0.3, 0.4, angle])
    sol = model.ik(model.fk(q), q0=np.array([0.1, 0.2, 0.3, 0.4, 0.0]))
    assert sol is not None
    np.testing.assert_allclose(sol, q, atol=1e-9)


def test_ik_unreachable(model) -> None:
    T = model.fk(np.array([0, 0, 0, 0, 0.5]))
    T[0, 3] += 0.01  # off the arm's circle
    assert model.ik(T) is None
    # Beyond the joint limit (q = −20°).
    assert model.ik(model.fk(np.array([0, 0, 0, 0, -0.35]))) is None
    with pytest.raises(ValueError):
        model.fk(np.zeros(3))
    with pytest.raises(ValueError, match="unknown link"):
        model.fk(np.zeros(5), "gripper")


def test_urdf_loads_in_yourdfpy(model) -> None:
    yourdfpy = pytest.importorskip("yourdfpy")
    u = yourdfpy.URDF.load(str(model.urdf_path))
    assert list(u.actuated_joint_names) == model.joint_names
    q = np.array([0.1, 0.2, 0.3, 0.4, 0.8])
    u.update_cfg(q)
    np.testing.assert_allclose(u.get_transform("arm_tip", "base_link"), model.fk(q), atol=1e-9)
    np.testing.assert_allclose(
        u.get_transform("camera_link", "base_link"), model.fk(q, "camera_link"), atol=1e-9
    )
    # Primitive geometry only, and nothing taller than the seed's 256 mm.
    for link in u.link_map.values():
        for v in link.visuals:
            assert v.geometry.mesh is None
