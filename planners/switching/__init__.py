"""ARA mobile/inch-worm switching control and inch-worm jump planning
(seed 000, Chapter 3 and §5.2.1–5.2.2).

Entry point: :func:`decide_mode` (DESIGN §5).  The jump planner is
:func:`plan_inchworm_jump`; test scenes are in :mod:`planners.switching.scenes`.
"""

from planners.switching.availability import (
    AreaResult,
    PlaneFrame,
    RectangleCandidate,
    area_check,
    exact_foot_placements,
    height_check,
)
from planners.switching.decide import (
    PlaneCandidate,
    SwitchingDecision,
    SwitchingParams,
    check_rigid,
    decide_mode,
    evaluate_planes,
)

__all__ = [
    "AreaResult",
    "PlaneCandidate",
    "PlaneFrame",
    "RectangleCandidate",
    "SwitchingDecision",
    "SwitchingParams",
    "area_check",
    "check_rigid",
    "decide_mode",
    "evaluate_planes",
    "exact_foot_placements",
    "height_check",
]
