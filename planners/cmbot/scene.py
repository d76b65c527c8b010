"""Where CMBOT stands and what its arm must avoid (seed §3.2 Fig. 12, §4 Fig. 21).

The arm works with both feet on the bar in the contracted *work stance*
(feet ``work_foot_distance_m`` apart, φy = 0).  Its base frame (6) = (K) then
has x up, y forward along the bar and z across (J6 coaxial with J3, z_6 =
−z_3).  Obstacles — guardrail and structure from
:class:`~planners.cmbot.guardrail.Guardrail`, and the climbing mechanism's
own URDF collision boxes — are expressed in (K) as cuboids.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from planners.cmbot.climbing_kinematics import climber_ik_batch
from planners.cmbot.distance import Cuboid
from planners.cmbot.guardrail import Guardrail
from planners.errors import UnreachableError

CLIMBER_LINKS = ["foot_rear", "link1", "link2", "link3", "link4", "link5", "foot_front"]


def work_stance(model: Any) -> np.ndarray:
    """Climbing joints (5,) of the work stance (seed §3.1: both feet on the bar, φy = φz = 0)."""
    c = model.params["climber"]
    q, ok = climber_ik_batch(
        np.array([c["work_foot_distance_m"], 0.0, 0.0]),
        0.0,
        c["l1"],
        c["l2"],
        model.climber.joint_limits,
    )
    if not ok:
        raise UnreachableError("work_foot_distance_m is not reachable by the climbing chain")
    return q


def translation(x: float, y: float = 0.0, z: float = 0.0) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = [x, y, z]
    return T


def arm_base_pose(model: Any, q_climb: np.ndarray, T_world_rear: np.ndarray) -> np.ndarray:
    """World pose of the arm base frame (6) for climbing joints ``q_climb`` (…,5)."""
    F = model.climber.link_frames(q_climb)
    return T_world_rear @ F[..., 2, :, :] @ model.arm_mount


def climber_boxes(model: Any, q_climb: np.ndarray, T_world_rear: np.ndarray) -> list[Cuboid]:
    """The climbing mechanism's URDF collision boxes in the world (group ``"climber"``)."""
    F = T_world_rear @ model.climber.link_frames(q_climb)
    out = []
    for k, link in enumerate(CLIMBER_LINKS):
        for i, b in enumerate(model.collision_boxes.get(link, [])):
            T = F[k] @ b.origin
            out.append(Cuboid(T[:3, 3], b.half, T[:3, :3], f"{link}.{i}", "climber"))
    return out


def climber_box_layout(model: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """The climbing mechanism's collision boxes in their links: link frame index
    (into ``link_frames``, CLIMBER_LINKS order) (M,), box origin in that link
    (M,4,4), half extents (M,3) and names (M,)."""
    frames, origins, halves, names = [], [], [], []
    for k, link in enumerate(CLIMBER_LINKS):
        for i, b in enumerate(model.collision_boxes.get(link, [])):
            frames.append(k)
            origins.append(b.origin)
            halves.append(b.half)
            names.append(f"{link}.{i}")
    return (
        np.array(frames, dtype=int),
        np.array(origins).reshape(-1, 4, 4),
        np.array(halves).reshape(-1, 3),
        names,
    )


def climber_box_arrays(
    model: Any, q_climb: np.ndarray, T_world_rear: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """Vectorised :func:`climber_boxes` over time: centres (T,M,3), half
    extents (M,3), rotations (T,M,3,3) and names (M,)."""
    F = np.asarray(T_world_rear)[..., None, :, :] @ model.climber.link_frames(q_climb)
    frames, origins, halves, names = climber_box_layout(model)
    T = F[..., frames, :, :] @ origins
    return T[..., :3, 3], halves, T[..., :3, :3], names


@dataclass(frozen=True)
class ArmScene:
    """Obstacles for the arm in its base frame (6): cuboids and the world pose of (6)."""

    boxes: list[Cuboid]
    T_world_base: np.ndarray
    rear_foot_x: float

    @property
    def gravity(self) -> np.ndarray:
        """Gravity (3,) in (6) [m/s²]."""
        return self.T_world_base[:3, :3].T @ np.array([0.0, 0.0, -9.81])


def arm_scene(
    model: Any, guardrail: Guardrail, rear_foot_x: float, reach_m: float = 3.6
) -> ArmScene:
    """Obstacles within ``reach_m`` along the bar of a robot in its work stance
    with the rear foot at ``rear_foot_x`` (metres along the bar)."""
    q = work_stance(model)
    T_wr = translation(rear_foot_x)
    T_wk = arm_base_pose(model, q, T_wr)
    T_kw = np.linalg.inv(T_wk)
    x0 = T_wk[0, 3]
    world = guardrail.boxes(x0 - reach_m, x0 + reach_m) + climber_boxes(model, q, T_wr)
    return ArmScene([b.transformed(T_kw) for b in world], T_wk, rear_foot_x)
