"""The kinematic model every robot in :func:`robots.load_robot` returns.

A :class:`RobotModel` is built from the robot's URDF (the single source of
truth for joints, limits, collision shapes and display, DESIGN §7) plus its
parameters file.  Subclasses supply ``fk``/``jacobian``/``ik``; the
standard-D-H serial chain of :class:`DHRobotModel` covers the arms.
Single-configuration FK and Jacobians come from pinocchio built from the URDF
(:mod:`robots.urdf_model`); batches of configurations use the numpy chains.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from robots.kinematics import dh_chain_transforms, geometric_jacobian, solve_ik_dls
from robots.urdf_model import UrdfChain, urdf_kinematics


@dataclass
class RobotModel:
    """Kinematics of one robot: joint names and limits, FK, Jacobian and IK.

    ``fk(q, link=None)`` returns the 4×4 pose of ``link`` (default: the last
    link of the main chain) in the robot base frame; ``jacobian(q)`` the 6×n
    geometric Jacobian ``[v; ω]`` of that link in the base frame; ``ik(T)`` a
    joint vector inside the limits reaching ``T``, or ``None``.
    """

    name: str
    urdf_path: Path
    joint_names: list[str]
    joint_limits: np.ndarray
    params: dict[str, Any] = field(default_factory=dict)

    @property
    def dof(self) -> int:
        return len(self.joint_names)

    @property
    def dispatch_joint_limits(self) -> np.ndarray:
        """Limits of every joint a command program drives, in wire order
        (the robot's hardware, which may be more than the kinematic chain of
        ``fk``; CMBOT sends its 5 climbing and 7 arm joints together)."""
        return self.joint_limits

    def within_limits(self, q: np.ndarray, tol: float = 1e-9) -> bool:
        q = np.asarray(q, dtype=float)
        lo, hi = self.joint_limits[:, 0], self.joint_limits[:, 1]
        return bool(np.all(q >= lo - tol) and np.all(q <= hi + tol))

    def fk(self, q: np.ndarray, link: str | None = None) -> np.ndarray:
        raise NotImplementedError(f"{self.name} has no forward kinematics")

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        raise NotImplementedError(f"{self.name} has no Jacobian")

    def ik(self, T: np.ndarray, q0: np.ndarray | None = None) -> np.ndarray | None:
        raise NotImplementedError(f"{self.name} has no inverse kinematics")


@dataclass
class DHRobotModel(RobotModel):
    """Serial arm in the standard Denavit–Hartenberg convention.

    ``T_i = Rz(θ_i + offset_i) · Tz(d_i) · Tx(a_i) · Rx(α_i)``; the base
    transform is applied first and the link names are ``link_names[i]`` for
    the frame after joint ``i``.  The URDF describes the same chain (its last
    link is D-H frame n): one configuration's Jacobian comes from pinocchio,
    batches from :func:`dh_chain_transforms`.
    """

    d: np.ndarray = field(default_factory=lambda: np.zeros(0))
    a: np.ndarray = field(default_factory=lambda: np.zeros(0))
    alpha: np.ndarray = field(default_factory=lambda: np.zeros(0))
    offset: np.ndarray = field(default_factory=lambda: np.zeros(0))
    base: np.ndarray = field(default_factory=lambda: np.eye(4))
    link_names: list[str] = field(default_factory=list)

    def frames(self, q: np.ndarray) -> np.ndarray:
        """All frames ``(n+1, 4, 4)``: base, then after each joint."""
        return dh_chain_transforms(
            np.asarray(q, dtype=float), self.d, self.a, self.alpha, self.offset, self.base
        )

    def fk(self, q: np.ndarray, link: str | None = None) -> np.ndarray:
        frames = self.frames(q)
        if link is None:
            return frames[-1]
        try:
            return frames[self.link_names.index(link) + 1]
        except ValueError:
            raise ValueError(
                f"unknown link {link!r} for {self.name}; known: {self.link_names}"
            ) from None

    @cached_property
    def urdf_chain(self) -> UrdfChain:
        """pinocchio chain of the URDF: ``joint_names`` to the last link."""
        return urdf_kinematics(self.urdf_path).chain(self.joint_names, self.link_names[-1])

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        """6×n geometric Jacobian ``[v; ω]`` of the last frame in the frame
        ``base`` is expressed in (pinocchio for one configuration)."""
        q = np.asarray(q, dtype=float)
        if q.ndim != 1:
            return geometric_jacobian(self.frames(q))
        J = self.urdf_chain.jacobian(q)
        R = self.base[:3, :3]
        return np.vstack([R @ J[:3], R @ J[3:]])

    def ik(self, T: np.ndarray, q0: np.ndarray | None = None) -> np.ndarray | None:
        return solve_ik_dls(self, np.asarray(T, dtype=float), q0)


def read_params(path: Path) -> dict[str, Any]:
    """Read a robot parameters TOML file."""
    with open(path, "rb") as fh:
        return tomllib.load(fh)
