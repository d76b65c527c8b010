"""Survey formats for uploaded clouds: LAS/LAZ (``laspy`` + ``lazrs``) and E57
(``pye57``), read in bounded chunks, with their coordinate
reference system, units and per-point attributes ("Scans as crews bring
them" §2, §3).

Both readers are generators over a :class:`server.cloud_io.Source` (a byte
range of the spooled upload), like the PLY/PCD/XYZ readers beside them.  Each
block is ``(xyz, attributes)``: a (k,3) float64 array in the file's unit and
a dict of per-point arrays of the same k rows (``intensity``, ``rgb`` (k,3),
``classification``).  What the reader learns about the file as a whole (its
CRS, why an attribute was not kept) goes into the ``meta`` dict it is given.

- LAS/LAZ: the header is checked first (so a damaged or truncated file is
  named as such), then ``laspy`` reads through a file object over the byte
  range :data:`CHUNK_POINTS` points at a time, scaled and offset to real
  coordinates (LAZ decompressed chunk by chunk).  The CRS comes from the WKT
  or GeoTIFF-key VLRs (``header.parse_crs()``), or, for a user-defined
  GeoTIFF CRS, from its ``ProjLinearUnitsGeoKey`` / ``VerticalUnitsGeoKey``.
- E57: libE57 needs a file, so the byte range is copied to a temporary file
  first (chunk by chunk); every scan is then read :data:`CHUNK_POINTS` at a
  time with its own buffers, invalid points dropped, spherical coordinates
  converted and the scan's pose (rotation, translation) applied, so several
  scanner stations land in one frame.  The root's ``coordinateMetadata``
  string is read as a CRS when pyproj knows it.

A file that cannot be read is refused with a sentence for people
(:class:`SurveyReadError`: no server path, no library debug text); the
library's full report is only logged.

:func:`decide_scale` turns the CRS, the request's ``units`` and the measured
spacing into the scale to metres, and :func:`survey_of_npy` applies it to
the stored array in place.
"""

from __future__ import annotations

import contextlib
import io
import logging
import math
import os
import re
import struct
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

#: Metres per unit of the ``units`` an upload (or a plan) may name.
US_SURVEY_FOOT_M = 1200.0 / 3937.0
UNIT_TO_M: dict[str, float] = {"m": 1.0, "mm": 0.001, "ft": 0.3048, "us-ft": US_SURVEY_FOOT_M}
UNIT_NAMES = {
    "m": "metres",
    "mm": "millimetres",
    "ft": "international feet",
    "us-ft": "US survey feet",
}
#: The ``units`` an upload accepts.
UPLOAD_UNITS = ("auto", *UNIT_TO_M)

#: How the units were decided (the survey record's ``units_from``).
FROM_CRS = "from the CRS"
DETECTED = "detected"
FROM_REQUEST = "set by the request"

#: GeoTIFF linear unit codes (EPSG unit codes) → our unit names.
_GEOTIFF_UNITS = {9001: "m", 9002: "ft", 9003: "us-ft", 9036: "km"}
_PROJ_LINEAR_UNITS_KEY = 3076
_VERTICAL_UNITS_KEY = 4099


class SurveyReadError(ValueError):
    """A survey file that cannot be read.  The message is for the uploader
    (no server path, no library debug text); ``debug`` is the library's full
    report, for the server's log."""

    def __init__(self, message: str, debug: str = "") -> None:
        super().__init__(message)
        self.debug = debug


class _Source(Protocol):
    size: int

    def read_at(self, offset: int, n: int) -> bytes: ...


Block = tuple[np.ndarray, dict[str, np.ndarray]]


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


def _no_paths(text: str) -> str:
    """``text`` without words that look like paths, on one line, at most 200 characters."""
    first = text.strip().splitlines()[0] if text.strip() else ""
    return " ".join(w for w in first.split() if "/" not in w and "\\" not in w)[:200]


