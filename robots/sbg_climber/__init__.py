"""Box-girder wall-climbing robot (seed 003, Song et al., Machines 2022).

A 4.08 kg, 230 × 210 × 256 mm differential-drive robot on four magnetic
wheels with a servo lifting arm for 90° concave corners (§2, §3.1), four
laser range finders l1–l4 (Fig. 7), an IMU and a camera.

The kinematic tree is read from ``sbg_climber.urdf``.  Joints, in order:
the four continuous wheels and the revolute lifting arm.  ``fk``/``jacobian``
default to ``arm_tip`` (the end of the only arm chain); ``ik`` solves the
lift angle analytically for an arm-tip target.  A mobile robot has no pose
IK of its base: where it goes is the planners' job (``planners.sbg``).
"""

from robots.sbg_climber.model import (
    ARM_INDEX,
    HERE,
    JOINT_NAMES,
    PARAMS_PATH,
    URDF_PATH,
    SbgClimberModel,
    load,
)

__all__ = [
    "ARM_INDEX",
    "HERE",
    "JOINT_NAMES",
    "PARAMS_PATH",
    "URDF_PATH",
    "SbgClimberModel",
    "load",
]
