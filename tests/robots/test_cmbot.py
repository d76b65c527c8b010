"""CMBOT robot description: URDF ↔ parameters ↔ D-H model consistency."""

from __future__ import annotations

import re

import numpy as np
import pytest
import yourdfpy

import robots
from planners.cmbot.arm import ArmKinematics
from planners.cmbot.climbing_kinematics import climber_fk
from robots.cmbot import PARAMS_PATH, URDF_PATH
from robots.cmbot.urdf import build_urdf
from robots.model import read_params


@pytest.fixture(scope="module")
def model():
    return robots.load_robot("cmbot")


@pytest.fixture(scope="module")
def urdf():
    return yourdfpy.URDF.load(str(URDF_PATH), build_collision_scene_graph=False, load_meshes=False)


def test_load_robot_contract(model):
    assert model.joint_names == [f"J{i}" for i in range(6, 13)]
    assert model.joint_limits.shape == (7, 2)
    assert np.all(model.joint_limits[:, 0] < model.joint_limits[:, 1])
    q = np.zeros(7)
    T = model.fk(q)
    assert T.shape == (4, 4) and np.allclose(T[3], [0, 0, 0, 1])
    assert model.jacobian(q).shape == (6, 7)
    assert model.climber.joint_names == [f"J{i}" for i in range(1, 6)]
    assert model.climber.fk(np.zeros(5)).shape == (4, 4)


def test_urdf_is_generated_from_params():
    """The committed URDF is exactly what params.toml generates (no drift)."""
    assert URDF_PATH.read_text() == build_urdf(read_params(PARAMS_PATH))


def test_every_parameter_is_marked_seed_or_chosen():
    unmarked = [
        line
        for line in PARAMS_PATH.read_text().splitlines()
        if re.match(r"^\s*[A-Za-z_0-9]+\s*=", line) and not re.search(r"#\s*(seed|chosen)", line)
    ]
    assert unmarked == []


def test_urdf_fk_matches_dh_chains(model, urdf):
    """yourdfpy's FK of the URDF equals the D-H arm (Eq. 12) and climbing (Eq. 1) chains."""
    rng = np.random.default_rng(7)
    arm = ArmKinematics.from_model(model)
    c = model.params["climber"]
    for _ in range(20):
        qc = rng.uniform(-1.5, 1.5, 5)
        qa = rng.uniform(-2.5, 2.5, 7)
        urdf.update_cfg(np.concatenate([qc, qa]))
        T_foot = urdf.get_transform("foot_front", "foot_rear")
        assert np.allclose(T_foot, climber_fk(qc, c["l1"], c["l2"]), atol=1e-7)
        assert np.allclose(T_foot, model.climber.fk(qc), atol=1e-7)
        T_tool = urdf.get_transform("tool", "arm_base")
        assert np.allclose(T_tool, model.fk(qa), atol=1e-7)
        assert np.allclose(T_tool, arm.tool_pose(qa), atol=1e-7)


def test_arm_table2_reading(model):
    """Zero angles: the arm lies straight along x6, turns 90° at the wrist link
    (d10 = −l6) and the tool continues along −z (e_q = (0, 0, −l7))."""
    a = model.params["arm"]
    T = model.fk(np.zeros(7))
    assert np.allclose(T[:3, 3], [a["l3"] + a["l4"] + a["l5"], 0.0, -a["l6"] - a["l7"]], atol=1e-9)


def test_j6_coaxial_with_j3_and_opposite(model):
    """Seed §2.2/§3.1: J6's axis is J3's axis with the opposite direction."""
    qc = np.array([0.3, 1.1, -1.7, 0.4, -0.2])
    F = model.climber.link_frames(qc)
    j3 = F[3]  # joint frame of J3 (axis z through origin)
    K = F[2] @ model.arm_mount  # arm base frame (6) on link2
    assert np.allclose(K[:3, 2], -j3[:3, 2], atol=1e-9)
    off = K[:3, 3] - j3[:3, 3]
    assert np.linalg.norm(np.cross(off, j3[:3, 2])) < 1e-9  # on the axis


def test_mass_below_indicator(model):
    assert 0 < model.total_mass < model.params["indicators"]["max_mass_kg"]


def test_climber_ik_roundtrip_and_refusal(model):
    T = model.climber.fk(np.array([0.2, 1.0, -1.6, 0.6, -0.1]))
    q = model.climber.ik(T)
    assert q is not None and np.allclose(model.climber.fk(q), T, atol=1e-9)
    tilted = T.copy()
    c, s = np.cos(0.2), np.sin(0.2)
    tilted[:3, :3] = tilted[:3, :3] @ np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    assert model.climber.ik(tilted) is None  # φy ≠ 0 is outside Eq. 8


def test_arm_ik_reaches_section4_start(model):
    from planners.cmbot.experiment import Section4Trajectory

    T = Section4Trajectory().start_pose()
    q = model.ik(T, q0=np.radians([90, 45, 50, -85, 0, -15, 180]))
    assert q is not None
    assert np.allclose(model.fk(q), T, atol=1e-6)
    assert model.within_limits(q)


def test_covering_spheres_cover_urdf_arm_geometry(model):
    """Points sampled on every arm collision cylinder lie inside some covering sphere."""
    from robots.cmbot import read_collision_boxes

    arm = ArmKinematics.from_model(model)
    boxes = read_collision_boxes(URDF_PATH)
    links = ["arm_base", *[f"link{i}" for i in range(6, 13)], "tool"]
    rng = np.random.default_rng(3)
    q = rng.uniform(-1, 1, 7)
    F = arm.frames(q)  # 0 base, 1..7 joint frames, 8 tool
    C = arm.sphere_centers(F)
    r = arm.spheres.radius
    for k, link in enumerate(links):
        for b in boxes.get(link, []):
            rad, half_len = b.half[0], b.half[2]
            th = rng.uniform(0, 2 * np.pi, 400)
            z = rng.uniform(-half_len, half_len, 400)
            local = np.column_stack([rad * np.cos(th), rad * np.sin(th), z, np.ones(400)])
            world = (F[k] @ b.origin @ local.T).T[:, :3]
            d = np.linalg.norm(world[:, None, :] - C[None], axis=-1) - r[None]
            assert np.all(d.min(axis=1) <= 1e-9), f"{link}: {d.min(axis=1).max():.4f} m uncovered"