# ------------------------------------------------------------------ CRS
def crs_meta(crs: Any) -> dict[str, Any]:
    """What ``meta`` keeps of a pyproj CRS: WKT, name, EPSG code (or None) and
    the metres per unit of its horizontal and vertical axes (None where the
    axis is not a length, e.g. degrees; vertical None where it has no vertical
    axis)."""
    axes = list(crs.axis_info)
    linear = [
        a
        for a in axes
        if a.unit_conversion_factor and not re.search(r"degree|radian|grad|arc", a.unit_name, re.I)
    ]
    horizontal = [a for a in axes if a.direction.lower() not in ("up", "down")]
    vertical = [a for a in axes if a.direction.lower() in ("up", "down")]
    try:
        epsg = crs.to_epsg()
    except Exception:  # pyproj finds no EPSG match for a custom CRS: fine
        epsg = None

    def factor(group: list[Any]) -> tuple[float | None, str | None]:
        if not group or any(a not in linear for a in group):
            return None, (group[0].unit_name if group else None)
        return float(group[0].unit_conversion_factor), group[0].unit_name

    h, h_name = factor(horizontal)
    v, v_name = factor(vertical)
    return {
        "wkt": crs.to_wkt(),
        "name": crs.name,
        "epsg": epsg,
        "geographic": bool(crs.is_geographic) or (h is None and h_name is not None),
        "unit_m": h,
        "unit_name": h_name,
        "z_unit_m": v,
        "z_unit_name": v_name,
    }


def _crs_from_text(text: str, what: str, meta: dict[str, Any]) -> None:
    """Parse ``text`` (WKT, ``EPSG:n``, a PROJ string) into ``meta["crs"]``; a
    text pyproj does not know becomes ``meta["crs_note"]`` (the upload goes on)."""
    import pyproj
    from pyproj.exceptions import CRSError

    try:
        meta["crs"] = crs_meta(pyproj.CRS.from_user_input(text))
    except (CRSError, ValueError, TypeError) as exc:
        log.info("unreadable CRS in an upload's %s: %s", what, exc)
        meta["crs_note"] = (
            f"the file's {what} is not a coordinate reference system pyproj knows "
            "(neither WKT nor an EPSG code); it was ignored"
        )


def _las_crs(header: Any, meta: dict[str, Any]) -> None:
    """The CRS of a LAS header (WKT preferred over GeoTIFF keys) into ``meta``."""
    from pyproj.exceptions import CRSError

    try:
        crs = header.parse_crs()
    except (CRSError, ValueError, TypeError, KeyError, IndexError, struct.error) as exc:
        log.info("unreadable CRS VLR in a LAS upload: %s", exc)
        meta["crs_note"] = (
            "the file's coordinate-system record (WKT or GeoTIFF keys) could not be read; "
            "it was ignored"
        )
        crs = None
    if crs is not None:
        meta["crs"] = crs_meta(crs)
        return
    # A user-defined GeoTIFF CRS (no EPSG code) still names its linear units.
    keys = {}
    for vlr in header.vlrs:
        for key in getattr(vlr, "geo_keys", []) or []:
            keys[int(key.id)] = int(key.value_offset)
    h = _GEOTIFF_UNITS.get(keys.get(_PROJ_LINEAR_UNITS_KEY, 0))
    if h is not None and h in UNIT_TO_M:
        v = _GEOTIFF_UNITS.get(keys.get(_VERTICAL_UNITS_KEY, 0))
        meta["geokey_units"] = {"unit": h, "z_unit": v if v in UNIT_TO_M else None}


# ------------------------------------------------------------------ LAS / LAZ
_LAS_HEADER_MIN = 227  # LAS 1.0–1.2 header size


def _las_unreadable(reason: str, debug: str = "", laz: bool = False) -> SurveyReadError:
    return SurveyReadError(f"not a readable {'LAZ' if laz else 'LAS'} file: {reason}", debug)


