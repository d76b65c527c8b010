"""The switching decision (seed 000 Eq. 3.1–3.4, Alg. 1–2) and, for
"inchworm", the inch-worm jump (§3.2) with its checks recomputed from the
trajectory (:mod:`planners.switching.jump_checks`).  The ``ara.switch``
kind's entry point, :func:`planners.switching.switch_result.plan_switch_result`,
shapes this outcome into the stored :class:`planners.result.PlanResult`."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from planners.errors import PlannerError
from planners.switching.decide import SwitchingDecision, SwitchingParams, decide_mode
from planners.switching.jump import JumpParams, JumpPlan, plan_inchworm_jump
from planners.switching.jump_checks import (
    SurfaceFrame,
    foot_inside_surface,
    joint_limit_excess,
    speed_ratio,
)


@dataclass(frozen=True)
class SwitchOutcome:
    """What :func:`plan_switch` returns: the decision, and for "inchworm" the
    jump (None when not asked for, or when planning failed: ``jump_error``)
    with its recomputed checks."""

    decision: SwitchingDecision
    jump: JumpPlan | None = None
    jump_error: str | None = None
    surface: SurfaceFrame | None = None
    joint_limit_excess_rad: float = 0.0
    speed_ratio: float = 0.0
    foot1_inside: bool = False


def plan_switch(
    robot: Any,
    points: np.ndarray,
    *,
    camera_to_base: np.ndarray,
    base_height: float,
    foot: tuple[float, float],
    params: SwitchingParams,
    jump: JumpParams | None,
    inside_tol_m: float = 0.01,
    progress: Callable[[float, str], None] | None = None,
) -> SwitchOutcome:
    """The switching function S = S_pa ∧ S_am ∧
    S_hc (Eq. 3.1, :func:`planners.switching.decide.decide_mode`), then, when
    it says "inchworm" and ``jump`` is given, the inch-worm jump (§3.2,
    :func:`planners.switching.jump.plan_inchworm_jump`) onto the chosen
    plane, and the checks of :mod:`planners.switching.jump_checks` recomputed from its trajectory.  A jump that
    cannot be planned (a :class:`planners.errors.PlannerError`) is reported
    in ``jump_error``, not raised: the decision itself still stands."""
    if progress is not None:
        progress(0.05, "switching decision")
    d = decide_mode(
        points, camera_to_base=camera_to_base, base_height=base_height, foot=foot, params=params
    )
    if d.mode != "inchworm" or jump is None:
        return SwitchOutcome(decision=d)
    if progress is not None:
        progress(0.3, "inch-worm jump")
    c = d.chosen
    if c is None:  # decide_mode says "inchworm" only with a chosen plane
        return SwitchOutcome(decision=d, jump_error="no target plane was chosen")
    surface: SurfaceFrame = (c.frame.origin, c.frame.x_axis, c.frame.y_axis, c.area.hull)
    try:
        plan = plan_inchworm_jump(
            robot,
            d.foothold_candidates,
            obstacles=d.points,
            base_height=base_height,
            surface=surface,
            params=jump,
        )
    except PlannerError as exc:
        return SwitchOutcome(decision=d, jump_error=str(exc), surface=surface)
    Q = plan.joint_trajectory
    return SwitchOutcome(
        decision=d,
        jump=plan,
        surface=surface,
        joint_limit_excess_rad=joint_limit_excess(Q, robot.joint_limits),
        speed_ratio=speed_ratio(Q, plan.times, robot.max_speed),
        foot1_inside=foot_inside_surface(plan.foot1_requested, foot, surface, inside_tol_m),
    )
