"""The inch-worm jump with ``motion_backend="ompl"``: the same assertions as
tests/switching/test_jump.py (phases, limits, speeds, feet on target, brute
force clearance), imported and run on the OMPL-planned step-down jump."""

from __future__ import annotations

import numpy as np
import pytest

from planners.switching.decide import decide_mode
from planners.switching.jump import JumpParams, plan_inchworm_jump
from planners.switching.scenes import make_scene
from tests.switching.test_jump import (  # same checks, collected here with the fixture below
    ARA,
    test_clearance_matches_brute_force,
    test_feet_reach_their_targets,
    test_phase_sequence_and_magnets,
    test_trajectory_respects_limits_and_speeds,
)

# Tens of seconds (planning on the seed scenes): `make test` runs it, not `make test-fast`.
pytestmark = pytest.mark.slow

__all__ = [
    "test_clearance_matches_brute_force",
    "test_feet_reach_their_targets",
    "test_phase_sequence_and_magnets",
    "test_trajectory_respects_limits_and_speeds",
]


@pytest.fixture(scope="module")
def step_down():
    sc = make_scene("step_down_7cm", 0)
    d = decide_mode(sc.points, camera_to_base=sc.camera_to_base, base_height=0.0, foot=(0.18, 0.12))
    c = d.chosen
    plan = plan_inchworm_jump(
        ARA,
        d.foothold_candidates,
        obstacles=d.points,
        surface=(c.frame.origin, c.frame.x_axis, c.frame.y_axis, c.area.hull),
        params=JumpParams(motion_backend="ompl"),
    )
    return sc, d, plan


def test_unknown_backend_is_rejected():
    from planners.errors import InvalidInputError
    from planners.switching.rrt import plan_path

    with pytest.raises(InvalidInputError):
        plan_path(
            np.zeros(2), np.ones((1, 2)), lambda Q: np.ones(len(Q), bool),
            lower=-np.ones(2), upper=2 * np.ones(2), rng=np.random.default_rng(0),
            backend="moveit",
        )  # fmt: skip