def _check_las_header(src: _Source) -> tuple[int, bool]:
    """Check the fixed LAS header by hand (laspy's own errors on a damaged one
    are about buffers and struct sizes); return ``(points promised, compressed)``."""
    head = src.read_at(0, 375)
    if len(head) < _LAS_HEADER_MIN:
        raise _las_unreadable(
            f"the file is truncated: {src.size} bytes cannot hold a LAS header "
            f"({_LAS_HEADER_MIN} bytes at least)"
        )
    major, minor = head[24], head[25]
    if major != 1 or minor > 4:
        raise _las_unreadable(f"version {major}.{minor} in its header is not LAS 1.0–1.4")
    header_size = struct.unpack_from("<H", head, 94)[0]
    offset = struct.unpack_from("<I", head, 96)[0]
    fmt_byte = head[104]
    record = struct.unpack_from("<H", head, 105)[0]
    compressed = bool(fmt_byte & 0xC0)
    fmt = fmt_byte & 0x3F
    if header_size < _LAS_HEADER_MIN or offset < header_size:
        raise _las_unreadable(
            f"its header is damaged (header size {header_size}, points at byte {offset})",
            laz=compressed,
        )
    if fmt > 10:
        raise _las_unreadable(
            f"its point format {fmt} is not one LAS defines (0–10)", laz=compressed
        )
    n = struct.unpack_from("<I", head, 107)[0]
    if minor >= 4 and len(head) >= 375 and header_size >= 375:
        n = max(n, struct.unpack_from("<Q", head, 247)[0])
    if offset > src.size:
        raise _las_unreadable(
            f"the file is truncated: its points should start at byte {offset}, "
            f"the file has {src.size} bytes",
            laz=compressed,
        )
    if not compressed and offset + n * record > src.size:
        have = (src.size - offset) // max(record, 1)
        raise _las_unreadable(
            f"the file is truncated: its header promises {n} points, it holds {have}"
        )
    return int(n), compressed


def read_las(src: _Source, meta: dict[str, Any] | None = None) -> Iterator[Block]:
    """LAS 1.0–1.4 and LAZ points as real coordinates with their intensity,
    classification and RGB (where the point format has it), chunk by chunk;
    the CRS into ``meta``."""
    import laspy

    meta = {} if meta is None else meta
    promised, compressed = _check_las_header(src)
    got = 0
    try:
        with laspy.open(io.BufferedReader(SourceFile(src), buffer_size=1 << 20)) as reader:
            _las_crs(reader.header, meta)
            dims = set(reader.header.point_format.dimension_names)
            rgb = {"red", "green", "blue"} <= dims
            for points in reader.chunk_iterator(CHUNK_POINTS):
                xyz = np.column_stack(
                    [np.asarray(points.x), np.asarray(points.y), np.asarray(points.z)]
                )
                attrs: dict[str, np.ndarray] = {
                    "intensity": np.asarray(points.intensity, dtype=np.uint16),
                    "classification": np.asarray(points.classification, dtype=np.uint8),
                }
                if rgb:
                    attrs["rgb"] = np.column_stack(
                        [np.asarray(points[c], dtype=np.uint16) for c in ("red", "green", "blue")]
                    )
                got += len(xyz)
                yield xyz, attrs
    except SurveyReadError:
        raise
    except Exception as exc:  # laspy / lazrs: why, for people
        raise _las_error(exc, compressed) from exc
    if got < promised:
        raise _las_unreadable(
            f"the file is truncated: its header promises {promised} points, it holds {got}",
            laz=compressed,
        )


