"""Reference copy of the hand-written URDF kinematics the robots used before
pinocchio (robots/{ara,cmbot,sbg_climber}/__init__.py up to 2ec2740): an
ElementTree parser, the URDF roll-pitch-yaw matrix R = Rz(y)·Ry(p)·Rx(r) and
Rodrigues joint rotations, walked along the tree from the root.  Only the
tests use it, to show pinocchio reproduces it.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np


def rpy_matrix(r: float, p: float, y: float) -> np.ndarray:
    """URDF fixed-axis roll-pitch-yaw: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def origin(elem: ET.Element | None) -> np.ndarray:
    T = np.eye(4)
    if elem is not None:
        T[:3, 3] = [float(v) for v in elem.get("xyz", "0 0 0").split()]
        T[:3, :3] = rpy_matrix(*[float(v) for v in elem.get("rpy", "0 0 0").split()])
    return T


def axis_angle(axis: np.ndarray, theta: float) -> np.ndarray:
    """4×4 rotation by ``theta`` about the unit ``axis`` (Rodrigues)."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    T = np.eye(4)
    T[:3, :3] = np.eye(3) + np.sin(theta) * k + (1.0 - np.cos(theta)) * (k @ k)
    return T


@dataclass
class Joint:
    name: str
    kind: str
    parent: str
    child: str
    origin: np.ndarray
    axis: np.ndarray


def parse_joints(path: Path) -> dict[str, Joint]:
    """Joints keyed by child link."""
    out: dict[str, Joint] = {}
    for j in ET.parse(path).getroot().findall("joint"):
        ax = j.find("axis")
        axis = np.array([float(v) for v in (ax.get("xyz") if ax is not None else "1 0 0").split()])
        parent = j.find("parent").get("link")  # type: ignore[union-attr]
        child = j.find("child").get("link")  # type: ignore[union-attr]
        out[child] = Joint(
            j.get("name", ""), j.get("type", "fixed"), parent, child, origin(j.find("origin")), axis
        )
    return out


def _path(joints: dict[str, Joint], link: str, base: str) -> list[Joint]:
    chain: list[Joint] = []
    while link != base:
        j = joints[link]
        chain.append(j)
        link = j.parent
    return chain[::-1]


def fk(joints: dict[str, Joint], q: dict[str, float], link: str, base: str) -> np.ndarray:
    """Pose of ``link`` in ``base`` (an ancestor) for joint angles by name."""
    T = np.eye(4)
    for j in _path(joints, link, base):
        T = T @ j.origin
        if j.kind != "fixed":
            T = T @ axis_angle(j.axis, q.get(j.name, 0.0))
    return T


def jacobian(
    joints: dict[str, Joint], q: dict[str, float], names: list[str], link: str, base: str
) -> np.ndarray:
    """6×n geometric Jacobian ``[v; ω]`` of ``link``'s origin in ``base``,
    columns in ``names`` order (zero for joints off the path)."""
    J = np.zeros((6, len(names)))
    tip = fk(joints, q, link, base)[:3, 3]
    T = np.eye(4)
    for j in _path(joints, link, base):
        T = T @ j.origin
        if j.kind != "fixed":
            z = T[:3, :3] @ j.axis
            if j.name in names:
                k = names.index(j.name)
                J[:3, k] = np.cross(z, tip - T[:3, 3])
                J[3:, k] = z
            T = T @ axis_angle(j.axis, q.get(j.name, 0.0))
    return J


def old_cmbot_frames(
    joint_origins: np.ndarray, end_offset: np.ndarray, q: np.ndarray
) -> np.ndarray:
    """The former duplicate arm FK of planners/cmbot/arm.py (Eq. 12)."""
    out = np.empty((len(joint_origins) + 2, 4, 4))
    out[0] = np.eye(4)
    for i in range(len(joint_origins)):
        out[i + 1] = out[i] @ joint_origins[i] @ axis_angle(np.array([0.0, 0.0, 1.0]), q[i])
    out[-1] = out[-2] @ end_offset
    return out
