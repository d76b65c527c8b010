"""A sensor frame the robot brings back: what its camera saw at one place.

A ``capture`` command in a program asks the robot for one; the robot sends it
to the host as a header message and point chunks (docs/protocol.md), and the
host's link reassembles them into a :class:`SensorCapture`.

Coordinates: the camera pose is given in the program's ``world`` frame, a
local frame whose origin the plan records (``world_origin_m``, float64, e.g.
a UTM position), so that the numbers stay small enough for float32 and for
the wire's integer micrometres.  Points are in the camera's optical frame
(z along the view, x right, y down), metres.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from robots.protocol.messages import (
    CHUNK_POINTS,
    MAX_CAPTURE_POINTS,
    QUAT_SCALE,
    CaptureChunk,
    CaptureHeader,
    Message,
)

__all__ = [
    "MAX_PENDING_CHUNKS",
    "CaptureAssembler",
    "SensorCapture",
    "capture_messages",
    "matrix_to_quaternion",
    "quaternion_to_matrix",
    "rpy_to_matrix",
]

#: Largest camera-frame coordinate a chunk can carry (i16 millimetres), metres.
MAX_POINT_M = 32.767
#: Chunks of one capture at most (MAX_CAPTURE_POINTS / CHUNK_POINTS, rounded up).
MAX_PENDING_CHUNKS = -(-MAX_CAPTURE_POINTS // CHUNK_POINTS)


@dataclass(frozen=True)
class SensorCapture:
    """One sensor frame, reassembled on the host.

    - ``capture_id``: the robot's number of this capture (unique per run);
    - ``run_id`` / ``command_index``: the program run and the ``capture``
      command that asked for it;
    - ``t_s``: robot clock at the capture, seconds;
    - ``camera_position_m`` (3,) float64 and ``camera_rotation`` (3, 3)
      float64: the camera → world transform (columns: the camera's axes in
      the world frame);
    - ``points_m`` (N, 3) float32 in the camera frame;
    - ``intensity`` (N,) uint8 or ``None``;
    - ``complete``: every point the header announced arrived.
    """

    capture_id: int
    run_id: int
    command_index: int
    t_s: float
    camera_position_m: np.ndarray
    camera_rotation: np.ndarray
    points_m: np.ndarray
    intensity: np.ndarray | None = None
    complete: bool = True
    meta: dict[str, float] = field(default_factory=dict)

    def world_points(self) -> np.ndarray:
        """The points in the world frame, float64 (N, 3)."""
        pts = np.asarray(self.points_m, dtype=np.float64)
        return pts @ np.asarray(self.camera_rotation, dtype=np.float64).T + np.asarray(
            self.camera_position_m, dtype=np.float64
        )


# --- rotations ----------------------------------------------------------------------------


def rpy_to_matrix(rpy: np.ndarray | tuple[float, ...] | list[float]) -> np.ndarray:
    """``R = Rz(yaw)·Ry(pitch)·Rx(roll)`` (URDF convention), (3, 3) float64."""
    r, p, y = (float(v) for v in rpy)
    cr, sr, cp, sp, cy, sy = (
        math.cos(r),
        math.sin(r),
        math.cos(p),
        math.sin(p),
        math.cos(y),
        math.sin(y),
    )
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def matrix_to_quaternion(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z), w ≥ 0, of a rotation matrix (Shepperd's method)."""
    m = np.asarray(R, dtype=float)
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0:
        s = 2.0 * math.sqrt(tr + 1.0)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s]
    out = np.asarray(q) / np.linalg.norm(q)
    return -out if out[0] < 0 else out


def quaternion_to_matrix(q: np.ndarray | tuple[float, ...] | list[float]) -> np.ndarray:
    """Rotation matrix of quaternion (w, x, y, z) (normalised first; zero → identity)."""
    w, x, y, z = (float(v) for v in q)
    n = math.sqrt(w * w + x * x + y * y + z * z)
    if n == 0.0 or not math.isfinite(n):
        return np.eye(3)
    w, x, y, z = w / n, x / n, y / n, z / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


# --- robot side: a frame as messages ----------------------------------------------------------


def capture_messages(
    *,
    capture_id: int,
    run_id: int,
    index: int,
    t_s: float,
    camera_to_world: np.ndarray,
    points_m: np.ndarray,
    intensity: np.ndarray | None = None,
) -> list[Message]:
    """The header and chunks that carry one frame (what a robot sends, in order).

    ``camera_to_world`` (4, 4); ``points_m`` (N, 3) in the camera frame, N ≤
    :data:`MAX_CAPTURE_POINTS`, every coordinate within ±:data:`MAX_POINT_M`
    (raises ``ValueError`` otherwise: the caller thins and crops); quantised
    to millimetres.  ``intensity`` (N,) uint8 or ``None``.
    """
    pts = np.asarray(points_m, dtype=np.float64).reshape(-1, 3)
    n = len(pts)
    if n > MAX_CAPTURE_POINTS:
        raise ValueError(f"{n} points > {MAX_CAPTURE_POINTS} per capture")
    mm = np.rint(pts * 1000.0)
    if n and (not np.all(np.isfinite(mm)) or np.abs(mm).max() > 32767):
        raise ValueError(f"a point is not finite or beyond ±{MAX_POINT_M} m of the camera")
    mm_i = mm.astype(np.int16)
    inten = None
    if intensity is not None:
        inten = np.asarray(intensity).reshape(-1).astype(np.uint8)
        if len(inten) != n:
            raise ValueError(f"{len(inten)} intensities for {n} points")
    T = np.asarray(camera_to_world, dtype=float)
    pos = np.rint(T[:3, 3] * 1e6)
    if not np.all(np.abs(pos) < 2**31):
        raise ValueError("camera position beyond the i32 µm range")
    quat = np.rint(matrix_to_quaternion(T[:3, :3]) * QUAT_SCALE).astype(np.int64)
    out: list[Message] = [
        CaptureHeader(
            capture_id=int(capture_id) & 0xFFFFFFFF,
            run_id=int(run_id),
            index=int(index),
            t_ms=int(t_s * 1000) & 0xFFFFFFFF,
            x_um=int(pos[0]),
            y_um=int(pos[1]),
            z_um=int(pos[2]),
            qw=int(quat[0]),
            qx=int(quat[1]),
            qy=int(quat[2]),
            qz=int(quat[3]),
            n_points=n,
            has_intensity=inten is not None,
        )
    ]
    for start in range(0, n, CHUNK_POINTS):
        part = mm_i[start : start + CHUNK_POINTS]
        out.append(
            CaptureChunk(
                capture_id=int(capture_id) & 0xFFFFFFFF,
                offset=start,
                x_mm=tuple(part[:, 0].tolist()),
                y_mm=tuple(part[:, 1].tolist()),
                z_mm=tuple(part[:, 2].tolist()),
                intensity=()
                if inten is None
                else tuple(inten[start : start + CHUNK_POINTS].tolist()),
            )
        )
    return out


