"""Captures stored with their execution: rows in ``execution_captures``, points as ``.npy``.

A capture's points are kept as the robot sent them, float32 in the camera's
optical frame, in ``<data>/captures/<execution id>/<capture id>.points.npy``
(and ``….intensity.npy``, uint8, when it had intensities), written through
:class:`server.store.arrays.ArrayStore` (temporary name, fsync, rename)
*before* the row that names them is committed.  The camera pose (camera →
world, the plan's local ``world`` frame) is stored as float64 JSON, which
reads back bit for bit.

Each execution is bounded (:class:`server.captures.limits.CaptureLimits`):
past its number of captures or of points, or with the data volume at its
reserve, :meth:`CaptureStore.add` refuses with :class:`CaptureRefused`
and stores nothing.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from server.captures.limits import CaptureLimits, capture_limits
from server.diskspace import describe, is_disk_full
from server.store.arrays import ArrayStore
from server.store.database import RowLike, utcnow
from server.store.store import NotFoundError

if TYPE_CHECKING:
    from robots.protocol.capture import SensorCapture
    from server.diskspace import DiskGauge
    from server.store.store import Store

#: Directory (under the data directory) of the capture arrays.
CAPTURES_DIR = "captures"

_INSERT = (
    "INSERT INTO execution_captures (execution_id, capture_id, run_id, command_index, "
    "t_robot_s, received_at, position_m, rotation, n_points, complete, points_file, "
    "intensity_file, meta, created_at) VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?)"
)


class CaptureRefused(Exception):
    """A capture was not stored; ``why`` is ``limit``, ``disk`` or ``invalid``."""

    def __init__(self, why: str, message: str) -> None:
        super().__init__(message)
        self.why = why


@dataclass(frozen=True)
class CaptureRecord:
    """One stored capture (its metadata; the points are loaded on demand)."""

    execution_id: str
    capture_id: int
    run_id: int
    command_index: int
    t_robot_s: float
    received_at: float
    position_m: tuple[float, float, float]
    rotation: tuple[tuple[float, float, float], ...]
    n_points: int
    complete: bool
    points_file: str
    intensity_file: str | None
    meta: dict[str, Any] = field(default_factory=dict)
    created_at: str = ""

    @classmethod
    def from_row(cls, row: RowLike) -> CaptureRecord:
        d = dict(row)
        return cls(
            execution_id=str(d["execution_id"]),
            capture_id=int(d["capture_id"]),
            run_id=int(d["run_id"]),
            command_index=int(d["command_index"]),
            t_robot_s=float(d["t_robot_s"]),
            received_at=float(d["received_at"]),
            position_m=tuple(float(v) for v in json.loads(d["position_m"])),  # type: ignore[arg-type]
            rotation=tuple(tuple(float(v) for v in r) for r in json.loads(d["rotation"])),  # type: ignore[misc]
            n_points=int(d["n_points"]),
            complete=bool(d["complete"]),
            points_file=str(d["points_file"]),
            intensity_file=d["intensity_file"],
            meta=json.loads(d["meta"] or "{}"),
            created_at=str(d["created_at"]),
        )

    @property
    def camera_pose(self) -> np.ndarray:
        """4×4 float64: the camera → world transform."""
        T = np.eye(4)
        T[:3, :3] = np.asarray(self.rotation, dtype=np.float64)
        T[:3, 3] = np.asarray(self.position_m, dtype=np.float64)
        return T

    def public(self, start_s: float | None = None) -> dict[str, Any]:
        """The list entry of ``GET /executions/{id}/captures``; ``t_s``: seconds
        after ``start_s`` (the execution's start) at which the host received it."""
        base = f"/api/v1/executions/{self.execution_id}/captures/{self.capture_id}"
        return {
            "capture_id": self.capture_id,
            "run_id": self.run_id,
            "command_index": self.command_index,
            "t_robot_s": self.t_robot_s,
            "received_at": self.received_at,
            "t_s": None if start_s is None else self.received_at - start_s,
            "pose": {
                "frame_id": "world",
                "position_m": list(self.position_m),
                "rotation": [list(r) for r in self.rotation],
            },
            "n_points": self.n_points,
            "has_intensity": self.intensity_file is not None,
            "complete": self.complete,
            "meta": self.meta,
            "url": base,
        }


def _finite_json(values: Any) -> str:
    return json.dumps(values, allow_nan=False, separators=(",", ":"))


def _checked(capture: SensorCapture, max_points: int) -> tuple[np.ndarray, np.ndarray | None]:
    """The capture's points (N,3) float32 and intensity (N,) uint8 or None, or
    :class:`CaptureRefused` (``invalid``) saying what is wrong."""
    pos = np.asarray(capture.camera_position_m, dtype=np.float64)
    rot = np.asarray(capture.camera_rotation, dtype=np.float64)
    if pos.shape != (3,) or rot.shape != (3, 3):
        raise CaptureRefused("invalid", f"camera pose of shape {pos.shape} / {rot.shape}")
    if not (np.isfinite(pos).all() and np.isfinite(rot).all()):
        raise CaptureRefused("invalid", "camera pose is not finite")
    if not np.allclose(rot.T @ rot, np.eye(3), atol=1e-4):
        raise CaptureRefused("invalid", "camera rotation is not a rotation matrix")
    pts = np.asarray(capture.points_m)
    if pts.size == 0:
        pts = pts.reshape(0, 3)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise CaptureRefused("invalid", f"points of shape {pts.shape}, not (N, 3)")
    if len(pts) > max_points:
        raise CaptureRefused(
            "limit", f"{len(pts)} points in one capture, more than the {max_points} allowed"
        )
    pts = np.ascontiguousarray(pts, dtype=np.float32)
    inten = None
    if capture.intensity is not None:
        inten = np.ascontiguousarray(np.asarray(capture.intensity).reshape(-1), dtype=np.uint8)
        if len(inten) != len(pts):
            inten = None  # not one per point: meaningless, the points are kept
    keep = np.isfinite(pts).all(axis=1)
    if not keep.all():
        pts = pts[keep]
        inten = None if inten is None else inten[keep]
    return pts, inten


class CaptureStore:
    """The captures of every execution, on the service's store."""

    def __init__(
        self,
        store: Store,
        *,
        limits: CaptureLimits | None = None,
        gauge: DiskGauge | None = None,
    ) -> None:
        self.store = store
        self.db = store.db
        self.limits = limits or capture_limits()
        self.gauge = gauge
        self.arrays = ArrayStore(store.data_dir / CAPTURES_DIR)

    # ----------------------------------------------------------------- reading
    def list(self, execution_id: str) -> list[CaptureRecord]:
        rows = self.db.query(
            "SELECT * FROM execution_captures WHERE execution_id = ? "
            "ORDER BY received_at, capture_id",
            (execution_id,),
        )
        return [CaptureRecord.from_row(r) for r in rows]

    def get(self, execution_id: str, capture_id: int) -> CaptureRecord:
        row = self.db.query_one(
            "SELECT * FROM execution_captures WHERE execution_id = ? AND capture_id = ?",
            (execution_id, int(capture_id)),
        )
        if row is None:
            raise NotFoundError(f"execution {execution_id} has no capture {capture_id}")
        return CaptureRecord.from_row(row)

    def totals(self, execution_id: str) -> tuple[int, int]:
        """(captures, points) stored for ``execution_id``."""
        row = self.db.query_one(
            "SELECT COUNT(*) AS n, COALESCE(SUM(n_points), 0) AS p FROM execution_captures "
            "WHERE execution_id = ?",
            (execution_id,),
        )
        return (int(row["n"]), int(row["p"])) if row is not None else (0, 0)

    def points(self, rec: CaptureRecord) -> np.ndarray:
        """The capture's points as stored: (N,3) float32 in the camera frame."""
        return np.asarray(self.arrays.load(rec.points_file), dtype=np.float32).reshape(-1, 3)

    def intensity(self, rec: CaptureRecord) -> np.ndarray | None:
        if rec.intensity_file is None:
            return None
        return np.asarray(self.arrays.load(rec.intensity_file), dtype=np.uint8).reshape(-1)

    def world_points(self, rec: CaptureRecord) -> np.ndarray:
        """The capture's points in the world frame, float64 (N,3)."""
        T = rec.camera_pose
        return np.asarray(self.points(rec), dtype=np.float64) @ T[:3, :3].T + T[:3, 3]

    # ----------------------------------------------------------------- writing
    def add(
        self, execution_id: str, capture: SensorCapture, received_at: float | None = None
    ) -> CaptureRecord:
        """Store ``capture`` with ``execution_id``; :class:`CaptureRefused` if it
        may not be (a bound reached, the disk at its reserve, a malformed capture).

        The same capture again (a robot resending it) changes nothing, unless
        the stored one was incomplete and this one is complete: it replaces it.
        """
        received_at = time.time() if received_at is None else float(received_at)
        if not math.isfinite(received_at):
            raise CaptureRefused("invalid", "receipt time is not finite")
        cid = int(capture.capture_id)
        lim = self.limits
        pts, inten = _checked(capture, lim.capture_max_points)
        try:
            old: CaptureRecord | None = self.get(execution_id, cid)
        except NotFoundError:
            old = None
        if old is not None and (old.complete or not capture.complete):
            return old
        count, total = self.totals(execution_id)
        if old is not None:
            count, total = count - 1, total - old.n_points
        if count >= lim.capture_max_per_execution:
            raise CaptureRefused(
                "limit",
                f"capture {cid} refused: execution {execution_id} already holds "
                f"{count} captures, the most allowed (STEELPATH_CAPTURE_MAX_PER_EXECUTION="
                f"{lim.capture_max_per_execution})",
            )
        if total + len(pts) > lim.capture_max_points_per_execution:
            raise CaptureRefused(
                "limit",
                f"capture {cid} ({len(pts)} points) refused: execution {execution_id} holds "
                f"{total} points and may hold at most {lim.capture_max_points_per_execution} "
                "(STEELPATH_CAPTURE_MAX_POINTS_PER_EXECUTION)",
            )
        nbytes = pts.nbytes + (0 if inten is None else inten.nbytes) + 4096
        if self.gauge is not None and not self.gauge.room_for(nbytes):
            raise CaptureRefused(
                "disk",
                f"capture {cid} ({len(pts)} points) refused: the server's disk is full (its "
                "reserve is kept for the audit log and the E-stop); free space on the data "
                "volume",
            )
        meta = {str(k): float(v) for k, v in dict(capture.meta or {}).items()}
        meta = {k: v for k, v in meta.items() if math.isfinite(v)}
        base = f"{execution_id}/{cid}"
        points_file = f"{base}.points.npy"
        intensity_file = None if inten is None else f"{base}.intensity.npy"
        row = (
            execution_id,
            cid,
            int(capture.run_id),
            int(capture.command_index),
            float(capture.t_s),
            received_at,
            _finite_json([float(v) for v in np.asarray(capture.camera_position_m, np.float64)]),
            _finite_json(np.asarray(capture.camera_rotation, np.float64).tolist()),
            len(pts),
            1 if capture.complete else 0,
            points_file,
            intensity_file,
            _finite_json(meta),
            utcnow(),
        )
        try:
            self.arrays.save(points_file, pts)
            if inten is not None and intensity_file is not None:
                self.arrays.save(intensity_file, inten)
            elif old is not None and old.intensity_file is not None:
                self.arrays.delete(old.intensity_file)
            with self.db.transaction() as conn:
                if old is not None:
                    conn.execute(
                        "DELETE FROM execution_captures WHERE execution_id = ? AND capture_id = ?",
                        (execution_id, cid),
                    )
                conn.execute(_INSERT, row)
        except Exception as exc:
            if old is None:  # nothing refers to what was written: no orphan left
                self.arrays.delete(points_file)
                if intensity_file is not None:
                    self.arrays.delete(intensity_file)
            if is_disk_full(exc):
                if self.gauge is not None:
                    self.gauge.refresh()
                raise CaptureRefused(
                    "disk",
                    f"capture {cid} ({len(pts)} points) refused: the server's disk is full "
                    f"({describe(exc)}); free space on the data volume",
                ) from exc
            raise
        return self.get(execution_id, cid)

    def delete_execution(self, execution_id: str) -> None:
        """Remove the capture files of an execution (its rows go with the execution)."""
        self.arrays.delete_tree(execution_id)
