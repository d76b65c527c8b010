"""pinocchio kinematics from the URDFs (robots/urdf_model.py) against the former
hand-written URDF kinematics (tests/robots/_reference_kinematics.py), on random
configurations of every robot."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from planners.cmbot.arm import ArmKinematics, rpy_to_matrix
from robots import load_robot
from robots.urdf_model import collision_primitives, joint_origin, link_inertials
from tests.robots import _reference_kinematics as ref

TOL = 1e-9
ROBOTS = ["denso_vm6083", "cmbot", "ara", "sbg_climber"]
MODELS = {name: load_robot(name) for name in ROBOTS}
CMBOT = MODELS["cmbot"]
CHAINS = {
    "denso_vm6083": MODELS["denso_vm6083"],
    "cmbot.arm": CMBOT,
    "cmbot.climber": CMBOT.climber,
    "ara": MODELS["ara"],
    "sbg_climber": MODELS["sbg_climber"],
}
# The link every chain's fk/jacobian defaults to, and the frame they are expressed in.
TIP_BASE = {
    "denso_vm6083": ("flange", "base_link"),
    "cmbot.arm": ("tool", "arm_base"),
    "cmbot.climber": ("foot_front", "foot_rear"),
    "ara": ("foot1_sole", "base_link"),
    "sbg_climber": ("arm_tip", "base_link"),
}

unit = arrays(np.float64, 7, elements=st.floats(0.0, 1.0))


def _q(model, u: np.ndarray) -> np.ndarray:
    """A configuration inside the limits (continuous joints over ±π)."""
    lo = np.maximum(model.joint_limits[:, 0], -np.pi)
    hi = np.minimum(model.joint_limits[:, 1], np.pi)
    return lo + u[: model.dof] * (hi - lo)


def _links(name: str, model) -> list[str]:
    if name == "denso_vm6083":
        return ["base_link", "link1", "link2", "link3", "link4", "link5", "link6", "flange"]
    return list(model.link_names)


@pytest.mark.parametrize("name", list(CHAINS))
@settings(max_examples=40, deadline=None)
@given(u=unit)
def test_pinocchio_fk_and_jacobian_match_the_former_urdf_kinematics(name: str, u: np.ndarray):
    model = CHAINS[name]
    joints = ref.parse_joints(model.urdf_path)
    q = _q(model, u)
    qd = dict(zip(model.joint_names, q, strict=True))
    tip, base = TIP_BASE[name]
    for link in _links(name, model):
        expected = ref.fk(joints, qd, link, base)
        np.testing.assert_allclose(model.fk(q, link), expected, atol=TOL, rtol=0)
    np.testing.assert_allclose(model.fk(q), ref.fk(joints, qd, tip, base), atol=TOL, rtol=0)
    J_ref = ref.jacobian(joints, qd, list(model.joint_names), tip, base)
    np.testing.assert_allclose(model.jacobian(q), J_ref, atol=TOL, rtol=0)


@pytest.mark.parametrize("name", ["denso_vm6083", "cmbot.arm", "cmbot.climber", "ara"])
@settings(max_examples=20, deadline=None)
@given(u=unit)
def test_single_configuration_pinocchio_agrees_with_the_batched_numpy_chain(
    name: str, u: np.ndarray
):
    model = CHAINS[name]
    q = _q(model, u)
    Q = np.stack([q, q[::-1].copy() * 0.5])
    batched = model.fk(Q)
    for k in range(2):
        np.testing.assert_allclose(model.fk(Q[k]), batched[k], atol=TOL, rtol=0)
    if name != "denso_vm6083":  # the D-H chain's batched Jacobian is not batched
        Jb = model.jacobian(Q)
        np.testing.assert_allclose(model.jacobian(Q[0]), Jb[0], atol=TOL, rtol=0)


@settings(max_examples=20, deadline=None)
@given(u=unit, yaw=st.floats(-np.pi, np.pi), shift=arrays(np.float64, 3, elements=st.floats(-2, 2)))
def test_denso_base_moves_pinocchio_fk_and_jacobian(u: np.ndarray, yaw: float, shift: np.ndarray):
    """``with_base`` places the pinocchio chain in the world like the D-H frames."""
    base = np.eye(4)
    base[:3, :3] = rpy_to_matrix(0.3, -0.2, yaw)
    base[:3, 3] = shift
    robot = MODELS["denso_vm6083"].with_base(base)
    q = _q(robot, u)
    np.testing.assert_allclose(robot.fk(q), robot.frames(q)[-1], atol=TOL, rtol=0)
    from robots.kinematics import geometric_jacobian

    np.testing.assert_allclose(
        robot.jacobian(q), geometric_jacobian(robot.frames(q)), atol=TOL, rtol=0
    )


@pytest.mark.parametrize("name", ROBOTS)
def test_loader_reads_the_same_origins_shapes_and_masses_as_the_former_parsers(name: str):
    import xml.etree.ElementTree as ET

    path = MODELS[name].urdf_path
    root = ET.parse(path).getroot()
    for j in root.findall("joint"):
        np.testing.assert_allclose(
            joint_origin(path, j.get("name")), ref.origin(j.find("origin")), atol=1e-15
        )
    cols = [
        (link.get("name"), c) for link in root.findall("link") for c in link.findall("collision")
    ]
    prims = collision_primitives(path)
    assert len(prims) == len(cols) > 0
    for p, (link, c) in zip(prims, cols, strict=True):
        assert p.link == link
        assert p.kind == next(iter(c.find("geometry"))).tag
        np.testing.assert_allclose(p.origin, ref.origin(c.find("origin")), atol=1e-15)
    inertials = link_inertials(path)
    for link in root.findall("link"):
        el = link.find("inertial")
        if el is not None:
            got = inertials[link.get("name")]
            assert got.mass == float(el.find("mass").get("value"))
            np.testing.assert_allclose(got.com, ref.origin(el.find("origin"))[:3, 3])


@settings(max_examples=20, deadline=None)
@given(u=unit)
def test_cmbot_arm_frames_are_the_robot_chain_not_a_copy(u: np.ndarray):
    arm = ArmKinematics.from_model(CMBOT)
    q = _q(CMBOT, u)
    expected = ref.old_cmbot_frames(CMBOT.joint_origins, CMBOT.end_offset, q)
    np.testing.assert_allclose(arm.frames(q), expected, atol=TOL, rtol=0)
    np.testing.assert_allclose(arm.tool_pose(q), expected[-1], atol=TOL, rtol=0)
    np.testing.assert_allclose(
        arm.jacobian(q), arm.jacobian_from_frames(expected), atol=TOL, rtol=0
    )


@given(rpy=arrays(np.float64, 3, elements=st.floats(-np.pi, np.pi)))
def test_rpy_to_matrix_is_the_fixed_axis_convention(rpy: np.ndarray):
    np.testing.assert_allclose(rpy_to_matrix(*rpy), ref.rpy_matrix(*rpy), atol=1e-14)


@pytest.mark.parametrize("name", ROBOTS)
def test_models_pickle_with_their_pinocchio_chain(name: str):
    """Plans run in worker processes: a model whose chain was built must pickle."""
    model = MODELS[name]
    q = _q(model, np.full(7, 0.3))
    T = model.fk(q)
    again = pickle.loads(pickle.dumps(model))
    np.testing.assert_allclose(again.fk(q), T, atol=0)
