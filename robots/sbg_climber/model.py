"""The sbg_climber robot description: model, kinematics and ``load()``
(see :mod:`robots.sbg_climber` for the robot)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from robots.model import RobotModel, read_params
from robots.urdf_model import UrdfChain, joint_origin, urdf_description, urdf_kinematics

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


@dataclass
class SbgClimberModel(RobotModel):
    """Wheels + lifting arm read from the URDF; analytic lift-angle IK.

    Wheel joints are continuous: their limits are ``(-inf, inf)``.  FK and
    the Jacobian are pinocchio's on the URDF tree (:mod:`robots.urdf_model`).
    """

    link_names: list[str] = field(default_factory=list)
    lift_pivot: np.ndarray = field(default_factory=lambda: np.eye(4))
    default_link: str = "arm_tip"

    @cached_property
    def urdf_chain(self) -> UrdfChain:
        """pinocchio tree with the joints in :data:`JOINT_NAMES` order, tip arm_tip."""
        return urdf_kinematics(self.urdf_path).chain(self.joint_names, self.default_link)

    def fk(self, q: np.ndarray, link: str | None = None) -> np.ndarray:
        """4×4 pose of ``link`` (default ``arm_tip``) in ``base_link``."""
        q = self._check_q(q)
        link = link or self.default_link
        if link not in self.link_names:
            raise ValueError(f"unknown link {link!r} for {self.name}; known: {self.link_names}")
        return self.urdf_chain.fk(q, link)

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        """6×n geometric Jacobian ``[v; ω]`` of ``arm_tip`` in ``base_link``:
        only the lifting-arm column is non-zero (wheels do not move the tip
        relative to the body)."""
        return self.urdf_chain.jacobian(self._check_q(q))

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
        pivot = self.lift_pivot
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
    urdf = urdf_description(URDF_PATH)
    limits = np.empty((len(JOINT_NAMES), 2))
    for i, name in enumerate(JOINT_NAMES):
        j = urdf.joint_map.get(name)
        if j is None:
            raise ValueError(f"{URDF_PATH} lacks joint {name!r}")
        if j.type == "continuous" or j.limit is None:
            limits[i] = (-np.inf, np.inf)
        else:
            limits[i] = (float(j.limit.lower or 0.0), float(j.limit.upper or 0.0))
    return SbgClimberModel(
        name="sbg_climber",
        urdf_path=URDF_PATH,
        joint_names=list(JOINT_NAMES),
        joint_limits=limits,
        params=read_params(PARAMS_PATH),
        link_names=["base_link", *[str(j.child) for j in urdf.joint_map.values()]],
        lift_pivot=joint_origin(URDF_PATH, "lift_arm_joint"),
    )
