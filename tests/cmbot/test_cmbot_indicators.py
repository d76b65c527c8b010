"""The seed's §2.1 design indicators, measured on the chosen design."""

from __future__ import annotations

import numpy as np

import robots
from planners.cmbot.arm import ArmKinematics
from planners.cmbot.indicators import (
    fastest_climb,
    position_ik,
    robot_mass,
    workspace_and_payload,
    workspace_cuboid,
)

MODEL = robots.load_robot("cmbot")
IND = MODEL.params["indicators"]


def test_mass_below_100_kg():
    assert robot_mass(MODEL) < IND["max_mass_kg"]


def test_cuboid_has_the_seed_dimensions():
    pts = workspace_cuboid(MODEL)
    ext = pts.max(axis=0) - pts.min(axis=0)  # in (6): x up, y along the bar, z across
    assert np.allclose(sorted(ext), sorted(IND["workspace_cuboid_m"]), atol=1e-9)
    assert np.allclose([ext[1], ext[2], ext[0]], IND["workspace_cuboid_m"], atol=1e-9)


def test_workspace_covers_cuboid_with_5kg_payload():
    res = workspace_and_payload(MODEL, n=(4, 3, 4), seeds=8)
    assert res.reachable.all()
    assert res.capacity_kg.min() >= IND["payload_kg"]
    # the position IK really reaches (FK check, independent of its own residual)
    arm = ArmKinematics.from_model(MODEL)
    q, ok = position_ik(arm, res.points[:4], seeds=8)
    k = ok.argmax(axis=1)
    p = arm.tool_pose(q[np.arange(4), k])[:, :3, 3]
    assert np.allclose(p, res.points[:4], atol=1e-4)


def test_a_point_out_of_reach_is_not_reported_reachable():
    arm = ArmKinematics.from_model(MODEL)
    _, ok = position_ik(arm, np.array([[0.0, 0.0, -3.6]]), seeds=6)
    assert not ok.any()


def test_climbing_speed_at_least_0_1_m_s():
    res = fastest_climb(MODEL, steps=4, step_m=(0.33,), phase_time_s=(1.1,))
    assert res.speed_m_s >= IND["climb_speed_m_s"], res.tried
    # and the gate is what limits it: a much faster phase fails
    too_fast = fastest_climb(MODEL, steps=2, step_m=(0.33,), phase_time_s=(0.6,))
    assert too_fast.speed_m_s == 0.0
