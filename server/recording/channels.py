"""What a recording derives from stored data, shared by the MCAP and the ROS 2 bag.

Nothing here is made up: each value comes from a stored row or array, or is
computed from one with the robot's own kinematics.

* :func:`planned_path` — the plan's Cartesian path: the stored array
  ``path_xyz`` (``demo.route``, ``ara.navigate``, ``sbg.inspect``: the route's
  positions in the plan's world frame, m) or ``nozzle_tip`` (``blast``: the
  nozzle tip along the motion).  Positions only: the arrays hold no
  orientation, so the poses are written with the identity rotation.  Kinds
  whose plan is a joint trajectory (``ara.switch``, ``cmbot.*``) or a route on
  a structure model without one (``ara.inspect``) have none: ``None`` and why.
* :func:`plan_cloud` — the stored cloud the plan's params name
  (``cloud_id``), stride-thinned to at most :data:`MAX_CLOUD_POINTS` points
  (every ``stride``-th point, in stored order); plans of a sample scene name
  no stored cloud and get none.
* :class:`RobotFrames` — per state report, the robot's link frames from its
  URDF at the *reported* joints (pinocchio forward kinematics of
  :mod:`robots.urdf_model`): one transform per URDF joint, parent link →
  child link, and the pose of the main chain's tip link in the URDF root
  link.  State reports carry joints and wheel odometry but no base pose, so
  the root link is not placed in the world frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import datetime
from typing import TYPE_CHECKING, Any

import numpy as np

from server.store.records import PlanRecord

if TYPE_CHECKING:
    from server.store.store import Store

#: At most this many cloud points are written (stride-thinned above it).
MAX_CLOUD_POINTS = 200_000
#: Stored arrays holding a plan's Cartesian path, first found wins.
PATH_ARRAYS = ("path_xyz", "nozzle_tip")
#: Frame of the planned path and cloud (the plan's world frame, metres).
WORLD_FRAME = "world"


def iso_ns(ts: str) -> int:
    """Unix nanoseconds of an ISO-8601 time stored by the service."""
    return round(datetime.fromisoformat(ts).timestamp() * 1e9)


def stamp(ns: int) -> tuple[int, int]:
    """(seconds, nanoseconds) of Unix nanoseconds."""
    return ns // 1_000_000_000, ns % 1_000_000_000


def planned_path(plan: PlanRecord) -> tuple[np.ndarray | None, str]:
    """The plan's path positions (N,3) and where they come from, or ``None``
    and why there is none."""
    for name in PATH_ARRAYS:
        if name in plan.arrays:
            xyz = np.asarray(plan.array(name), dtype=np.float64).reshape(-1, 3)
            xyz = xyz[np.isfinite(xyz).all(axis=1)]
            return xyz, f"stored array {name!r} of plan {plan.id} ({len(xyz)} poses)"
    return None, f"a {plan.kind} plan stores no Cartesian path (none of {list(PATH_ARRAYS)})"


@dataclass(frozen=True)
class PlanCloud:
    """The plan's stored cloud as written: ``points`` (M,3) float32 or ``None``."""

    points: np.ndarray | None
    note: str
    cloud_id: str | None = None
    stored_points: int = 0
    stride: int = 1


def thin_cloud(points: np.ndarray, cloud_id: str | None = None) -> PlanCloud:
    """Every ``stride``-th point so that at most :data:`MAX_CLOUD_POINTS` remain."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    pts = pts[np.isfinite(pts).all(axis=1)]
    stride = max(1, math.ceil(len(pts) / MAX_CLOUD_POINTS))
    kept = np.ascontiguousarray(pts[::stride], dtype=np.float32)
    note = (
        f"stored cloud {cloud_id} ({len(pts)} points), every {stride}. point kept "
        f"({len(kept)} points, at most {MAX_CLOUD_POINTS})"
    )
    return PlanCloud(kept, note, cloud_id, len(pts), stride)


def plan_cloud(store: Store, plan: PlanRecord) -> PlanCloud:
    """The stored cloud named by the plan's ``cloud_id``, thinned; or why none."""
    from server.store.store import NotFoundError

    cid = plan.params.get("cloud_id")
    if not isinstance(cid, str) or not cid:
        return PlanCloud(
            None, f"the plan's params name no stored cloud (cloud_id); kind {plan.kind}"
        )
    try:
        return thin_cloud(store.cloud_points(cid), cid)
    except NotFoundError:
        return PlanCloud(None, f"the plan's cloud {cid} is no longer stored", cid)


