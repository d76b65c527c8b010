"""CMBOT: 5-DoF biped climbing mechanism + 7-DoF redundant arm (seed 002 §2–§3).

``load()`` returns :class:`CmbotModel`, whose default chain is the 7-DoF arm
J6…J12: ``fk(q)`` is the tool point Q (seed Eq. 12) in the arm base frame (6)
and ``jacobian(q)`` its 6×7 geometric Jacobian ``[v; ω]`` (seed Eq. 13).
``model.climber`` is the 5-DoF climbing chain J1…J5 from the stance (rear)
foot sole B to the swing (front) foot sole P (seed Eq. 1) with the closed-form
φy = 0 inverse kinematics of Eq. 8.  Both chains are read from ``cmbot.urdf``
(generated from ``params.toml`` by :mod:`robots.cmbot.urdf`); the closed forms
live in :mod:`robots.cmbot.kinematics`.
"""

from robots.cmbot.model import (
    ARM_JOINTS,
    CLIMB_JOINTS,
    HERE,
    PARAMS_PATH,
    URDF_PATH,
    ClimberModel,
    CmbotChain,
    CmbotModel,
    CollisionBox,
    load,
    read_collision_boxes,
    rz,
)

__all__ = [
    "ARM_JOINTS",
    "CLIMB_JOINTS",
    "HERE",
    "PARAMS_PATH",
    "URDF_PATH",
    "ClimberModel",
    "CmbotChain",
    "CmbotModel",
    "CollisionBox",
    "load",
    "read_collision_boxes",
    "rz",
]
