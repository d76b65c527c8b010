"""A run as an MCAP file ("recorded runs"), for Foxglove / Lichtblick.

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
  the plan's stored cloud at the run's start, thinned to ≤ 200 000 points;
* ``/<robot>/camera/points`` (``foxglove.PointCloud``, frame
  ``<robot>/camera``, float32 x y z and a uint8 ``intensity`` when the
  capture has one): what the robot's camera saw, one message per capture at
  the time the host received it, with, on ``/tf`` at the same time,
  ``world → <robot>/base → <robot>/camera``, so Foxglove places it
  (:mod:`server.recording.captures`).

Every position is in the plan's local ``world`` frame; the ``world``
metadata record states its origin (float64, the plan's ``world_origin_m``,
zeros when the plan states none).

A channel with nothing to hold (a kind without a path, a plan without a
stored cloud, an unknown robot) is left out; the ``channels`` metadata record
says, per channel, where its data came from or why it is absent, and the
``cloud`` record how the cloud was thinned.  Timestamps are Unix
nanoseconds.  :func:`write_recording` returns the message count per channel
written (the same counts the MCAP summary holds).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from typing import IO, Any

import numpy as np
from mcap.writer import CompressionType, Writer

from server.recording.captures import (
    ExportCaptures,
    base_frame,
    camera_frame,
    camera_topic,
    origin_metadata,
    transforms,
)
from server.recording.channels import PlanCloud, iso_ns, planned_path, robot_frames
from server.recording.messages import (
    CHANNELS,
    INFO,
    WARNING,
    acked_msg,
    capture_cloud_msg,
    cloud_msg,
    log_msg,
    path_msg,
    program_msgs,
    state_msg,
    tf_msg,
    tool_pose_msg,
    transforms_msg,
)
from server.store.records import AuditEvent, ExecutionRecord, PlanRecord

#: Audit actions logged as warnings.
_WARN = {"estop", "abort", "fault", "interrupt"}

__all__ = ["CHANNELS", "iso_ns", "write_recording"]


def _log_line(e: AuditEvent) -> dict[str, Any]:
    words = [e.actor, e.action, f"{e.entity} {e.entity_id}"]
    if e.from_state or e.to_state:
        words.append(f"{e.from_state or '–'} → {e.to_state or '–'}")
    if e.reason:
        words.append(f"({e.reason})")
    return log_msg(iso_ns(e.ts), WARNING if e.action in _WARN else INFO, " ".join(words), e.entity)


def write_recording(
    out: IO[bytes],
    execution: ExecutionRecord,
    plan: PlanRecord,
    acks: Sequence[tuple[int, str]],
    states: Sequence[tuple[float, dict[str, Any]]],
    audit: Sequence[AuditEvent],
    *,
    cloud: PlanCloud | None = None,
    captures: ExportCaptures | None = None,
) -> dict[str, int]:
    """Write the run to ``out`` as MCAP; the message count of each channel written.

    ``captures``: what the robot's camera saw
    (:func:`server.recording.captures.load_captures`); none if not given.
    """
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
    shots = captures.captures if captures is not None else []
    cam_topic = camera_topic(execution.robot)
    if shots and captures is not None:
        notes[cam_topic] = captures.note
        notes["/tf"] += "; per capture world → " + " → ".join(
            (base_frame(execution.robot), camera_frame(execution.robot))
        )
    present = {
        cam_topic: bool(shots),
        "/tf": bool(placed) or bool(shots),
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
    w.add_metadata("world", origin_metadata(plan))
    if shots and captures is not None:
        w.add_metadata("captures", captures.metadata())
    ids: dict[str, int] = {}
    sids: dict[str, int] = {}
    channels = dict(CHANNELS)
    if shots:
        channels[cam_topic] = CHANNELS["/plan/cloud"]
    for topic, (name, schema) in channels.items():
        if present.get(topic, True):
            if name not in sids:
                data = json.dumps(schema).encode()
                sids[name] = w.register_schema(name=name, encoding="jsonschema", data=data)
            ids[topic] = w.register_channel(
                topic=topic, message_encoding="json", schema_id=sids[name]
            )
    counts = dict.fromkeys(ids, 0)

    def put(topic: str, t_ns: int, msg: dict[str, Any]) -> None:
        if topic not in ids:
            return
        seq = counts[topic]
        counts[topic] += 1
        data = json.dumps(msg, separators=(",", ":"), allow_nan=False).encode()
        w.add_message(ids[topic], log_time=t_ns, data=data, publish_time=t_ns, sequence=seq)

    for msg in program_msgs(program):
        put("/plan/program", start_ns, msg)
    if path is not None:
        put("/plan/path", start_ns, path_msg(start_ns, path))
    if cloud.points is not None:
        put("/plan/cloud", start_ns, cloud_msg(start_ns, cloud.points))
    for idx, ts in acks:
        put("/commands/acknowledged", iso_ns(ts), acked_msg(program, idx))
    for ns, st, fs in samples:
        put("/robot/state", ns, state_msg(execution.robot, st))
        if fs is None or frames is None:
            continue
        put("/tf", ns, tf_msg(ns, fs))
        tool = tool_pose_msg(ns, frames.base, fs)
        if tool is not None:
            put("/robot/tool_pose", ns, tool)
    cam = camera_frame(execution.robot)
    for c in shots:
        put("/tf", c.t_ns, transforms_msg(c.t_ns, transforms(execution.robot, c)))
        put(cam_topic, c.t_ns, capture_cloud_msg(c.t_ns, cam, c))
    for e in sorted(audit, key=lambda a: (a.ts, a.id)):
        put("/operator", iso_ns(e.ts), _log_line(e))
    w.finish()
    return counts
