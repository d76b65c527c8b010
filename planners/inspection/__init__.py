"""ARA inspection route over a 3D structure model (seed 000
§3.1 Eq. 3.1–3.4, Alg. 2, Alg. 5).

Entry point: :func:`plan_inspection` (``model, *, start, end, params`` →
:class:`InspectionPlan`).  Modules: :mod:`.params` (tunables, ARA defaults),
:mod:`.faces` (driving faces, continuity, foot placements), :mod:`.transitions`
(mobile / inch-worm decision and availability, jump-cost weights),
:mod:`.gaps` (pieces of a disconnected model and jumps across them),
:mod:`.plan` (the chain).  This package only re-exports them.
"""

from planners.inspection.faces import driving_face
from planners.inspection.gaps import Gap
from planners.inspection.params import ARA_ARM_LENGTH_M, ARA_JUMP_REACH_M, InspectionParams
from planners.inspection.plan import InspectionPlan, plan_inspection
from planners.inspection.transitions import MODES, Transition

__all__ = [
    "ARA_ARM_LENGTH_M",
    "ARA_JUMP_REACH_M",
    "MODES",
    "Gap",
    "InspectionParams",
    "InspectionPlan",
    "Transition",
    "driving_face",
    "plan_inspection",
]
