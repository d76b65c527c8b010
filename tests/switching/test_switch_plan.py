"""planners.switching.switch_plan: the ``ara.switch`` entry point agrees with
the decision and jump planners called on their own."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from planners.switching import SwitchingParams, decide_mode
from planners.switching.jump import JumpParams
from planners.switching.jump_checks import foot_inside_surface, joint_limit_excess, speed_ratio
from planners.switching.scenes import make_scene
from planners.switching.switch_plan import plan_switch


@pytest.fixture(scope="module")
def ara() -> Any:
    from robots import load_robot

    return load_robot("ara")


def _foot(ara: Any) -> tuple[float, float]:
    return float(ara.params["foot"]["length_m"]), float(ara.params["foot"]["width_m"])


def test_without_a_jump_it_is_the_decision(ara: Any) -> None:
    scene = make_scene("perpendicular", 0)
    kw = dict(camera_to_base=scene.camera_to_base, base_height=0.0, foot=_foot(ara))
    out = plan_switch(ara, scene.points, params=SwitchingParams(), jump=None, **kw)
    alone = decide_mode(scene.points, params=SwitchingParams(), **kw)
    assert out.decision.summary() == alone.summary()
    assert out.decision.mode == "inchworm"
    assert out.jump is None and out.jump_error is None


@pytest.mark.slow
def test_the_jump_and_its_recomputed_checks(ara: Any) -> None:
    scene = make_scene("perpendicular", 0)
    stages: list[str] = []
    out = plan_switch(
        ara,
        scene.points,
        camera_to_base=scene.camera_to_base,
        base_height=0.0,
        foot=_foot(ara),
        params=SwitchingParams(),
        jump=JumpParams(seed=0),
        progress=lambda f, s: stages.append(s),
    )
    assert stages == ["switching decision", "inch-worm jump"]
    assert out.jump is not None, out.jump_error
    Q = out.jump.joint_trajectory
    assert out.speed_ratio == speed_ratio(Q, out.jump.times, ara.max_speed) <= 1.0
    assert out.joint_limit_excess_rad == joint_limit_excess(Q, ara.joint_limits) == 0.0
    assert out.surface is not None
    assert out.foot1_inside == foot_inside_surface(
        out.jump.foot1_requested, _foot(ara), out.surface, 0.01
    )
    assert np.all(np.isfinite(Q))
