"""JSON Schemas of the MCAP channels: SteelPath's own and Foxglove's well-known
ones in their JSON form (https://docs.foxglove.dev/docs/visualization/message-schemas/:
``foxglove.Log``, ``foxglove.FrameTransforms``, ``foxglove.PoseInFrame``,
``foxglove.PosesInFrame``, ``foxglove.PointCloud``; ``bytes`` fields are
base64 strings, timestamps ``{sec, nsec}``)."""

from __future__ import annotations

from typing import Any

_NUM = {"type": "number"}
_TIME = {
    "type": "object",
    "properties": {"sec": {"type": "integer", "minimum": 0}, "nsec": {"type": "integer"}},
}
_VEC3 = {"type": "object", "properties": {"x": _NUM, "y": _NUM, "z": _NUM}}
_QUAT = {"type": "object", "properties": {"x": _NUM, "y": _NUM, "z": _NUM, "w": _NUM}}
_POSE = {"type": "object", "properties": {"position": _VEC3, "orientation": _QUAT}}

PLANNED: dict[str, Any] = {
    "type": "object",
    "title": "steelpath.PlannedCommand",
    "properties": {
        "index": {"type": "integer"},
        "planned_start_s": _NUM,
        "duration_s": _NUM,
        "command": {"type": "object"},
    },
}
ACKED: dict[str, Any] = {
    "type": "object",
    "title": "steelpath.AcknowledgedCommand",
    "properties": {
        "index": {"type": "integer"},
        "op": {"type": "string"},
        "command": {"type": "object"},
    },
}
STATE: dict[str, Any] = {
    "type": "object",
    "title": "steelpath.RobotState",
    "properties": {
        "robot": {"type": "string"},
        "q_rad": {"type": "array", "items": _NUM},
        "odometry_m": {"type": "array", "items": _NUM},
        "lift_rad": _NUM,
        "mode": {"type": "integer"},
        "faults": {"type": "integer"},
        "executing": {"type": "integer"},
        "last_done": {"type": "integer"},
    },
}
LOG: dict[str, Any] = {
    "type": "object",
    "title": "foxglove.Log",
    "properties": {
        "timestamp": _TIME,
        "level": {"type": "integer", "description": "1 debug, 2 info, 3 warning, 4 error"},
        "message": {"type": "string"},
        "name": {"type": "string"},
        "file": {"type": "string"},
        "line": {"type": "integer"},
    },
}
FRAME_TRANSFORMS: dict[str, Any] = {
    "type": "object",
    "title": "foxglove.FrameTransforms",
    "properties": {
        "transforms": {
            "type": "array",
            "items": {
                "type": "object",
                "title": "foxglove.FrameTransform",
                "properties": {
                    "timestamp": _TIME,
                    "parent_frame_id": {"type": "string"},
                    "child_frame_id": {"type": "string"},
                    "translation": _VEC3,
                    "rotation": _QUAT,
                },
            },
        }
    },
}
POSE_IN_FRAME: dict[str, Any] = {
    "type": "object",
    "title": "foxglove.PoseInFrame",
    "properties": {"timestamp": _TIME, "frame_id": {"type": "string"}, "pose": _POSE},
}
POSES_IN_FRAME: dict[str, Any] = {
    "type": "object",
    "title": "foxglove.PosesInFrame",
    "properties": {
        "timestamp": _TIME,
        "frame_id": {"type": "string"},
        "poses": {"type": "array", "items": _POSE},
    },
}
POINT_CLOUD: dict[str, Any] = {
    "type": "object",
    "title": "foxglove.PointCloud",
    "properties": {
        "timestamp": _TIME,
        "frame_id": {"type": "string"},
        "pose": _POSE,
        "point_stride": {"type": "integer", "minimum": 0},
        "fields": {
            "type": "array",
            "items": {
                "type": "object",
                "title": "foxglove.PackedElementField",
                "properties": {
                    "name": {"type": "string"},
                    "offset": {"type": "integer", "minimum": 0},
                    "type": {
                        "type": "integer",
                        "description": "NumericType; 1 = UINT8, 7 = FLOAT32",
                    },
                },
            },
        },
        "data": {"type": "string", "contentEncoding": "base64"},
    },
}

#: foxglove.NumericType UINT8 and FLOAT32.
UINT8 = 1
FLOAT32 = 7