# --- host side: reassembly ------------------------------------------------------------------


@dataclass
class _Pending:
    header: CaptureHeader
    started: float
    last_rx: float
    points: np.ndarray  # (n, 3) int16 mm
    intensity: np.ndarray | None
    got: np.ndarray  # (n,) bool


class CaptureAssembler:
    """Reassembles :class:`CaptureHeader` + :class:`CaptureChunk` into :class:`SensorCapture`.

    Bounded: one capture is assembled at a time (a robot sends a capture's
    messages back to back), of at most :data:`MAX_CAPTURE_POINTS` points.  A
    capture is handed on as soon as every announced point arrived
    (``complete=True``); it is handed on *incomplete* (``complete=False``,
    the points that did arrive, in order) when the next header arrives, when
    no chunk came for ``timeout_s`` (:meth:`expire`) or on :meth:`flush`
    (link lost, end of run).  Chunks of any other capture, malformed chunks
    and repeated chunks are dropped and counted in :attr:`stats`.  Not
    thread-safe: the owner (the link's I/O thread) serialises calls.
    """

    def __init__(self, timeout_s: float = 1.0) -> None:
        self.timeout_s = timeout_s
        self._pending: _Pending | None = None
        self.stats: Counter[str] = Counter()

    @property
    def pending(self) -> bool:
        return self._pending is not None

    def feed(self, msg: CaptureHeader | CaptureChunk, now: float) -> list[SensorCapture]:
        """Take one message; returns the captures it finished (0, 1 or 2)."""
        out: list[SensorCapture] = []
        if isinstance(msg, CaptureHeader):
            out += self.flush()
            if msg.n_points > MAX_CAPTURE_POINTS:
                self.stats["capture_headers_refused"] += 1
                return out
            n = msg.n_points
            self._pending = _Pending(
                header=msg,
                started=now,
                last_rx=now,
                points=np.zeros((n, 3), dtype=np.int16),
                intensity=np.zeros(n, dtype=np.uint8) if msg.has_intensity else None,
                got=np.zeros(n, dtype=bool),
            )
            self.stats["capture_headers"] += 1
        else:
            p = self._pending
            if p is None or msg.capture_id != p.header.capture_id:
                self.stats["capture_chunks_orphaned"] += 1
                return out
            k = len(msg.x_mm)
            end = msg.offset + k
            want_i = k if p.intensity is not None else 0
            if (
                k == 0
                or len(msg.y_mm) != k
                or len(msg.z_mm) != k
                or len(msg.intensity) != want_i
                or end > len(p.got)
            ):
                self.stats["capture_chunks_invalid"] += 1
                return out
            if p.got[msg.offset : end].all():
                self.stats["capture_chunks_repeated"] += 1
                return out
            p.points[msg.offset : end, 0] = msg.x_mm
            p.points[msg.offset : end, 1] = msg.y_mm
            p.points[msg.offset : end, 2] = msg.z_mm
            if p.intensity is not None:
                p.intensity[msg.offset : end] = msg.intensity
            p.got[msg.offset : end] = True
            p.last_rx = now
            self.stats["capture_chunks"] += 1
        if self._pending is not None and self._pending.got.all():
            out += self.flush()
        return out

    def expire(self, now: float) -> list[SensorCapture]:
        """The pending capture, incomplete, if no chunk came for ``timeout_s``."""
        p = self._pending
        if p is not None and now - p.last_rx > self.timeout_s:
            return self.flush()
        return []

    def flush(self) -> list[SensorCapture]:
        """Hand on the pending capture now (complete or not); [] when none."""
        p, self._pending = self._pending, None
        if p is None:
            return []
        h = p.header
        complete = bool(p.got.all())
        self.stats["captures_complete" if complete else "captures_incomplete"] += 1
        keep = p.got
        quat = np.array([h.qw, h.qx, h.qy, h.qz], dtype=float) / QUAT_SCALE
        return [
            SensorCapture(
                capture_id=h.capture_id,
                run_id=h.run_id,
                command_index=h.index,
                t_s=h.t_ms / 1000.0,
                camera_position_m=np.array([h.x_um, h.y_um, h.z_um], dtype=float) / 1e6,
                camera_rotation=quaternion_to_matrix(quat),
                points_m=(p.points[keep].astype(np.float32) / np.float32(1000.0)),
                intensity=None if p.intensity is None else p.intensity[keep].copy(),
                complete=complete,
                meta={
                    "n_announced": float(len(p.got)),
                    "n_received": float(np.count_nonzero(keep)),
                },
            )
        ]
