"""3D structure model of a scanned steel structure (DESIGN §10): members
with section profile and faces, joints, member graph, per-point labels.

Entry point :func:`model_structure` (:func:`model_structure_tiled` for
whole spans, in overlapping tiles); contract in :mod:`.model`; stages in
:mod:`.pipeline`.  This package only re-exports.
"""

from planners.structure.model import FACE_KINDS, PROFILES, Face, Joint, Member, StructureModel
from planners.structure.params import StructureParams
from planners.structure.pipeline import model_structure
from planners.structure.tiles import model_structure_tiled

__all__ = [
    "FACE_KINDS",
    "PROFILES",
    "Face",
    "Joint",
    "Member",
    "StructureModel",
    "StructureParams",
    "model_structure",
    "model_structure_tiled",
]
