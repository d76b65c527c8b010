"""Sampling-based joint-space motion planning (OMPL wrapper); re-exports only."""

from planners.motion.ompl_planner import (
    PLANNERS,
    MotionResult,
    MotionValid,
    Valid,
    interpolate,
    plan_motion,
    segment_validator,
    wrap_angle,
)

__all__ = [
    "PLANNERS",
    "MotionResult",
    "MotionValid",
    "Valid",
    "interpolate",
    "plan_motion",
    "segment_validator",
    "wrap_angle",
]
