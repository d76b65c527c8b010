"""Sand-blasting planner (seed 004, Chapters 3–4).

``plan_blasting(surface, ...)`` (DESIGN §5) runs the chain of seed Fig. 3.1:
nozzle model (Eq. 3.1) → hexagonal disc pattern (§3.2.2) → classification
(Eq. 3.2) and boundary editing (§3.2.3, or ours) → sequencing (Eq. 3.3–3.4,
3.15; the seed's GA or ours) → with a robot: IK per spot with the least
joint change (§3.4.1), way-points and speed limits (Eq. 3.12–3.13), and the
force-field ellipsoid clearance (§3.4.2) at every way-point.

The pipeline lives in :mod:`planners.blasting.pipeline` (steps),
:mod:`~planners.blasting.spots` (per-spot poses), :mod:`~planners.blasting.trajectory`
(joint trajectory), :mod:`~planners.blasting.result` (:class:`BlastPlan`) and
:mod:`~planners.blasting.constants`; this package only re-exports them.
"""

from planners.blasting.collision import Box, Obstacles, Spheroids
from planners.blasting.constants import (
    CLEAR_HORIZON_M,
    CLEAR_REL_TOL,
    COVERAGE_TARGET,
    FOCI,
    JOINT_PLANNERS,
    JUMP_RAD,
    KP,
    MAX_TILT_DEG,
    OVERSPRAY_TARGET,
    RETRACT_M,
    RRT_BUDGET_ITER,
    RRT_MAX_ITER,
    SAFETY_M,
    START_POSE_DEG,
    STEP_RAD,
)
from planners.blasting.nozzle import NOZZLES, Nozzle, blast_radius_m
from planners.blasting.pipeline import plan_blasting
from planners.blasting.result import BlastPlan
from planners.blasting.spots import _family_groups, _family_mask, _join_tours
from planners.blasting.surface import Surface
from planners.blasting.trajectory import _via_polylines

__all__ = [
    "CLEAR_HORIZON_M",
    "CLEAR_REL_TOL",
    "COVERAGE_TARGET",
    "FOCI",
    "JOINT_PLANNERS",
    "JUMP_RAD",
    "KP",
    "MAX_TILT_DEG",
    "NOZZLES",
    "OVERSPRAY_TARGET",
    "RETRACT_M",
    "RRT_BUDGET_ITER",
    "RRT_MAX_ITER",
    "SAFETY_M",
    "START_POSE_DEG",
    "STEP_RAD",
    "BlastPlan",
    "Box",
    "Nozzle",
    "Obstacles",
    "Spheroids",
    "Surface",
    "_family_groups",
    "_family_mask",
    "_join_tours",
    "_via_polylines",
    "blast_radius_m",
    "plan_blasting",
]