def _las_error(exc: Exception, compressed: bool) -> SurveyReadError:
    full = f"{type(exc).__name__}: {exc}"
    log.warning("unreadable LAS/LAZ upload: %s", full)
    text = str(exc)
    name = type(exc).__name__
    if name == "LazrsError" or "lazrs" in type(exc).__module__:
        reason = "its compressed points are damaged or the file is truncated"
    elif name == "PointFormatNotSupported":
        reason = f"its point format {_no_paths(text)} is not one laspy reads"
    elif "too small" in text or "to small" in text or isinstance(exc, (struct.error, EOFError)):
        reason = "the file is truncated"
    elif "buffer size must be a multiple" in text:
        reason = "the file is truncated: its last point is cut short"
    elif "header size" in text.lower():
        reason = "its header is damaged (the header size does not match its version)"
    else:
        reason = _no_paths(text) or name
    return _las_unreadable(reason, full, laz=compressed)


# ------------------------------------------------------------------ E57
#: libE57 error codes → what was wrong, for people.
_E57_REASONS = {
    "ErrorBadFileLength": "the file is truncated (its length is not what its header says)",
    "ErrorBadChecksum": "checksum mismatch: the file is corrupted (damaged in transfer?)",
    "ErrorBadFileSignature": "bad signature: it is not an E57 file",
    "ErrorUnknownFileVersion": "its E57 version is not one libE57 reads",
    "ErrorBadCVHeader": "a block of points is damaged",
    "ErrorBadCVPacket": "a block of points is damaged",
    "ErrorBadXMLFormat": "its XML section is damaged",
    "ErrorXMLParser": "its XML section is damaged",
    "ErrorXMLParserInit": "its XML section is damaged",
    "ErrorSeekFailed": "the file is truncated",
    "ErrorReadFailed": "the file is truncated",
    "ErrorInternal": "its structure is damaged or the file is truncated",
}


def _e57_unreadable(exc: Exception, tmp: str) -> SurveyReadError:
    """``exc`` from libE57 as a :class:`SurveyReadError` (logged in full here).

    libE57's message starts with a one-line reason ("checksum mismatch, file
    is corrupted (ErrorBadChecksum)") and goes on with debug text holding the
    temporary file's path and libE57's build paths: a known error code is
    said in our words, any other keeps the first line without its code or
    any path."""
    full = str(exc).strip()
    log.warning("unreadable E57 upload (%s): %s", type(exc).__name__, full)
    first = full.splitlines()[0] if full else ""
    code = re.search(r"\((Error\w+)\)\s*$", first)
    reason = _E57_REASONS.get(code.group(1)) if code else None
    if reason is None:
        first = re.sub(r"\s*\(Error\w+\)\s*$", "", first.replace(tmp, "the file"))
        reason = _no_paths(first) or type(exc).__name__
    return SurveyReadError(f"not a readable E57 file: {reason}", debug=full)


def read_e57(src: _Source, meta: dict[str, Any] | None = None) -> Iterator[Block]:
    """Every scan of an E57 file, posed into the file's frame, with intensity
    and colour where every scan has them, chunk by chunk; the root's
    ``coordinateMetadata`` into ``meta``."""
    import pye57

    meta = {} if meta is None else meta
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
            root = e57.root
            if root.isDefined("coordinateMetadata"):
                text = str(root["coordinateMetadata"].value()).strip()
                if text:
                    meta["e57_coordinate_metadata"] = text[:200]
                    _crs_from_text(text, "E57 coordinateMetadata", meta)
            for index in range(e57.scan_count):
                yield from _e57_scan(e57, index)
        except Exception as exc:  # a scan libE57 (or _e57_scan) cannot read
            raise _e57_unreadable(exc, tmp) from exc
        finally:
            e57.close()
    finally:
        with contextlib.suppress(OSError):
            os.unlink(tmp)


