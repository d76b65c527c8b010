"""What the robot's camera saw, for the MCAP and the ROS 2 bag.

Every exported geometry is in the plan's local ``world`` frame, whose origin
the plan states (:func:`world_origin`: ``world_origin_m`` of the plan's
summary, float64, e.g. a UTM position; zeros when the plan states none): the
recording's metadata gives it, so a reader adds it back.

A capture is exported in its camera frame (:func:`camera_frame`, the optical
frame: z along the view, x right, y down), placed by two transforms at its
time: ``world → <robot>/base`` (the plan's ``robot_base_pose`` if its summary
states one, else the identity: a capture carries the camera's pose in the
world, not the base's) and ``<robot>/base → <robot>/camera`` (the base's
inverse times the camera pose), so their product is exactly the camera pose
the robot reported.  The points are exported as stored (float32, camera
frame); above :data:`MAX_EXPORT_POINTS` in all, every ``stride``-th point of
each capture is written (the metadata says so).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from server.recording.channels import WORLD_FRAME

if TYPE_CHECKING:
    from server.captures.store import CaptureRecord
    from server.store.records import PlanRecord
    from server.store.store import Store

#: At most this many capture points in one export (over all its captures).
MAX_EXPORT_POINTS = 5_000_000


def world_origin(plan: PlanRecord) -> tuple[np.ndarray, str]:
    """The plan's stated origin of its ``world`` frame (float64 (3,)) and where it came from."""
    summary = plan.result or {}
    for where in (summary, summary.get("summary")):
        if isinstance(where, dict) and "world_origin_m" in where:
            try:
                o = np.asarray(where["world_origin_m"], dtype=np.float64).reshape(3)
            except (TypeError, ValueError):
                continue
            if np.isfinite(o).all():
                return o, f"world_origin_m of plan {plan.id}"
    return np.zeros(3), f"plan {plan.id} states no world_origin_m: zeros"


def origin_metadata(plan: PlanRecord) -> dict[str, str]:
    """The MCAP ``world`` metadata record: the origin, float64 to the last bit (``repr``)."""
    o, note = world_origin(plan)
    return {
        "frame_id": WORLD_FRAME,
        "origin_x_m": repr(float(o[0])),
        "origin_y_m": repr(float(o[1])),
        "origin_z_m": repr(float(o[2])),
        "note": (
            "every exported position is in the frame 'world', relative to this origin "
            f"(float64): add it back for absolute coordinates ({note})"
        ),
    }


def base_frame(robot: str) -> str:
    return f"{robot}/base"


def camera_frame(robot: str) -> str:
    return f"{robot}/camera"


def camera_topic(robot: str) -> str:
    return f"/{robot}/camera/points"


def base_pose(plan: PlanRecord) -> np.ndarray:
    """world → base: the plan's ``robot_base_pose`` (4×4) if it states one, else identity."""
    raw = (plan.result or {}).get("robot_base_pose")
    if raw is not None:
        try:
            T = np.asarray(raw, dtype=np.float64).reshape(4, 4)
        except (TypeError, ValueError):
            return np.eye(4)
        if np.isfinite(T).all():
            return T
    return np.eye(4)


@dataclass(frozen=True)
class ExportCapture:
    """One capture as exported."""

    record: CaptureRecord
    t_ns: int
    points: np.ndarray  # (M,3) float32, camera frame
    intensity: np.ndarray | None  # (M,) uint8
    world_T_base: np.ndarray
    base_T_camera: np.ndarray


@dataclass(frozen=True)
class ExportCaptures:
    robot: str
    captures: list[ExportCapture]
    stored_points: int
    stride: int
    note: str

    def metadata(self) -> dict[str, str]:
        return {
            "topic": camera_topic(self.robot),
            "frame_id": camera_frame(self.robot),
            "captures": str(len(self.captures)),
            "stored_points": str(self.stored_points),
            "stride": str(self.stride),
            "written_points": str(sum(len(c.points) for c in self.captures)),
            "note": self.note,
        }


