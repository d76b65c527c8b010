"""Survey formats for uploaded clouds: LAS/LAZ (``laspy`` + ``lazrs``) and E57
(``pye57``), read in bounded chunks (issue #14 §1).

Both readers are generators of (k,3) float64 blocks over a
:class:`server.cloud_io.Source` (a byte range of the spooled upload), like
the PLY/PCD/XYZ readers beside them:

- LAS/LAZ: ``laspy`` reads through a file object over the byte range and
  yields :data:`CHUNK_POINTS` points at a time, scaled and offset to real
  coordinates (LAZ decompressed chunk by chunk).
- E57: libE57 needs a file, so the byte range is copied to a temporary file
  first (chunk by chunk); every scan is then read :data:`CHUNK_POINTS` at a
  time with its own buffers, invalid points dropped, spherical coordinates
  converted and the scan's pose (rotation, translation) applied, so several
  scanner stations land in one frame.  A file libE57 cannot read is refused
  with its one-line reason (:class:`SurveyReadError`); libE57's full report,
  which names the temporary file and its own source files, is only logged.
"""

from __future__ import annotations

import contextlib
import io
import logging
import os
import re
import tempfile
from collections.abc import Iterator
from typing import Any, Protocol

import numpy as np

# re-exported: uploads decide units here (the decision itself lives with the spacing)
from planners.pointcloud.spacing import MIN_POINTS_TO_DETECT as MIN_POINTS_TO_DETECT
from planners.pointcloud.spacing import MM_EXTENT_FROM as MM_EXTENT_FROM
from planners.pointcloud.spacing import MM_SPACING_FROM as MM_SPACING_FROM
from planners.pointcloud.spacing import decide_units as decide_units
from planners.pointcloud.spacing import measure_spacing

log = logging.getLogger(__name__)

#: Points per block (three float64 columns: 24 MB).
CHUNK_POINTS = 1 << 20
#: Bytes copied per step when an E57 byte range goes to a temporary file.
_COPY_BYTES = 8 << 20


class SurveyReadError(ValueError):
    """A survey file that cannot be read.  The message is for the uploader
    (no server path, no library debug text); ``debug`` is the library's full
    report, for the server's log."""

    def __init__(self, message: str, debug: str = "") -> None:
        super().__init__(message)
        self.debug = debug


def _e57_unreadable(exc: Exception, tmp: str) -> SurveyReadError:
    """``exc`` from libE57 as a :class:`SurveyReadError` (logged in full here).

    libE57's message starts with a one-line reason ("checksum mismatch, file
    is corrupted (ErrorBadChecksum)") and goes on with debug text holding the
    temporary file's path and libE57's build paths: only the reason is kept,
    without its error code and without any path."""
    full = str(exc).strip()
    log.warning("unreadable E57 upload (%s): %s", type(exc).__name__, full)
    first = full.splitlines()[0] if full else ""
    first = re.sub(r"\s*\(Error\w+\)\s*$", "", first.replace(tmp, "the file"))
    reason = " ".join(w for w in first.split() if "/" not in w and "\\" not in w)[:200]
    return SurveyReadError(f"not a readable E57 file: {reason or type(exc).__name__}", debug=full)


class _Source(Protocol):
    size: int

    def read_at(self, offset: int, n: int) -> bytes: ...


class SourceFile(io.RawIOBase):
    """A read-only, seekable file object over a :class:`Source`."""

    def __init__(self, src: _Source) -> None:
        self._src = src
        self._pos = 0

    def readable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True

    def tell(self) -> int:
        return self._pos

    def seek(self, offset: int, whence: int = io.SEEK_SET) -> int:
        base = {io.SEEK_SET: 0, io.SEEK_CUR: self._pos, io.SEEK_END: self._src.size}[whence]
        self._pos = max(0, base + offset)
        return self._pos

    def readinto(self, buffer: Any) -> int:
        view = memoryview(buffer).cast("B")
        data = self._src.read_at(self._pos, len(view))
        view[: len(data)] = data
        self._pos += len(data)
        return len(data)


def read_las(src: _Source) -> Iterator[np.ndarray]:
    """LAS 1.0–1.4 and LAZ points as real coordinates, chunk by chunk."""
    import laspy

    with laspy.open(io.BufferedReader(SourceFile(src), buffer_size=1 << 20)) as reader:
        for points in reader.chunk_iterator(CHUNK_POINTS):
            yield np.column_stack(
                [np.asarray(points.x), np.asarray(points.y), np.asarray(points.z)]
            )


