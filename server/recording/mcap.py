"""A run as an MCAP file (issue #16 §3: "recorded runs"), for Foxglove / Lichtblick.

Everything comes from what the service stored while the execution ran:
the plan's compiled program and arrays, the stored cloud its params name, the
acknowledgement time of each command, the robot's state reports while the
execution was active (mirrored at 2 Hz by the dispatch engine) and the audit
trail of the plan and the execution (approve, dispatch, pause, resume, abort,
E-stop…).  Messages are JSON with a JSON Schema per channel, so Foxglove
decodes them without plugins:

* ``/plan/program`` (``steelpath.PlannedCommand``): every command of the
  program at the run's start, with its index and planned start time;
* ``/commands/acknowledged`` (``steelpath.AcknowledgedCommand``): each
  command at the time the robot acknowledged it;
* ``/robot/state`` (``steelpath.RobotState``): the state reports — joints
  (rad), odometry (m), lift, mode, faults, the command executing — which the
  Plot panel plots field by field;
* ``/operator`` (``foxglove.Log``): operator and system actions as log lines;
* ``/tf`` (``foxglove.FrameTransforms``): per state report, one transform per
  URDF joint (parent link → child link) at the reported joints
  (:class:`server.recording.channels.RobotFrames`); the robot's root link is
  not placed in the world (the reports hold no base pose);
* ``/robot/tool_pose`` (``foxglove.PoseInFrame``): per state report, the pose
  of the robot model's chain tip in its chain base link, by the same FK;
* ``/plan/path`` (``foxglove.PosesInFrame``, frame ``world``): the planned
  path at the run's start (:func:`server.recording.channels.planned_path`;
  positions, identity orientation);
* ``/plan/cloud`` (``foxglove.PointCloud``, frame ``world``, float32 x y z):
  the plan's stored cloud at the run's start, thinned to ≤ 200 000 points.

A channel with nothing to hold (a kind without a path, a plan without a
stored cloud, an unknown robot) is left out; the ``channels`` metadata record
says, per channel, where its data came from or why it is absent, and the
``cloud`` record how the cloud was thinned.  Timestamps are Unix
nanoseconds.  :func:`write_recording` returns the message count per channel
written (the same counts the MCAP summary holds).
"""

from __future__ import annotations

import base64
import json
from collections.abc import Sequence
from typing import IO, Any

import numpy as np
from mcap.writer import CompressionType, Writer

from server.recording import schemas
from server.recording.channels import (
    WORLD_FRAME,
    PlanCloud,
    iso_ns,
    planned_path,
    quaternion,
    robot_frames,
    stamp,
)
from server.store.records import AuditEvent, ExecutionRecord, PlanRecord

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

#: Audit actions logged as warnings.
_WARN = {"estop", "abort", "fault", "interrupt"}

__all__ = ["CHANNELS", "iso_ns", "write_recording"]


def _time(ns: int) -> dict[str, int]:
    sec, nsec = stamp(ns)
    return {"sec": sec, "nsec": nsec}


def _pose(T: np.ndarray) -> dict[str, dict[str, float]]:
    x, y, z, w = quaternion(T[:3, :3])
    p = [float(v) for v in T[:3, 3]]
    return {
        "position": {"x": p[0], "y": p[1], "z": p[2]},
        "orientation": {"x": x, "y": y, "z": z, "w": w},
    }


def _point(xyz: np.ndarray) -> dict[str, dict[str, float]]:
    T = np.eye(4)
    T[:3, 3] = xyz
    return _pose(T)


def _log_line(e: AuditEvent) -> dict[str, Any]:
    words = [e.actor, e.action, f"{e.entity} {e.entity_id}"]
    if e.from_state or e.to_state:
        words.append(f"{e.from_state or '–'} → {e.to_state or '–'}")
    if e.reason:
        words.append(f"({e.reason})")
    return {
        "timestamp": _time(iso_ns(e.ts)),
        "level": 3 if e.action in _WARN else 2,
        "message": " ".join(words),
        "name": e.entity,
        "file": "",
        "line": 0,
    }