def _e57_scan(e57: Any, index: int) -> Iterator[Block]:
    from pye57 import libe57

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
    # Intensity as float32, colour as uint16 (pye57's own uint8 buffer would
    # refuse a 16-bit colour): buffers of our own, beside pye57's.
    extra: list[tuple[str, Any]] = [("intensity", np.float32)] if "intensity" in fields else []
    colours = ("colorRed", "colorGreen", "colorBlue")
    if set(colours) <= fields:
        extra += [(c, np.uint16) for c in colours]
    for name, dtype in extra:
        arr = np.empty(capacity, dtype)
        data[name] = arr
        buffers.append(libe57.SourceDestBuffer(e57.image_file, name, arr, capacity, True, True))
    R = header.rotation_matrix if header.has_pose() else np.eye(3)
    t = np.asarray(header.translation, dtype=float)
    reader = header.points.reader(buffers)
    try:
        while (n := int(reader.read())) > 0:
            a, b, c = (np.asarray(data[k][:n], dtype=np.float64) for k in coords)
            if spherical:
                # libE57's convention: azimuth from x towards y, elevation from the xy-plane
                rc = a * np.cos(c)
                a, b, c = rc * np.cos(b), rc * np.sin(b), a * np.sin(c)
            xyz = np.column_stack([a, b, c])
            attrs: dict[str, np.ndarray] = {}
            if "intensity" in data:
                attrs["intensity"] = np.array(data["intensity"][:n], dtype=np.float32)
            if colours[0] in data:
                attrs["rgb"] = np.column_stack([np.array(data[k][:n]) for k in colours])
            if invalid in data:
                keep = np.asarray(data[invalid][:n]) == 0
                xyz = xyz[keep]
                attrs = {k: v[keep] for k, v in attrs.items()}
            yield xyz @ np.asarray(R, dtype=float).T + t, attrs
    finally:
        reader.close()


# ------------------------------------------------------------------ spacing and units
# The unit decision for a cloud without a CRS
# (:func:`planners.pointcloud.spacing.decide_units`) lives beside the spacing it
# is made from, so a planner given a cloud in an unknown unit decides the same
# way an upload does.


def _unit_key(metres: float) -> str | None:
    return next((k for k, v in UNIT_TO_M.items() if math.isclose(metres, v, rel_tol=1e-9)), None)


def _crs_label(crs: dict[str, Any]) -> str:
    return f"{crs['name']}" + (f" (EPSG:{crs['epsg']})" if crs.get("epsg") else "")


def decide_scale(
    meta: dict[str, Any],
    fmt: str,
    units: str,
    spacing: float | None,
    extent: float,
    n_points: int,
) -> dict[str, Any]:
    """The unit of a cloud's numbers and how it was decided: ``{"units",
    "units_from", "units_reason", "scale_to_m", "scale_to_m_z"}``.

    ``units`` (the request's) other than ``auto`` wins.  With ``auto``, a CRS
    that names a linear unit decides (its horizontal axes; its vertical axis
    where it has one, else the same unit); an E57 file's CRS is recorded but
    its unit not applied (ASTM E2807 stores coordinates in metres); a
    geographic CRS (degrees) is refused; otherwise the unit is detected from
    the spacing and extent (metres or millimetres).  Raises ``ValueError`` for
    a ``units`` it does not know or a cloud in degrees."""
    if units not in UPLOAD_UNITS:
        raise ValueError(f"units must be one of {', '.join(UPLOAD_UNITS)}; got {units!r}")
    crs = meta.get("crs")
    keys = meta.get("geokey_units")
    if units != "auto":
        scale = UNIT_TO_M[units]
        reason = f"set by the request: the uploader chose units={units} ({UNIT_NAMES[units]})"
        if crs is not None and crs.get("unit_m") and fmt != "e57":
            said = _unit_key(crs["unit_m"])
            if said != units:
                reason += f"; the file's CRS {_crs_label(crs)} says {crs['unit_name']}"
        return _decision(units, FROM_REQUEST, reason, scale, scale)
    if crs is not None and fmt == "e57":
        unit, why = decide_units(spacing, extent, n_points)
        reason = (
            f"{why}; the file's CRS {_crs_label(crs)} is kept, its unit not applied: "
            "E57 stores coordinates in metres (ASTM E2807)"
        )
        return _decision(unit, DETECTED, reason, UNIT_TO_M[unit], UNIT_TO_M[unit])
    if crs is not None and crs.get("unit_m"):
        h = float(crs["unit_m"])
        v = float(crs["z_unit_m"]) if crs.get("z_unit_m") else h
        unit = _unit_key(h) or str(crs["unit_name"])
        said = UNIT_NAMES.get(unit, str(crs["unit_name"]))
        reason = f"from the CRS: {_crs_label(crs)} gives x and y in {said}"
        if crs.get("z_unit_m"):
            z_key = _unit_key(v)
            reason += f" and z in {UNIT_NAMES[z_key] if z_key else crs['z_unit_name']}"
        else:
            reason += ", and z (it has no vertical axis) is taken in the same unit"
        return _decision(unit, FROM_CRS, reason, h, v)
    if crs is not None and crs.get("geographic"):
        raise ValueError(
            f"the file's CRS {_crs_label(crs)} gives longitude and latitude in degrees, "
            "not lengths: reproject the cloud to a projected CRS (metres or feet) first, "
            "or give units to read its numbers as lengths"
        )
    if keys is not None:
        h = UNIT_TO_M[keys["unit"]]
        v = UNIT_TO_M[keys["z_unit"]] if keys.get("z_unit") else h
        reason = (
            f"from the CRS: the file's GeoTIFF keys give linear units of {UNIT_NAMES[keys['unit']]}"
        )
        return _decision(keys["unit"], FROM_CRS, reason, h, v)
    unit, why = decide_units(spacing, extent, n_points)
    if meta.get("crs_note"):
        why += f" ({meta['crs_note']})"
    elif crs is not None:
        why += f" (the file's CRS {_crs_label(crs)} names no linear unit)"
    return _decision(unit, DETECTED, why, UNIT_TO_M[unit], UNIT_TO_M[unit])


