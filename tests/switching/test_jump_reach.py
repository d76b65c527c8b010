"""Reach of the ARA arm for inch-worm jumps (seed §3.2): the exact
wrist-distance bound, the landing test without RRT, the mobile IK seed."""

from __future__ import annotations

from typing import Any

import numpy as np

from planners.switching.jump import (
    JumpParams,
    JumpRobot,
    arm_length,
    landing_configurations,
    wrist_distance,
)
from robots import load_robot

ARA: Any = load_robot("ara")


def test_wrist_distance_never_exceeds_the_arm_brute_force() -> None:
    """Every configuration (2 000 random, inside the limits) puts foot 1 at
    a pose whose wrist distance is ≤ link2 + link3 + link4; the straight
    (mobile) arm reaches the bound exactly."""
    rng = np.random.default_rng(3)
    lo, hi = ARA.joint_limits[:, 0], ARA.joint_limits[:, 1]
    Q = rng.uniform(lo, hi, (2000, 6))
    E = ARA.fk_all(Q)[:, -1]
    d = np.array([wrist_distance(T, ARA) for T in E])
    assert arm_length(ARA) == 0.5
    assert d.max() <= 0.5 + 1e-9
    # Independent: joint 2 and joint 5 origins from the link frames.
    F = ARA.fk_all(Q)
    assert np.allclose(d, np.linalg.norm(F[:, 5, :3, 3] - F[:, 2, :3, 3], axis=1), atol=1e-9)
    assert abs(wrist_distance(ARA.fk(ARA.q_mobile)) - 0.5) < 1e-9


def test_landing_configurations_out_of_reach_and_free() -> None:
    rob = JumpRobot.from_model(ARA)
    far = np.eye(4)
    far[:3, 3] = (0.7, 0.0, 0.0)
    p = JumpParams()
    assert len(landing_configurations(rob, far, obstacles=np.zeros((0, 3)), params=p)) == 0
    near = np.eye(4)
    near[:3, 3] = (0.35, 0.0, 0.0)  # ahead of foot 2, on its floor
    Q = landing_configurations(rob, near, obstacles=np.zeros((0, 3)), params=p, limit=2)
    assert 1 <= len(Q) <= 2
    E = ARA.fk_all(Q)[:, -1]
    assert np.allclose(E[:, :3, 3], near[:3, 3], atol=1e-4)


def test_the_straight_arm_is_found_with_the_mobile_seed() -> None:
    """Foot 2 landing one spacing ahead of foot 1 is the singular straight
    arm: the IK from random seeds alone rarely converges to it, seeded with
    the mobile configuration it does at once."""
    T = ARA.fk(ARA.q_mobile)
    sols = ARA.ik_solutions(T, q0=ARA.q_mobile, n_seeds=4, seed=0)
    assert len(sols) and np.allclose(sols[0], 0.0, atol=1e-6)
