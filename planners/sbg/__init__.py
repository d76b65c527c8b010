"""Box-girder wall-climber inspection: path, controllers, closed-loop simulation.

Seed 003 (Song et al., *A Path Tracking Method of a Wall-Climbing Robot
towards Autonomous Inspection of Steel Box Girder*, Machines 2022, 10, 256):

- :mod:`~planners.sbg.girder`: girder geometry (deck, U-ribs, lanes, crossbeams).
- :mod:`~planners.sbg.path`: the boustrophedon path of §3 / Fig. 4, 9.
- :mod:`~planners.sbg.corner`: 90° concave corner, Eq. 1–4.
- :mod:`~planners.sbg.trilateration`: d and δ from l2, l3, l4, Eq. 5.
- :mod:`~planners.sbg.preview`: preview-follow, Eq. 6–9.
- :mod:`~planners.sbg.dead_reckoning`: U-turn dead reckoning, Eq. 10–11.
- :mod:`~planners.sbg.camera`: weld lines in the camera's field of view.
- :mod:`~planners.sbg.simulator`: closed-loop kinematic simulator with noise.
- :mod:`~planners.sbg.experiments`: Fig. 12, Fig. 14, §4.3 and the Lx sweep.

Entry point: :func:`plan_inspection` (:mod:`~planners.sbg.pipeline`); the
``sbg.inspect`` kind's is
:func:`planners.sbg.inspection_report.plan_inspection_result` (the plan, the
Fig. 12 comparison and the Lx sweep as a :class:`planners.result.PlanResult`).
``Check`` is :class:`planners.result.Check`.  This package only re-exports.
"""

from planners.result import Check
from planners.sbg.girder import Girder, sample_girders
from planners.sbg.path import InspectionPath, PathSegment, plan_path
from planners.sbg.pipeline import InspectionPlan, Limits, SegmentCommand, plan_inspection
from planners.sbg.robot import CameraParams, ClimberParams
from planners.sbg.simulator import MODE_NAMES, ControllerConfig, NoiseModel, SimResult, simulate

__all__ = [
    "MODE_NAMES",
    "CameraParams",
    "Check",
    "ClimberParams",
    "ControllerConfig",
    "Girder",
    "InspectionPath",
    "InspectionPlan",
    "Limits",
    "NoiseModel",
    "PathSegment",
    "SegmentCommand",
    "SimResult",
    "plan_inspection",
    "plan_path",
    "sample_girders",
    "simulate",
]
