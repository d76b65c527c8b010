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

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from robots.model import RobotModel, read_params

HERE = Path(__file__).resolve().parent
URDF_PATH = HERE / "sbg_climber.urdf"
PARAMS_PATH = HERE / "params.toml"

JOINT_NAMES = [
    "wheel_fl_joint",
    "wheel_fr_joint",
    "wheel_rl_joint",
    "wheel_rr_joint",
    "lift_arm_joint",
]
ARM_INDEX = 4


def _rpy_matrix(r: float, p: float, y: float) -> np.ndarray:
    """URDF fixed-axis roll-pitch-yaw: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr, cp, sp, cy, sy = (
        math.cos(r),
        math.sin(r),
        math.cos(p),
        math.sin(p),
        math.cos(y),
        math.sin(y),
    )
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def _axis_angle(axis: np.ndarray, theta: float) -> np.ndarray:
    """4×4 rotation by ``theta`` about the unit ``axis`` (Rodrigues)."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    T = np.eye(4)
    T[:3, :3] = np.eye(3) + math.sin(theta) * k + (1.0 - math.cos(theta)) * (k @ k)
    return T


@dataclass
class _Joint:
    name: str
    kind: str
    parent: str
    child: str
    origin: np.ndarray
    axis: np.ndarray


def _parse_urdf(path: Path) -> dict[str, _Joint]:
    """Joints of the URDF keyed by child link (the tree is rooted at base_link)."""
    root = ET.parse(path).getroot()
    joints: dict[str, _Joint] = {}
    for j in root.findall("joint"):
        o = j.find("origin")
        T = np.eye(4)
        if o is not None:
            T[:3, 3] = [float(v) for v in o.get("xyz", "0 0 0").split()]
            T[:3, :3] = _rpy_matrix(*[float(v) for v in o.get("rpy", "0 0 0").split()])
        ax = j.find("axis")
        axis = np.array([float(v) for v in (ax.get("xyz") if ax is not None else "1 0 0").split()])
        parent = j.find("parent").get("link")  # type: ignore[union-attr]
        child = j.find("child").get("link")  # type: ignore[union-attr]
        joints[child] = _Joint(j.get("name", ""), j.get("type", "fixed"), parent, child, T, axis)
    return joints


@dataclass
class SbgClimberModel(RobotModel):
    """Wheels + lifting arm read from the URDF; analytic lift-angle IK.

    Wheel joints are continuous: their limits are ``(-inf, inf)``.
    """

    joints_by_child: dict[str, _Joint] = field(default_factory=dict)
    default_link: str = "arm_tip"

    @property
    def link_names(self) -> list[str]:
        return ["base_link", *self.joints_by_child]

    def _chain(self, link: str) -> list[_Joint]:
        if link != "base_link" and link not in self.joints_by_child:
            raise ValueError(f"unknown link {link!r} for {self.name}; known: {self.link_names}")
        chain: list[_Joint] = []
        while link != "base_link":
            j = self.joints_by_child[link]
            chain.append(j)
            link = j.parent
        return chain[::-1]

    def fk(self, q: np.ndarray, link: str | None = None) -> np.ndarray:
        """4×4 pose of ``link`` (default ``arm_tip``) in ``base_link``."""
        q = self._check_q(q)
        T = np.eye(4)
        for j in self._chain(link or self.default_link):
            T = T @ j.origin
            if j.kind in ("revolute", "continuous"):
                T = T @ _axis_angle(j.axis, float(q[JOINT_NAMES.index(j.name)]))
        return T

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        """6×n geometric Jacobian ``[v; ω]`` of ``arm_tip`` in ``base_link``:
        only the lifting-arm column is non-zero (wheels do not move the tip
        relative to the body)."""
        q = self._check_q(q)
        J = np.zeros((6, self.dof))
        tip = self.fk(q)[:3, 3]
        T = np.eye(4)
        for j in self._chain(self.default_link):
            T = T @ j.origin
            if j.kind in ("revolute", "continuous"):
                z = T[:3, :3] @ j.axis
                J[:3, JOINT_NAMES.index(j.name)] = np.cross(z, tip - T[:3, 3])
                J[3:, JOINT_NAMES.index(j.name)] = z
                T = T @ _axis_angle(j.axis, float(q[JOINT_NAMES.index(j.name)]))
        return J

    def ik(self, T: np.ndarray, q0: np.ndarray | None = None) -> np.ndarray | None:
        """Lift angle that puts ``arm_tip`` at ``T`` (position and orientation).

        The arm turns about the body y axis through the pivot A, so the tip
        lies on a circle of radius ``larm`` around A in the x–z plane:
        ``q = atan2(-(p_x - A_x), -(p_z - A_z))``.  Returns ``None`` when the
        target is off that circle (1e-6 m), its orientation differs from the
        arm's at that angle, or the angle is outside the joint limits.
        Wheel angles are copied from ``q0`` (zeros by default): a wheeled base
        has no pose IK — where it drives is planned by ``planners.sbg``.
        """
        T = np.asarray(T, dtype=float)
        if T.shape != (4, 4):
            raise ValueError(f"ik target must be a 4×4 pose, got shape {T.shape}")
        q = np.zeros(self.dof) if q0 is None else self._check_q(q0).copy()
        pivot = self.joints_by_child["lift_arm"].origin
        rel = pivot[:3, :3].T @ (T[:3, 3] - pivot[:3, 3])
        q_arm = math.atan2(-rel[0], -rel[2])
        q[ARM_INDEX] = q_arm
        if not self.within_limits(q):
            return None
        reached = self.fk(q)
        if np.linalg.norm(reached[:3, 3] - T[:3, 3]) > 1e-6:
            return None
        if np.linalg.norm(reached[:3, :3] - T[:3, :3]) > 1e-6:
            return None
        return q

    def _check_q(self, q: np.ndarray) -> np.ndarray:
        q = np.asarray(q, dtype=float).reshape(-1)
        if q.shape != (self.dof,):
            raise ValueError(
                f"{self.name} expects {self.dof} joint values {JOINT_NAMES}, got {q.shape}"
            )
        return q


def load() -> SbgClimberModel:
    """The climber's kinematic model from its URDF and params.toml."""
    joints = _parse_urdf(URDF_PATH)
    limits = np.empty((len(JOINT_NAMES), 2))
    root = ET.parse(URDF_PATH).getroot()
    for i, name in enumerate(JOINT_NAMES):
        elem = root.find(f"joint[@name='{name}']")
        if elem is None:
            raise ValueError(f"{URDF_PATH} lacks joint {name!r}")
        lim = elem.find("limit")
        if elem.get("type") == "continuous" or lim is None:
            limits[i] = (-np.inf, np.inf)
        else:
            limits[i] = (float(lim.get("lower", "0")), float(lim.get("upper", "0")))
    return SbgClimberModel(
        name="sbg_climber",
        urdf_path=URDF_PATH,
        joint_names=list(JOINT_NAMES),
        joint_limits=limits,
        params=read_params(PARAMS_PATH),
        joints_by_child=joints,
    )
