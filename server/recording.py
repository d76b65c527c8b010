"""A run as an MCAP file (issue #16 §3: "recorded runs"), for Foxglove / Lichtblick.

Everything comes from what the service stored while the execution ran:
the plan's compiled program, the acknowledgement time of each command, the
robot's state reports while the execution was active (mirrored at 2 Hz by
the dispatch engine) and the audit trail of the plan and the execution
(approve, dispatch, pause, resume, abort, E-stop…).  Messages are JSON with
a JSON Schema per channel, so Foxglove decodes them without plugins:

* ``/plan/program`` (``steelpath.PlannedCommand``): every command of the
  program at the run's start, with its index and planned start time;
* ``/commands/acknowledged`` (``steelpath.AcknowledgedCommand``): each
  command at the time the robot acknowledged it;
* ``/robot/state`` (``steelpath.RobotState``): the state reports — joints
  (rad), odometry (m), lift, mode, faults, the command executing — which the
  Plot panel plots field by field;
* ``/operator`` (Foxglove's well-known ``foxglove.Log``): operator and
  system actions as log lines (Log panel).

Timestamps are Unix nanoseconds.  :func:`write_recording` returns the
message count per channel (the same counts the MCAP summary holds).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from datetime import datetime
from typing import IO, Any

from mcap.writer import CompressionType, Writer

from server.store.records import AuditEvent, ExecutionRecord, PlanRecord

_PLANNED = {
    "type": "object",
    "title": "steelpath.PlannedCommand",
    "properties": {
        "index": {"type": "integer"},
        "planned_start_s": {"type": "number"},
        "duration_s": {"type": "number"},
        "command": {"type": "object"},
    },
}
_ACKED = {
    "type": "object",
    "title": "steelpath.AcknowledgedCommand",
    "properties": {
        "index": {"type": "integer"},
        "op": {"type": "string"},
        "command": {"type": "object"},
    },
}
_STATE = {
    "type": "object",
    "title": "steelpath.RobotState",
    "properties": {
        "robot": {"type": "string"},
        "q_rad": {"type": "array", "items": {"type": "number"}},
        "odometry_m": {"type": "array", "items": {"type": "number"}},
        "lift_rad": {"type": "number"},
        "mode": {"type": "integer"},
        "faults": {"type": "integer"},
        "executing": {"type": "integer"},
        "last_done": {"type": "integer"},
    },
}
# Foxglove's well-known Log schema (JSON form).
_LOG = {
    "type": "object",
    "title": "foxglove.Log",
    "properties": {
        "timestamp": {
            "type": "object",
            "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}},
        },
        "level": {"type": "integer", "description": "1 debug, 2 info, 3 warning, 4 error"},
        "message": {"type": "string"},
        "name": {"type": "string"},
        "file": {"type": "string"},
        "line": {"type": "integer"},
    },
}

CHANNELS: dict[str, tuple[str, dict[str, Any]]] = {
    "/plan/program": ("steelpath.PlannedCommand", _PLANNED),
    "/commands/acknowledged": ("steelpath.AcknowledgedCommand", _ACKED),
    "/robot/state": ("steelpath.RobotState", _STATE),
    "/operator": ("foxglove.Log", _LOG),
}

#: Audit actions logged as warnings.
_WARN = {"estop", "abort", "fault", "interrupt"}


def iso_ns(ts: str) -> int:
    """Unix nanoseconds of an ISO-8601 time stored by the service."""
    return round(datetime.fromisoformat(ts).timestamp() * 1e9)


def write_recording(
    out: IO[bytes],
    execution: ExecutionRecord,
    plan: PlanRecord,
    acks: Sequence[tuple[int, str]],
    states: Sequence[tuple[float, dict[str, Any]]],
    audit: Sequence[AuditEvent],
) -> dict[str, int]:
    """Write the run to ``out`` as MCAP; the message count of each channel."""
    program = list(plan.program or [])
    start_ns = iso_ns(execution.created_at)
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
    ids: dict[str, int] = {}
    for topic, (name, schema) in CHANNELS.items():
        sid = w.register_schema(name=name, encoding="jsonschema", data=json.dumps(schema).encode())
        ids[topic] = w.register_channel(topic=topic, message_encoding="json", schema_id=sid)
    counts = dict.fromkeys(CHANNELS, 0)

    def put(topic: str, t_ns: int, msg: dict[str, Any]) -> None:
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
    for idx, ts in acks:
        c = program[idx] if 0 <= idx < len(program) else {}
        put(
            "/commands/acknowledged",
            iso_ns(ts),
            {"index": idx, "op": str(c.get("op", "")), "command": c},
        )
    for t_s, st in states:
        msg = {"robot": execution.robot, **st}
        put("/robot/state", round(t_s * 1e9), msg)
    for e in sorted(audit, key=lambda a: (a.ts, a.id)):
        ns = iso_ns(e.ts)
        words = [e.actor, e.action, f"{e.entity} {e.entity_id}"]
        if e.from_state or e.to_state:
            words.append(f"{e.from_state or '–'} → {e.to_state or '–'}")
        if e.reason:
            words.append(f"({e.reason})")
        put(
            "/operator",
            ns,
            {
                "timestamp": {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000},
                "level": 3 if e.action in _WARN else 2,
                "message": " ".join(words),
                "name": e.entity,
                "file": "",
                "line": 0,
            },
        )
    w.finish()
    return counts