def _decision(unit: str, how: str, reason: str, h: float, v: float) -> dict[str, Any]:
    return {
        "units": unit,
        "units_from": how,
        "units_reason": reason,
        "scale_to_m": h,
        "scale_to_m_z": v,
    }


def survey_of_npy(
    path: str | os.PathLike[str],
    fmt: str,
    units: str = "auto",
    meta: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Measure the spacing of the (N,3) float64 ``.npy`` at ``path``, decide its
    units (:func:`decide_scale`) and rescale it to metres in place (chunk by
    chunk).  Returns the survey record: format, units, how and why they were
    decided, the scale applied (``scale_to_m_z`` too where z differs), the
    CRS (name and EPSG code, or None), the spacing in metres, and the bounds
    in metres."""
    meta = {} if meta is None else meta
    arr = np.load(path, mmap_mode="r+")
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for a in range(0, len(arr), CHUNK_POINTS):
        block = arr[a : a + CHUNK_POINTS]
        if len(block):
            np.minimum(lo, block.min(axis=0), out=lo)
            np.maximum(hi, block.max(axis=0), out=hi)
    spacing = measure_spacing(arr)
    extent = float((hi - lo).max()) if len(arr) else 0.0
    decision = decide_scale(meta, fmt, units, spacing, extent, len(arr))
    h, v = decision["scale_to_m"], decision["scale_to_m_z"]
    scale = np.array([h, h, v])
    if h != 1.0 or v != 1.0:
        for a in range(0, len(arr), CHUNK_POINTS):
            arr[a : a + CHUNK_POINTS] *= scale
        lo, hi = lo * scale, hi * scale
    arr.flush()
    del arr
    crs = meta.get("crs")
    survey: dict[str, Any] = {
        "format": fmt,
        **decision,
        "crs": None if crs is None else {"name": crs["name"], "epsg": crs["epsg"]},
        "spacing_m": None if spacing is None else spacing * h,
        "bounds": {"min": lo.tolist(), "max": hi.tolist()},
    }
    if v == h:
        del survey["scale_to_m_z"]
    if meta.get("crs_note"):
        survey["crs_note"] = meta["crs_note"]
    return survey