def load_captures(store: Store, execution_id: str, robot: str, plan: PlanRecord) -> ExportCaptures:
    """The execution's captures as exported (an empty list if it has none).

    Each capture's file is memory-mapped and only the points kept are read, so
    an execution at its bound (50 M points) never sits in memory whole."""
    from server.captures.store import CaptureStore

    cs = CaptureStore(store)
    recs = cs.list(execution_id)
    total = sum(r.n_points for r in recs)
    stride = max(1, math.ceil(total / MAX_EXPORT_POINTS))
    loaded = []
    for r in recs:
        pts = np.asarray(cs.arrays.load(r.points_file, mmap=True)).reshape(-1, 3)[::stride]
        inten = None
        if r.intensity_file is not None:
            inten = np.asarray(cs.arrays.load(r.intensity_file, mmap=True)).reshape(-1)[::stride]
        loaded.append((r, np.array(pts, dtype=np.float32), None if inten is None else
                       np.array(inten, dtype=np.uint8)))  # fmt: skip
    return export_captures(robot, plan, loaded, stored_points=total, stride=stride)


def export_captures(
    robot: str,
    plan: PlanRecord,
    loaded: list[tuple[CaptureRecord, np.ndarray, np.ndarray | None]],
    *,
    stored_points: int | None = None,
    stride: int | None = None,
) -> ExportCaptures:
    """:class:`ExportCaptures` of loaded captures (record, points, intensity);
    given a ``stride``, they were thinned by it already (of ``stored_points``)."""
    total = sum(len(p) for _, p, _ in loaded) if stored_points is None else stored_points
    thin = stride is None
    stride = max(1, math.ceil(total / MAX_EXPORT_POINTS)) if stride is None else stride
    step = stride if thin else 1
    wTb = base_pose(plan)
    bTw = np.linalg.inv(wTb)
    out = []
    for rec, pts, inten in loaded:
        out.append(
            ExportCapture(
                rec,
                round(rec.received_at * 1e9),
                np.ascontiguousarray(pts[::step], dtype=np.float32),
                None if inten is None else np.ascontiguousarray(inten[::step], np.uint8),
                wTb,
                bTw @ rec.camera_pose,
            )
        )
    note = (
        f"{len(out)} captures, camera frame, placed by /tf world → {base_frame(robot)} → "
        f"{camera_frame(robot)}"
        + ("" if stride == 1 else f"; every {stride}. point (at most {MAX_EXPORT_POINTS})")
    )
    return ExportCaptures(robot, out, total, stride, note)


def cloud_fields(has_intensity: bool) -> tuple[list[tuple[str, int, str]], int]:
    """(name, byte offset, kind) of a capture's packed point and its stride:
    float32 x y z, and a uint8 intensity when it has one."""
    fields = [("x", 0, "f4"), ("y", 4, "f4"), ("z", 8, "f4")]
    if has_intensity:
        fields.append(("intensity", 12, "u1"))
        return fields, 13
    return fields, 12


def packed(c: ExportCapture) -> bytes:
    """The capture's points packed as :func:`cloud_fields` says (little-endian)."""
    fields, step = cloud_fields(c.intensity is not None)
    dt = np.dtype(
        {"names": [f[0] for f in fields], "formats": ["<" + f[2] for f in fields],
         "offsets": [f[1] for f in fields], "itemsize": step}
    )  # fmt: skip
    arr = np.zeros(len(c.points), dtype=dt)
    for k, name in enumerate("xyz"):
        arr[name] = c.points[:, k]
    if c.intensity is not None:
        arr["intensity"] = c.intensity
    return arr.tobytes()


def transforms(robot: str, c: ExportCapture) -> list[tuple[str, str, np.ndarray]]:
    """(parent, child, 4×4) of a capture: world → base → camera."""
    return [
        (WORLD_FRAME, base_frame(robot), c.world_T_base),
        (base_frame(robot), camera_frame(robot), c.base_T_camera),
    ]