def write_recording(
    out: IO[bytes],
    execution: ExecutionRecord,
    plan: PlanRecord,
    acks: Sequence[tuple[int, str]],
    states: Sequence[tuple[float, dict[str, Any]]],
    audit: Sequence[AuditEvent],
    *,
    cloud: PlanCloud | None = None,
) -> dict[str, int]:
    """Write the run to ``out`` as MCAP; the message count of each channel written."""
    program = list(plan.program or [])
    start_ns = iso_ns(execution.created_at)
    path, path_note = planned_path(plan)
    frames, frames_note = robot_frames(execution.robot)
    cloud = cloud or PlanCloud(None, "no cloud was looked up for this recording")
    samples = [(round(t_s * 1e9), st, frames.at(list(st.get("q_rad") or [])) if frames else None)
               for t_s, st in states]  # fmt: skip
    placed = [s for s in samples if s[2] is not None]
    notes = {
        "/tf": frames_note if placed or not frames else f"{frames_note}: no report it can place",
        "/robot/tool_pose": (
            f"{frames.tip} in {frames.base} by FK of the reported joints" if frames else frames_note
        ),
        "/plan/path": path_note,
        "/plan/cloud": cloud.note,
    }
    present = {
        "/tf": bool(placed),
        "/robot/tool_pose": any(np.isfinite(s[2].tip_pose).all() for s in placed if s[2]),
        "/plan/path": path is not None,
        "/plan/cloud": cloud.points is not None,
    }
    w = Writer(out, compression=CompressionType.ZSTD)
    w.start(profile="", library="steelpath")
    w.add_metadata(
        "execution",
        {
            "execution_id": execution.id,
            "plan_id": plan.id,
            "kind": plan.kind,
            "robot": execution.robot,
            "state": execution.state,
            "commands": str(len(program)),
        },
    )
    w.add_metadata(
        "channels",
        {t: (n if present[t] else f"absent: {n}") for t, n in notes.items()},
    )
    w.add_metadata(
        "cloud",
        {
            "cloud_id": cloud.cloud_id or "",
            "stored_points": str(cloud.stored_points),
            "stride": str(cloud.stride),
            "written_points": str(0 if cloud.points is None else len(cloud.points)),
        },
    )
    ids: dict[str, int] = {}
    for topic, (name, schema) in CHANNELS.items():
        if present.get(topic, True):
            data = json.dumps(schema).encode()
            sid = w.register_schema(name=name, encoding="jsonschema", data=data)
            ids[topic] = w.register_channel(topic=topic, message_encoding="json", schema_id=sid)
    counts = dict.fromkeys(ids, 0)

    def put(topic: str, t_ns: int, msg: dict[str, Any]) -> None:
        if topic not in ids:
            return
        seq = counts[topic]
        counts[topic] += 1
        data = json.dumps(msg, separators=(",", ":"), allow_nan=False).encode()
        w.add_message(ids[topic], log_time=t_ns, data=data, publish_time=t_ns, sequence=seq)

    t = 0.0
    for i, c in enumerate(program):
        d = max(float(c.get("duration_s", 0.0) or 0.0), 0.0)
        put(
            "/plan/program",
            start_ns,
            {"index": i, "planned_start_s": t, "duration_s": d, "command": c},
        )
        t += d
    if path is not None:
        msg = {
            "timestamp": _time(start_ns),
            "frame_id": WORLD_FRAME,
            "poses": [_point(p) for p in path],
        }
        put("/plan/path", start_ns, msg)
    if cloud.points is not None:
        put(
            "/plan/cloud",
            start_ns,
            {
                "timestamp": _time(start_ns),
                "frame_id": WORLD_FRAME,
                "pose": _point(np.zeros(3)),
                "point_stride": 12,
                "fields": [
                    {"name": n, "offset": 4 * k, "type": schemas.FLOAT32}
                    for k, n in enumerate("xyz")
                ],
                "data": base64.b64encode(cloud.points.astype("<f4").tobytes()).decode(),
            },
        )
    for idx, ts in acks:
        c = program[idx] if 0 <= idx < len(program) else {}
        put(
            "/commands/acknowledged",
            iso_ns(ts),
            {"index": idx, "op": str(c.get("op", "")), "command": c},
        )
    for ns, st, fs in samples:
        put("/robot/state", ns, {"robot": execution.robot, **st})
        if fs is None or frames is None:
            continue
        tfs = []
        for parent, child, T in fs.transforms:
            pose = _pose(T)
            tfs.append({"timestamp": _time(ns), "parent_frame_id": parent, "child_frame_id": child,
                        "translation": pose["position"], "rotation": pose["orientation"]})  # fmt: skip
        put("/tf", ns, {"transforms": tfs})
        if np.isfinite(fs.tip_pose).all():
            put("/robot/tool_pose", ns,
                {"timestamp": _time(ns), "frame_id": frames.base, "pose": _pose(fs.tip_pose)})  # fmt: skip
    for e in sorted(audit, key=lambda a: (a.ts, a.id)):
        put("/operator", iso_ns(e.ts), _log_line(e))
    w.finish()
    return counts
