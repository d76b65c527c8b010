"""DENSO VM-6083 six-axis arm (seed 004's sand-blasting robot).

Kinematics are the standard D-H chain of DESIGN §7 (``params.toml``); FK is
at the tool flange in the robot base frame (``base`` places that frame in the
world).  The blasting nozzle is *not* part of the chain: the planner applies
it as a fixed transform along the flange z axis.

The inverse kinematics is closed-form (spherical wrist, no shoulder offset):
up to eight solutions (shoulder front/back × elbow up/down × wrist flip),
each joint taken in its 2π-equivalent nearest the reference within the
limits; :meth:`DensoVM6083.ik` returns the one with the least joint change
(seed §3.4.1.1), the largest single-joint move first because that move sets
the motion time under the 30°/s blasting limit.
"""

from robots.denso_vm6083.model import (
    HERE,
    JOINT_NAMES,
    PARAMS_PATH,
    URDF_LINKS,
    URDF_PATH,
    DensoVM6083,
    load,
    select_least_change,
)

__all__ = [
    "HERE",
    "JOINT_NAMES",
    "PARAMS_PATH",
    "URDF_LINKS",
    "URDF_PATH",
    "DensoVM6083",
    "load",
    "select_least_change",
]