def read_e57(src: _Source) -> Iterator[np.ndarray]:
    """Every scan of an E57 file, posed into the file's frame, chunk by chunk."""
    import pye57

    fd, tmp = tempfile.mkstemp(prefix=".tmp-e57-", suffix=".e57")
    try:
        with os.fdopen(fd, "wb") as fh:
            for off in range(0, src.size, _COPY_BYTES):
                fh.write(src.read_at(off, _COPY_BYTES))
        try:
            e57 = pye57.E57(tmp)
        except Exception as exc:  # libE57 refuses the file: why, for people
            raise _e57_unreadable(exc, tmp) from exc
        try:
            for index in range(e57.scan_count):
                yield from _e57_scan(e57, index)
        except Exception as exc:  # a scan libE57 (or _e57_scan) cannot read
            raise _e57_unreadable(exc, tmp) from exc
        finally:
            e57.close()
    finally:
        with contextlib.suppress(OSError):
            os.unlink(tmp)


def _e57_scan(e57: Any, index: int) -> Iterator[np.ndarray]:
    header = e57.get_header(index)
    fields = set(header.point_fields)
    if {"cartesianX", "cartesianY", "cartesianZ"} <= fields:
        coords, spherical = ["cartesianX", "cartesianY", "cartesianZ"], False
        invalid = "cartesianInvalidState"
    elif {"sphericalRange", "sphericalAzimuth", "sphericalElevation"} <= fields:
        coords, spherical = ["sphericalRange", "sphericalAzimuth", "sphericalElevation"], True
        invalid = "sphericalInvalidState"
    else:
        raise ValueError(f"scan {index} has neither cartesian nor spherical coordinates")
    names = coords + ([invalid] if invalid in fields else [])
    capacity = min(CHUNK_POINTS, max(int(header.point_count), 1))
    data, buffers = e57.make_buffers(names, capacity)
    R = header.rotation_matrix if header.has_pose() else np.eye(3)
    t = np.asarray(header.translation, dtype=float)
    reader = header.points.reader(buffers)
    try:
        while (n := int(reader.read())) > 0:
            a, b, c = (np.asarray(data[k][:n], dtype=np.float64) for k in coords)
            if (
                spherical
            ):  # libE57's convention: azimuth from x towards y, elevation from the xy-plane
                rc = a * np.cos(c)
                a, b, c = rc * np.cos(b), rc * np.sin(b), a * np.sin(c)
            xyz = np.column_stack([a, b, c])
            if invalid in data:
                xyz = xyz[np.asarray(data[invalid][:n]) == 0]
            yield xyz @ np.asarray(R, dtype=float).T + t
    finally:
        reader.close()


# ------------------------------------------------------------------ spacing and units
# The unit decision (:func:`planners.pointcloud.spacing.decide_units`) lives
# beside the spacing it is made from, so a planner given a cloud in an unknown
# unit decides the same way an upload does.


def survey_of_npy(path: str | os.PathLike[str], fmt: str, units: str = "auto") -> dict[str, Any]:
    """Measure the spacing of the (N,3) float64 ``.npy`` at ``path``, decide its
    units and, for millimetres, rescale it to metres in place (chunk by
    chunk).  Returns the survey record: format, units, how they were decided,
    the scale applied, the spacing in metres, and the bounds in metres."""
    arr = np.load(path, mmap_mode="r+")
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for a in range(0, len(arr), CHUNK_POINTS):
        block = arr[a : a + CHUNK_POINTS]
        if len(block):
            np.minimum(lo, block.min(axis=0), out=lo)
            np.maximum(hi, block.max(axis=0), out=hi)
    spacing = measure_spacing(arr)
    extent = float((hi - lo).max()) if len(arr) else 0.0
    unit, reason = decide_units(spacing, extent, len(arr), units)
    scale = 0.001 if unit == "mm" else 1.0
    if scale != 1.0:
        for a in range(0, len(arr), CHUNK_POINTS):
            arr[a : a + CHUNK_POINTS] *= scale
        lo, hi = lo * scale, hi * scale
    arr.flush()
    del arr
    return {
        "format": fmt,
        "units": unit,
        "units_reason": reason,
        "scale_to_m": scale,
        "spacing_m": None if spacing is None else spacing * scale,
        "bounds": {"min": lo.tolist(), "max": hi.tolist()},
    }