@dataclass(frozen=True)
class FrameSample:
    """The robot's frames at one state report."""

    #: (parent link, child link, 4×4 transform of the child in the parent).
    transforms: list[tuple[str, str, np.ndarray]]
    #: 4×4 pose of :attr:`RobotFrames.tip` in :attr:`RobotFrames.base`.
    tip_pose: np.ndarray


class RobotFrames:
    """URDF link frames of one robot at reported joint values.

    A joint's transform (parent → child) depends on that joint's value only,
    so a report of fewer joints than the URDF actuates (CMBOT may report its
    7 arm joints of 12) still places every fixed joint and every reported
    one; an actuated joint the report does not hold is left out.  The tip
    pose is the robot model's main chain (``RobotModel.urdf_chain``: ARA's
    ``foot1_sole`` in ``base_link``, the DENSO ``flange``, CMBOT's ``tool`` in
    ``arm_base``, the SBG climber's ``arm_tip``).
    """

    def __init__(self, robot: str) -> None:
        from robots import load_robot
        from robots.urdf_model import urdf_description, urdf_kinematics

        model = load_robot(robot)  # ValueError: not a robot SteelPath knows
        desc = urdf_description(model.urdf_path)
        self.robot = robot
        actuated = [str(n) for n in desc.actuated_joint_names]
        #: Joint names of a report's ``q_rad`` by its length: every actuated
        #: URDF joint (CMBOT's 12 on the wire) or the model's chain.
        self.names_by_len: dict[int, list[str]] = {
            len(actuated): actuated,
            model.dof: list(model.joint_names),
        }
        self.joints = [(str(j.name), str(j.parent), str(j.child)) for j in desc.robot.joints]
        children = {c for _, _, c in self.joints}
        self.root = next(p for _, p, _ in self.joints if p not in children)
        chain = getattr(model, "urdf_chain", None)
        self._tip_chain = chain
        self.tip = str(chain.tip) if chain is not None else ""
        self.base = str(chain.base or self.root) if chain is not None else self.root
        self._kin = urdf_kinematics(model.urdf_path)
        self._chains: dict[int, Any] = {}

    def joint_names(self, n: int) -> list[str] | None:
        """Names of a report's ``n`` joint values, or ``None`` (not this robot's)."""
        return self.names_by_len.get(n)

    def at(self, q: list[float]) -> FrameSample | None:
        """The frames at joints ``q`` (``None``: a ``q`` this URDF cannot place)."""
        names = self.joint_names(len(q))
        if names is None or not all(math.isfinite(v) for v in q):
            return None
        chain = self._chains.get(len(q))
        if chain is None:
            chain = self._chains[len(q)] = self._kin.chain(names, self.root)
        qa = np.asarray(q, dtype=float)
        value = dict(zip(names, qa, strict=True))
        movable = self._kin.joint_names  # pinocchio's: fixed joints are frames
        placed = [(p, c) for j, p, c in self.joints if j in value or j not in movable]
        pose = {link: chain.fk(qa, link) for link in {x for pc in placed for x in pc}}
        tfs = [(p, c, np.linalg.inv(pose[p]) @ pose[c]) for p, c in placed]
        tip = np.full((4, 4), np.nan)
        if self._tip_chain is not None and all(n in value for n in self._tip_chain.joints):
            tip = self._tip_chain.fk(np.array([value[n] for n in self._tip_chain.joints]))
        return FrameSample(tfs, tip)


def robot_frames(robot: str) -> tuple[RobotFrames | None, str]:
    """The robot's frames helper, or ``None`` and why (an unknown robot)."""
    try:
        return RobotFrames(robot), f"URDF of {robot} at the reported q_rad (pinocchio FK)"
    except ValueError as exc:
        return None, f"no URDF for robot {robot!r}: {exc}"


def quaternion(R: np.ndarray) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a 3×3 rotation matrix (Shepperd's method)."""
    m = np.asarray(R, dtype=float)
    tr = float(np.trace(m))
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        w, x = 0.25 * s, (m[2, 1] - m[1, 2]) / s
        y, z = (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2]) * 2
        w, x = (m[2, 1] - m[1, 2]) / s, 0.25 * s
        y, z = (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s
    elif m[1, 1] > m[2, 2]:
        s = math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2]) * 2
        w, x = (m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s
        y, z = 0.25 * s, (m[1, 2] + m[2, 1]) / s
    else:
        s = math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1]) * 2
        w, x = (m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s
        y, z = (m[1, 2] + m[2, 1]) / s, 0.25 * s
    n = math.sqrt(w * w + x * x + y * y + z * z)
    return float(x / n), float(y / n), float(z / n), float(w / n)
