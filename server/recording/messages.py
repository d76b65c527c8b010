"""The message of each recording channel, built from one stored (or live) value.

Shared by the MCAP file (:mod:`server.recording.mcap`) and the live Foxglove
server (:mod:`server.foxglove_live`), so both carry the same messages; the
schemas are :data:`CHANNELS` (topic → schema name, JSON Schema).
"""

from __future__ import annotations

import base64
from typing import Any

import numpy as np

from server.recording import schemas
from server.recording.captures import ExportCapture, cloud_fields, packed
from server.recording.channels import WORLD_FRAME, FrameSample, quaternion, stamp

CHANNELS: dict[str, tuple[str, dict[str, Any]]] = {
    "/plan/program": ("steelpath.PlannedCommand", schemas.PLANNED),
    "/commands/acknowledged": ("steelpath.AcknowledgedCommand", schemas.ACKED),
    "/robot/state": ("steelpath.RobotState", schemas.STATE),
    "/operator": ("foxglove.Log", schemas.LOG),
    "/tf": ("foxglove.FrameTransforms", schemas.FRAME_TRANSFORMS),
    "/robot/tool_pose": ("foxglove.PoseInFrame", schemas.POSE_IN_FRAME),
    "/plan/path": ("foxglove.PosesInFrame", schemas.POSES_IN_FRAME),
    "/plan/cloud": ("foxglove.PointCloud", schemas.POINT_CLOUD),
}

#: foxglove.Log levels.
INFO, WARNING = 2, 3


def time_msg(ns: int) -> dict[str, int]:
    """A ``{sec, nsec}`` timestamp of Unix nanoseconds."""
    sec, nsec = stamp(ns)
    return {"sec": sec, "nsec": nsec}


def pose_msg(T: np.ndarray) -> dict[str, dict[str, float]]:
    """A foxglove.Pose of a 4×4 transform."""
    x, y, z, w = quaternion(T[:3, :3])
    p = [float(v) for v in T[:3, 3]]
    return {
        "position": {"x": p[0], "y": p[1], "z": p[2]},
        "orientation": {"x": x, "y": y, "z": z, "w": w},
    }


def point_msg(xyz: np.ndarray) -> dict[str, dict[str, float]]:
    """A foxglove.Pose at ``xyz`` with the identity rotation."""
    T = np.eye(4)
    T[:3, 3] = xyz
    return pose_msg(T)


def program_msgs(program: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """``/plan/program``: each command with its index and planned start time."""
    out, t = [], 0.0
    for i, c in enumerate(program):
        d = max(float(c.get("duration_s", 0.0) or 0.0), 0.0)
        out.append({"index": i, "planned_start_s": t, "duration_s": d, "command": c})
        t += d
    return out


def path_msg(ns: int, path: np.ndarray) -> dict[str, Any]:
    """``/plan/path``: the planned positions in the world frame."""
    return {
        "timestamp": time_msg(ns),
        "frame_id": WORLD_FRAME,
        "poses": [point_msg(p) for p in path],
    }


def cloud_msg(ns: int, points: np.ndarray) -> dict[str, Any]:
    """``/plan/cloud``: float32 x y z points in the world frame."""
    return {
        "timestamp": time_msg(ns),
        "frame_id": WORLD_FRAME,
        "pose": point_msg(np.zeros(3)),
        "point_stride": 12,
        "fields": [
            {"name": n, "offset": 4 * k, "type": schemas.FLOAT32} for k, n in enumerate("xyz")
        ],
        "data": base64.b64encode(points.astype("<f4").tobytes()).decode(),
    }


def capture_cloud_msg(ns: int, frame: str, c: ExportCapture) -> dict[str, Any]:
    """A capture's points (``/<robot>/camera/points``) in its camera frame."""
    fields, step = cloud_fields(c.intensity is not None)
    kinds = {"f4": schemas.FLOAT32, "u1": schemas.UINT8}
    return {
        "timestamp": time_msg(ns),
        "frame_id": frame,
        "pose": point_msg(np.zeros(3)),
        "point_stride": step,
        "fields": [{"name": n, "offset": o, "type": kinds[k]} for n, o, k in fields],
        "data": base64.b64encode(packed(c)).decode(),
    }


def transforms_msg(ns: int, tfs: list[tuple[str, str, np.ndarray]]) -> dict[str, Any]:
    """``/tf``: the given (parent, child, 4×4) transforms at ``ns``."""
    out = []
    for parent, child, T in tfs:
        pose = pose_msg(T)
        out.append({"timestamp": time_msg(ns), "parent_frame_id": parent, "child_frame_id": child,
                    "translation": pose["position"], "rotation": pose["orientation"]})  # fmt: skip
    return {"transforms": out}


def acked_msg(program: list[dict[str, Any]], idx: int) -> dict[str, Any]:
    """``/commands/acknowledged``: command ``idx`` of the program."""
    c = program[idx] if 0 <= idx < len(program) else {}
    return {"index": idx, "op": str(c.get("op", "")), "command": c}


def state_msg(robot: str, state: dict[str, Any]) -> dict[str, Any]:
    """``/robot/state``: one state report of ``robot``."""
    return {"robot": robot, **state}


def tf_msg(ns: int, sample: FrameSample) -> dict[str, Any]:
    """``/tf``: one transform per placed URDF joint (parent link → child link)."""
    return transforms_msg(ns, sample.transforms)


def tool_pose_msg(ns: int, base: str, sample: FrameSample) -> dict[str, Any] | None:
    """``/robot/tool_pose``: the chain tip in ``base``, or ``None`` (not placed)."""
    if not np.isfinite(sample.tip_pose).all():
        return None
    return {"timestamp": time_msg(ns), "frame_id": base, "pose": pose_msg(sample.tip_pose)}


def log_msg(ns: int, level: int, message: str, name: str) -> dict[str, Any]:
    """``/operator``: a foxglove.Log line."""
    return {
        "timestamp": time_msg(ns),
        "level": level,
        "message": message,
        "name": name,
        "file": "",
        "line": 0,
    }
