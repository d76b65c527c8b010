"""3D structure model of a scanned steel structure (DESIGN §10): members
with section profile and faces, joints, member graph, per-point labels.

Entry point :func:`model_structure`; contract in :mod:`.model`; stages in
:mod:`.pipeline`.  This package only re-exports.
"""

from planners.structure.model import FACE_KINDS, PROFILES, Face, Joint, Member, StructureModel
from planners.structure.params import StructureParams
from planners.structure.pipeline import model_structure

__all__ = [
    "FACE_KINDS",
    "PROFILES",
    "Face",
    "Joint",
    "Member",
    "StructureModel",
    "StructureParams",
    "model_structure",
]
