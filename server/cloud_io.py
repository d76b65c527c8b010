"""Reading uploaded point clouds: PLY, PCD (ascii/binary), XYZ/CSV, NPY, LAS/LAZ,
E57 (:mod:`server.survey_io`) — in chunks.

Every reader walks its input in bounded chunks (:data:`CHUNK_BYTES`): binary
PLY/PCD/NPY records are read with ``os.pread`` (or sliced from bytes) and
viewed with ``np.frombuffer``; text rows are cut at line ends and parsed
chunk by chunk with ``np.loadtxt``.  Each chunk becomes an (k,3) float64
block; rows with a non-finite coordinate are dropped and counted.  Empty,
unparseable or self-contradicting input (negative counts, complex numbers,
short bodies) raises :class:`CloudFormatError` with a message saying what
was wrong.

Two sinks share the readers: :func:`read_cloud` collects the points in memory
(small inputs, tests), :func:`parse_to_npy` streams them into an ``.npy``
file written under a temporary name and renamed into place, so its memory
stays a few chunks whatever the file size.  ``python -m server.cloud_io
upload RAW CONTENT_TYPE OUT`` is the upload parser the API runs in a niced
child process: it finds the ``file`` part of a spooled multipart body (by
byte range, without copying it), parses it into ``OUT`` and prints one JSON
line with the outcome.
"""

from __future__ import annotations

import contextlib
import io
import itertools
import json
import math
import os
import re
import resource
import sys
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from server.lifetime import die_with_parent
from server.survey_io import (
    UPLOAD_UNITS,
    SurveyReadError,
    read_e57,
    read_las,
    survey_of_npy,
)

FORMATS = ("ply", "pcd", "xyz", "csv", "txt", "npy", "las", "laz", "e57")

#: Bytes read per step; the parser's memory is a small multiple of this.
CHUNK_BYTES = 8 << 20
#: How far into a file its header may reach.
HEADER_BYTES = 1 << 20
#: Size of the ``.npy`` header :func:`parse_to_npy` writes (fixed, so it can be
#: written last, once the number of points is known).
NPY_HEADER_BYTES = 128
#: Fewest finite points an uploaded cloud may hold: fewer than any plan kind
#: can use, so such a cloud is refused (422) rather than stored for every plan
#: on it to fail.  The least demanding use is ``ara.inspect``'s structure
#: model, which needs 10 points (``planners.inspection.inspect_plan.crop``);
#: a ``blast`` surface needs a plane of 100, ``ara.switch`` one of 150 and
#: ``ara.navigate`` one of 200.
MIN_CLOUD_POINTS = 10


class CloudFormatError(ValueError):
    """The upload is not a readable point cloud."""


_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}  # fmt: skip


# ------------------------------------------------------------------ sources
class Source(Protocol):
    """Random access to a byte range (a whole buffer or a window of a file)."""

    size: int

    def read_at(self, offset: int, n: int) -> bytes: ...


class BytesSource:
    def __init__(self, data: bytes) -> None:
        self._view = memoryview(data)
        self.size = len(data)

    def read_at(self, offset: int, n: int) -> bytes:
        return bytes(self._view[offset : offset + max(n, 0)])


class FileSource:
    """Bytes ``[start, end)`` of an open file descriptor, read with ``os.pread``."""

    def __init__(self, fd: int, start: int = 0, end: int | None = None) -> None:
        self.fd = fd
        self.start = start
        self.size = (os.fstat(fd).st_size if end is None else end) - start

    def read_at(self, offset: int, n: int) -> bytes:
        n = min(n, self.size - offset)
        if n <= 0:
            return b""
        parts, got = [], 0
        while got < n:  # pread may return short reads on large requests
            b = os.pread(self.fd, n - got, self.start + offset + got)
            if not b:
                break
            parts.append(b)
            got += len(b)
        return b"".join(parts)


# ------------------------------------------------------------------ sinks
def read_cloud(data: bytes, filename: str = "") -> tuple[np.ndarray, int]:
    """Parse ``data``; returns ``(points (N,3) float64, dropped_nonfinite)``."""
    blocks: list[np.ndarray] = []
    dropped = 0
    for block, bad, _ in _finite_blocks(BytesSource(data), filename):
        blocks.append(block)
        dropped += bad
    pts = np.concatenate(blocks) if blocks else np.zeros((0, 3))
    return np.ascontiguousarray(pts, dtype=np.float64), dropped


@dataclass
class ParseResult:
    n_points: int
    dropped: int
    bounds: dict[str, list[float]]
    #: Per-point attributes kept, name → what they hold (dtype, range, bit depth...).
    attributes: dict[str, dict[str, Any]] = field(default_factory=dict)
    #: ... and where each was written (beside ``out``: ``<stem>.<name>.npy``).
    attribute_paths: dict[str, Path] = field(default_factory=dict)


#: Per-point attributes an upload keeps, in the order the record lists them.
ATTRIBUTES = ("intensity", "rgb", "classification")


def attribute_path(out: Path, name: str) -> Path:
    """Where the attribute ``name`` of the cloud stored at ``out`` is written."""
    return out.with_name(f"{out.stem}.{name}.npy")


class _DropAttribute(Exception):
    """An attribute cannot be kept for every point: it is not kept at all."""


class _ArraySink:
    """An ``.npy`` written block by block behind a reserved header (as the
    points are), its dtype and columns fixed by the first block."""

    def __init__(self, name: str, target: Path) -> None:
        self.name, self.target = name, target
        fd, self.tmp = tempfile.mkstemp(dir=target.parent, prefix=".tmp-", suffix=".npy")
        self.fh = os.fdopen(fd, "wb")
        self.fh.write(b"\0" * NPY_HEADER_BYTES)
        self.dtype: np.dtype | None = None
        self.cols: tuple[int, ...] = ()
        self.n = 0
        self.lo = math.inf
        self.hi = -math.inf
        self.counts = np.zeros(256, dtype=np.int64)

    def write(self, arr: np.ndarray) -> None:
        if self.dtype is None:
            self.dtype, self.cols = arr.dtype, arr.shape[1:]
        elif arr.dtype != self.dtype or arr.shape[1:] != self.cols:
            raise _DropAttribute(f"its type changes within the file ({self.dtype} → {arr.dtype})")
        if not len(arr):
            return
        self.fh.write(np.ascontiguousarray(arr, dtype=self.dtype.newbyteorder("<")).tobytes())
        self.n += len(arr)
        with np.errstate(invalid="ignore"):
            lo, hi = float(np.nanmin(arr)), float(np.nanmax(arr))
        if math.isfinite(lo):
            self.lo = min(self.lo, lo)
        if math.isfinite(hi):
            self.hi = max(self.hi, hi)
        if self.name == "classification":
            self.counts += np.bincount(arr.astype(np.uint8, copy=False), minlength=256)

    def finish(self) -> dict[str, Any]:
        """Write the header, fsync and rename into place; what the array holds."""
        assert self.dtype is not None
        descr = str(np.lib.format.dtype_to_descr(self.dtype.newbyteorder("<")))
        self.fh.seek(0)
        self.fh.write(npy_header(self.n, descr, self.cols))
        self.fh.flush()
        os.fsync(self.fh.fileno())
        self.fh.close()
        os.replace(self.tmp, self.target)
        info: dict[str, Any] = {"dtype": str(self.dtype)}
        if self.name == "rgb":
            info["bits"] = 8 if self.hi <= 255 else 16
        elif self.name == "classification":
            info["classes"] = {str(c): int(k) for c, k in enumerate(self.counts) if k}
        else:
            info["min"] = self.lo if math.isfinite(self.lo) else None
            info["max"] = self.hi if math.isfinite(self.hi) else None
        return info

    def abandon(self) -> None:
        with contextlib.suppress(OSError):
            self.fh.close()
        Path(self.tmp).unlink(missing_ok=True)


def parse_to_npy(
    src: Source, filename: str, out: Path, meta: dict[str, Any] | None = None
) -> ParseResult:
    """Parse ``src`` into an (N,3) float64 ``.npy`` at ``out``, atomically, and
    its per-point attributes (:data:`ATTRIBUTES`, where the file has them for
    every point) into ``<stem>.<name>.npy`` beside it.

    The rows go to a temporary file beside ``out`` behind a reserved header;
    the header is written once N is known, the file is fsynced and renamed
    over ``out``; each attribute likewise, its rows those of the kept points.
    An attribute that is not given for every point, changes type, or is zero
    for every point (LAS writers fill fields they have no data for with 0) is
    not kept: ``meta["attribute_notes"]`` says why.  On any error every
    temporary file is removed.  ``meta`` receives what the reader learnt of
    the file as a whole (its CRS)."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    meta = {} if meta is None else meta
    notes: dict[str, str] = meta.setdefault("attribute_notes", {})
    fd, tmp = tempfile.mkstemp(dir=out.parent, prefix=".tmp-", suffix=".npy")
    n = dropped = 0
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    sinks: dict[str, _ArraySink] = {}
    done: dict[str, Path] = {}
    infos: dict[str, dict[str, Any]] = {}

    def drop(name: str, why: str) -> None:
        notes.setdefault(name, why)
        sink = sinks.pop(name, None)
        if sink is not None:
            sink.abandon()

    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(b"\0" * NPY_HEADER_BYTES)
            for block, bad, attrs in _finite_blocks(src, filename, meta):
                dropped += bad
                for name in list(sinks):
                    if name not in attrs:
                        drop(name, "not given for every point")
                for name in ATTRIBUTES:
                    if name in attrs and name not in sinks and name not in notes:
                        if n:
                            notes[name] = "not given for every point"
                        else:
                            sinks[name] = _ArraySink(name, attribute_path(out, name))
                for name, sink in list(sinks.items()):
                    try:
                        sink.write(attrs[name])
                    except _DropAttribute as exc:
                        drop(name, str(exc))
                if len(block):
                    fh.write(block.tobytes())
                    n += len(block)
                    np.minimum(lo, block.min(axis=0), out=lo)
                    np.maximum(hi, block.max(axis=0), out=hi)
            fh.seek(0)
            fh.write(npy_header(n))
            fh.flush()
            os.fsync(fh.fileno())
        for name in list(sinks):
            sink = sinks[name]
            if sink.n != n or sink.dtype is None:
                drop(name, "not given for every point")
            elif sink.hi <= 0 and sink.lo >= 0:
                drop(name, "zero for every point: the file does not record it")
            else:
                infos[name] = sinks.pop(name).finish()
                done[name] = attribute_path(out, name)
        os.replace(tmp, out)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        for sink in sinks.values():
            sink.abandon()
        for path in done.values():
            path.unlink(missing_ok=True)
        raise
    ordered = {k: infos[k] for k in ATTRIBUTES if k in infos}
    return ParseResult(n, dropped, {"min": lo.tolist(), "max": hi.tolist()}, ordered, done)


def npy_header(n: int, descr: str = "<f8", cols: tuple[int, ...] = (3,)) -> bytes:
    """A version-1.0 ``.npy`` header for an (n, *cols) little-endian array of
    ``descr`` (default (n,3) float64), padded to exactly :data:`NPY_HEADER_BYTES`
    (the format allows any padding that keeps the data 64-byte aligned and
    ends the header with a newline)."""
    shape = (n, *cols)
    d = f"{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape!r}, }}"
    body_len = NPY_HEADER_BYTES - 10
    if len(d) + 1 > body_len:
        raise CloudFormatError(f"{n} points do not fit an .npy header")
    text = d.ljust(body_len - 1) + "\n"
    return b"\x93NUMPY\x01\x00" + body_len.to_bytes(2, "little") + text.encode("latin-1")


# ------------------------------------------------------------------ readers
def _finite_blocks(
    src: Source, filename: str, meta: dict[str, Any] | None = None
) -> Iterator[tuple[np.ndarray, int, dict[str, np.ndarray]]]:
    """(finite rows, number dropped, their attributes) per chunk; raises if
    nothing finite is left."""
    if src.size == 0:
        raise CloudFormatError("the uploaded file is empty")
    meta = {} if meta is None else meta
    head = src.read_at(0, 8192)
    fmt = detect_format(head, filename)
    readers: dict[str, Any] = {
        "ply": _read_ply,
        "pcd": _read_pcd,
        "npy": _read_npy,
    }
    kept = dropped = 0
    try:
        if fmt in readers:
            blocks: Iterator[Any] = readers[fmt](src)
        else:
            blocks = {"las": read_las, "e57": read_e57}.get(fmt, _read_text)(src, meta)
        for raw in blocks:
            xyz, attrs = raw if isinstance(raw, tuple) else (raw, {})
            pts = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
            finite = np.isfinite(pts).all(axis=1)
            bad = int(len(pts) - finite.sum())
            attrs = {k: np.asarray(v) for k, v in attrs.items() if len(v) == len(pts)}
            if bad:
                pts = pts[finite]
                attrs = {k: v[finite] for k, v in attrs.items()}
            kept += len(pts)
            dropped += bad
            yield pts, bad, attrs
    except CloudFormatError:
        raise
    except SurveyReadError as exc:  # its message is written for people already
        raise CloudFormatError(str(exc)) from exc
    except Exception as exc:  # any parser failure becomes a readable 400
        raise CloudFormatError(f"could not parse {fmt.upper()} data: {exc}") from exc
    if kept == 0:
        raise CloudFormatError(
            f"the {fmt.upper()} file holds no points with finite x, y, z"
            + (f" ({dropped} non-finite rows dropped)" if dropped else "")
        )


def detect_format(data: bytes, filename: str) -> str:
    """Format from the first bytes (magic, PCD keywords), else the extension."""
    ext = filename.rsplit(".", 1)[-1].lower() if "." in filename else ""
    if data.startswith(b"ply"):
        return "ply"
    if data.startswith(b"\x93NUMPY"):
        return "npy"
    if data.startswith(b"LASF"):  # LAS and LAZ share the signature
        return "las"
    if data.startswith(b"ASTM-E57"):
        return "e57"
    head = data[:2048].decode("latin-1")
    if re.search(r"^\s*(VERSION|FIELDS)\s", head, re.M) and "DATA" in data[:8192].decode("latin-1"):
        return "pcd"
    if ext in ("las", "laz"):
        raise CloudFormatError(
            f"not a {ext.upper()} file: bad signature (a LAS or LAZ file starts with 'LASF')"
        )
    if ext == "e57":
        raise CloudFormatError(
            "not an E57 file: bad signature (an E57 file starts with 'ASTM-E57')"
        )
    if ext in ("ply", "pcd", "npy"):
        raise CloudFormatError(f"file {filename!r} does not start like a {ext.upper()} file")
    return "xyz"


def _count(text: str, what: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise CloudFormatError(f"{what} must be a whole number, got {text!r}") from None
    if n < 0:
        raise CloudFormatError(f"{what} must be ≥ 0, got {n}")
    return n


def _records(src: Source, start: int, n: int, dtype: np.dtype, what: str) -> Iterator[np.ndarray]:
    """``n`` fixed-size records from ``start``, a chunk at a time."""
    need = n * dtype.itemsize
    have = src.size - start
    if have < need:
        raise CloudFormatError(
            f"{what} body too short: {n} records need {need} bytes, got {max(have, 0)}"
        )
    per = max(1, CHUNK_BYTES // max(dtype.itemsize, 1))
    for i in range(0, n, per):
        k = min(per, n - i)
        yield np.frombuffer(src.read_at(start + i * dtype.itemsize, k * dtype.itemsize), dtype)


def _line_chunks(src: Source, start: int) -> Iterator[bytes]:
    """The bytes from ``start`` in chunks that end at a line end (or EOF)."""
    pos = start
    while pos < src.size:
        buf = src.read_at(pos, CHUNK_BYTES)
        if pos + len(buf) < src.size:
            cut = buf.rfind(b"\n")
            if cut < 0:
                raise CloudFormatError(
                    f"a line longer than {CHUNK_BYTES >> 20} MiB: not a point-cloud text file"
                )
            buf = buf[: cut + 1]
        pos += len(buf)
        yield buf


def _loadtxt(text: str, **kw: Any) -> np.ndarray | None:
    """``np.loadtxt`` of one chunk; ``None`` when it holds no rows."""
    if not text.strip():
        return None
    arr = np.loadtxt(io.StringIO(text), ndmin=2, **kw)
    return arr if arr.size else None


def _read_ply(src: Source) -> Iterator[np.ndarray]:
    head = src.read_at(0, HEADER_BYTES)
    end = head.find(b"end_header")
    if end < 0:
        raise CloudFormatError("PLY header has no 'end_header' line")
    nl = head.find(b"\n", end)
    body = src.size if nl < 0 else nl + 1
    header = head[:end].decode("ascii", "replace").splitlines()
    fmt = None
    elements: list[tuple[str, int, list[tuple[str, str]]]] = []
    for line in header:
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "format":
            fmt = parts[1] if len(parts) > 1 else None
        elif parts[0] == "element":
            if len(parts) < 3:
                raise CloudFormatError(f"PLY element line {line!r} needs a name and a count")
            elements.append((parts[1], _count(parts[2], f"PLY element {parts[1]} count"), []))
        elif parts[0] == "property":
            if not elements:
                raise CloudFormatError("PLY property before any element")
            if len(parts) < 3:
                raise CloudFormatError(f"PLY property line {line!r} needs a type and a name")
            if parts[1] == "list":
                elements[-1][2].append((parts[-1], "list"))
            else:
                if parts[1] not in _PLY_TYPES:
                    raise CloudFormatError(f"unknown PLY property type {parts[1]!r}")
                elements[-1][2].append((parts[2], _PLY_TYPES[parts[1]]))
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise CloudFormatError(f"unsupported PLY format {fmt!r}")
    if not elements or elements[0][0] != "vertex":
        raise CloudFormatError("PLY file has no leading 'vertex' element")
    _, n, props = elements[0]
    names = [p[0] for p in props]
    if any(t == "list" for _, t in props):
        raise CloudFormatError("PLY vertex element with list properties is not supported")
    missing = [c for c in "xyz" if c not in names]
    if missing:
        raise CloudFormatError(f"PLY vertex element lacks properties {missing}")
    cols = [names.index(c) for c in "xyz"]
    if fmt == "ascii":
        left = n
        for chunk in _line_chunks(src, body):
            if left == 0:
                break
            text = chunk.decode("ascii", "replace")
            lines = text[:-1].split("\n") if text.endswith("\n") else text.split("\n")
            take = lines[:left]
            left -= len(take)
            arr = _loadtxt("\n".join(take))
            if arr is None:
                continue
            if arr.shape[1] < len(names):
                raise CloudFormatError("PLY vertex rows have fewer values than properties")
            yield arr[:, cols]
        if left:
            raise CloudFormatError(f"PLY header promises {n} vertices, file has {n - left}")
        return
    endian = "<" if fmt == "binary_little_endian" else ">"
    dtype = np.dtype([(nm, endian + t) for nm, t in props])
    for rec in _records(src, body, n, dtype, "PLY"):
        yield np.stack([rec[c].astype(np.float64) for c in "xyz"], axis=1)


def _read_pcd(src: Source) -> Iterator[np.ndarray]:
    head = src.read_at(0, HEADER_BYTES)
    header: dict[str, list[str]] = {}
    pos = 0
    while True:
        nl = head.find(b"\n", pos)
        if nl < 0:
            raise CloudFormatError("PCD header has no DATA line")
        line = head[pos:nl].decode("ascii", "replace").strip()
        pos = nl + 1
        if not line or line.startswith("#"):
            continue
        key, *vals = line.split()
        header[key.upper()] = vals
        if key.upper() == "DATA":
            break
    fields = header.get("FIELDS")
    if not fields:
        raise CloudFormatError("PCD header lacks FIELDS")
    missing = [c for c in "xyz" if c not in fields]
    if missing:
        raise CloudFormatError(f"PCD fields {fields} lack {missing}")
    nf = len(fields)
    sizes = [_count(s, "PCD SIZE") for s in header.get("SIZE", ["4"] * nf)]
    types = header.get("TYPE", ["F"] * nf)
    counts = [_count(c, "PCD COUNT") for c in header.get("COUNT", ["1"] * nf)]
    if not (len(sizes) == len(types) == len(counts) == nf):
        raise CloudFormatError("PCD SIZE, TYPE and COUNT must have one entry per field")
    if "POINTS" in header:
        n = _count((header["POINTS"] or [""])[0], "PCD POINTS")
    else:
        w = _count((header.get("WIDTH") or ["0"])[0], "PCD WIDTH")
        h = _count((header.get("HEIGHT") or ["1"])[0], "PCD HEIGHT")
        n = w * h
    if not header["DATA"]:
        raise CloudFormatError("PCD DATA line names no encoding")
    mode = header["DATA"][0].lower()
    if mode == "ascii":
        idx, c = {}, 0
        for f, cnt in zip(fields, counts, strict=True):
            if f in ("x", "y", "z"):
                idx[f] = c
            c += cnt
        cols = [idx["x"], idx["y"], idx["z"]]
        for chunk in _line_chunks(src, pos):
            arr = _loadtxt(chunk.decode("ascii", "replace"))
            if arr is None:
                continue
            if arr.shape[1] <= max(cols):
                raise CloudFormatError("PCD rows have fewer values than FIELDS/COUNT promise")
            yield arr[:, cols]
        return
    if mode == "binary":
        kinds = {"F": "f", "I": "i", "U": "u"}
        dt: list[Any] = []
        for f, s, t, cnt in zip(fields, sizes, types, counts, strict=True):
            if t.upper() not in kinds:
                raise CloudFormatError(f"unknown PCD TYPE {t!r} (use F, I or U)")
            name = f if f != "_" else f"_pad{len(dt)}"
            code = f"<{kinds[t.upper()]}{s}"
            dt.append((name, code, (cnt,)) if cnt > 1 else (name, code))
        dtype = np.dtype(dt)
        for rec in _records(src, pos, n, dtype, "PCD"):
            yield np.stack([rec[c].astype(np.float64) for c in "xyz"], axis=1)
        return
    raise CloudFormatError(
        f"PCD DATA {mode!r} is not supported (use ascii or binary; "
        "binary_compressed can be converted with pcl_convert_pcd_ascii_binary)"
    )


def _real(dtype: np.dtype) -> bool:
    return dtype.kind in "iuf"


def _read_npy(src: Source) -> Iterator[np.ndarray]:
    fp = io.BytesIO(src.read_at(0, HEADER_BYTES))
    version = np.lib.format.read_magic(fp)
    if version == (1, 0):
        shape, fortran, dtype = np.lib.format.read_array_header_1_0(fp)
    else:
        shape, fortran, dtype = np.lib.format.read_array_header_2_0(fp)
    start = fp.tell()
    if dtype.hasobject:
        raise CloudFormatError("NPY arrays of Python objects are not accepted")
    count = math.prod(shape)
    if dtype.names:
        missing = [c for c in "xyz" if c not in dtype.names]
        if missing:
            raise CloudFormatError(f"structured NPY array lacks fields {missing}")
        fields = dtype.fields
        assert fields is not None  # a dtype with names always has fields
        for c in "xyz":
            sub = fields[c][0]
            if sub.shape or not _real(sub):
                raise CloudFormatError(
                    f"structured NPY field {c!r} must be one real number; got {sub}"
                )
        for rec in _records(src, start, count, dtype, "NPY"):
            yield np.stack([rec[c].astype(np.float64) for c in "xyz"], axis=1)
        return
    if len(shape) != 2 or shape[1] < 3:
        raise CloudFormatError(f"NPY array must have shape (N, 3) or (N, >3); got {shape}")
    if not _real(dtype):
        raise CloudFormatError(f"NPY array must hold real numbers; got dtype {dtype}")
    n, m = shape
    if fortran:  # column-major: each column is n contiguous values
        need = n * m * dtype.itemsize
        if src.size - start < need:
            raise CloudFormatError(f"NPY body too short: {need} bytes needed")
        per = max(1, CHUNK_BYTES // (3 * dtype.itemsize))
        for i in range(0, n, per):
            k = min(per, n - i)
            size = dtype.itemsize
            cols = [
                np.frombuffer(src.read_at(start + (j * n + i) * size, k * size), dtype)
                for j in range(3)
            ]
            yield np.stack(cols, axis=1).astype(np.float64)
        return
    row = np.dtype((dtype, (m,)))
    for rec in _records(src, start, n, row, "NPY"):
        yield rec[:, :3].astype(np.float64)


_NUM = re.compile(r"^[\s,;]*[-+]?(\d|\.\d|nan|inf)", re.I)
_SEPARATORS = str.maketrans(",;", "  ")


#: Column names a text file's header line may use, and what they are.
_COLUMN_NAMES = {
    "x": "x", "y": "y", "z": "z",
    "i": "intensity", "intensity": "intensity", "scalar_intensity": "intensity",
    "r": "r", "red": "r", "g": "g", "green": "g", "b": "b", "blue": "b",
}  # fmt: skip
#: Columns by count when no header line names them.
_COLUMN_RULE: dict[int, tuple[str, ...]] = {
    3: ("x", "y", "z"),
    4: ("x", "y", "z", "intensity"),
    6: ("x", "y", "z", "r", "g", "b"),
    7: ("x", "y", "z", "r", "g", "b", "intensity"),
}
COLUMN_RULE_TEXT = (
    "3 columns: x y z; 4: x y z i; 6: x y z r g b; 7: x y z r g b i; "
    "or a header line naming the columns (x, y, z, intensity, r/red, g/green, b/blue)"
)


def text_columns(header: str | None, first_row: str) -> tuple[dict[str, int], str | None]:
    """Which column holds what (``x``, ``y``, ``z``, ``intensity``, ``r``,
    ``g``, ``b`` → index) for a text cloud whose first numeric row is
    ``first_row`` and whose last line before it is ``header``; and a note when
    columns were left unread.  A header naming x, y and z decides; otherwise
    the number of columns does (:data:`COLUMN_RULE_TEXT`)."""
    if header is not None:
        line = header.strip().lstrip("/#").strip()
        sep = "," if "," in line else (";" if ";" in line else None)
        names = [_COLUMN_NAMES.get(w.strip().lower()) for w in line.split(sep)]
        if all(c in names for c in "xyz"):
            cols = {c: names.index(c) for c in dict.fromkeys(n for n in names if n)}
            if not all(c in cols for c in "rgb"):
                cols = {k: v for k, v in cols.items() if k not in "rgb"}
            return cols, None
    n = len(first_row.split("#", 1)[0].translate(_SEPARATORS).split())
    rule = _COLUMN_RULE.get(n)
    if rule is None:
        return {c: i for i, c in enumerate("xyz")}, (
            f"rows have {n} columns: only x y z (the first three) were read; "
            f"the column rule is {COLUMN_RULE_TEXT}"
        )
    return {c: i for i, c in enumerate(rule)}, None


def _read_text(src: Source, meta: dict[str, Any] | None = None) -> Iterator[Any]:
    """Rows of ``x y z`` (commas, semicolons or blanks between), after any
    header lines; intensity and colour columns by :func:`text_columns`.  A
    chunk whose colour is not whole numbers 0–65535, or whose rows lack a
    column, is yielded without it (so the attribute is not kept)."""
    meta = {} if meta is None else meta
    notes: dict[str, str] = meta.setdefault("attribute_notes", {})
    first: int | None = None  # header lines before the first numeric row
    skipped = 0
    last_header: str | None = None
    cols: dict[str, int] = {}
    for chunk in _line_chunks(src, 0):
        try:
            text = chunk.decode("utf-8")
        except UnicodeDecodeError:
            raise CloudFormatError(
                "not a recognised point-cloud file: it is binary but neither PLY, PCD nor NPY"
            ) from None
        if first is None:
            # Skip comments and header lines (column names) before the first numeric row.
            lines = text.splitlines(keepends=True)
            at = next((i for i, ln in enumerate(lines) if _NUM.match(ln)), None)
            heads = [ln for ln in lines[: len(lines) if at is None else at] if ln.strip()]
            if heads:
                last_header = heads[-1]
            if at is None:
                skipped += len(lines)
                continue
            first = skipped + at
            text = "".join(lines[at:])
            cols, note = text_columns(last_header, lines[at])
            if note:
                meta["columns_note"] = note
            meta["columns"] = sorted(cols, key=cols.__getitem__)
        body = text.translate(_SEPARATORS)
        use = sorted(set(cols.values()))
        try:
            arr = _loadtxt(body, usecols=use, comments="#")
        except ValueError:
            arr = None
            if len(use) > 3:  # rows without the extra columns: x y z only from here on
                for name in ("intensity", "rgb"):
                    notes.setdefault(name, "not given on every row")
                cols = {c: cols[c] for c in "xyz"}
                use = sorted(set(cols.values()))
            try:
                arr = _loadtxt(body, usecols=use, comments="#")
            except ValueError as exc:
                raise CloudFormatError(
                    f"rows must hold at least 3 numbers (x y z), after {first} header line(s): "
                    f"{exc}"
                ) from None
        if arr is None:
            continue
        at_col = {c: use.index(i) for c, i in cols.items()}
        xyz = arr[:, [at_col["x"], at_col["y"], at_col["z"]]]
        attrs: dict[str, np.ndarray] = {}
        if "intensity" in at_col:
            attrs["intensity"] = arr[:, at_col["intensity"]].astype(np.float32)
        if all(c in at_col for c in "rgb"):
            rgb = arr[:, [at_col["r"], at_col["g"], at_col["b"]]]
            if (
                np.isfinite(rgb).all()
                and (rgb == np.round(rgb)).all()
                and (rgb.min(initial=0) >= 0 and rgb.max(initial=0) <= 65535)
            ):
                attrs["rgb"] = rgb.astype(np.uint16)
            else:
                notes.setdefault(
                    "rgb", "the r g b columns are not whole numbers 0–255 (or 0–65535)"
                )
        yield xyz, attrs
    if first is None:
        raise CloudFormatError("no numeric rows found: expected lines of 'x y z' or 'x,y,z'")


# ------------------------------------------------------------------ multipart
@dataclass
class Part:
    name: str
    filename: str | None
    start: int
    end: int


def multipart_parts(src: Source, boundary: bytes, max_parts: int = 16) -> list[Part]:
    """The parts of a ``multipart/form-data`` body as byte ranges (RFC 7578).

    Delimiters are ``--boundary`` at the start or ``CRLF--boundary``; each part
    is headers, a blank line, then its body up to the next delimiter.  Found by
    chunked search, so the body is never held whole.
    """
    if not boundary or len(boundary) > 200:
        raise CloudFormatError("multipart boundary is missing or too long")
    marker = b"\r\n--" + boundary
    offsets = [-2] if src.read_at(0, len(marker) - 2) == marker[2:] else []
    offsets += list(_find_all(src, marker))
    parts: list[Part] = []
    for here, nxt in itertools.pairwise(offsets):
        hstart = here + len(marker)
        if src.read_at(hstart, 2) == b"--":
            break
        block = src.read_at(hstart, min(16384, nxt - hstart))
        sep = block.find(b"\r\n\r\n")
        if sep < 0:
            raise CloudFormatError("malformed multipart body: a part has no header end")
        headers = block[:sep].decode("utf-8", "replace")
        disp = next(
            (h for h in headers.split("\r\n") if h.lower().startswith("content-disposition:")),
            "",
        )
        name = re.search(r';\s*name="([^"]*)"', disp)
        fname = re.search(r';\s*filename="([^"]*)"', disp)
        parts.append(
            Part(
                name.group(1) if name else "",
                fname.group(1) if fname else None,
                hstart + sep + 4,
                nxt,
            )
        )
        if len(parts) > max_parts:
            raise CloudFormatError(f"multipart body has more than {max_parts} parts")
    if not offsets:
        raise CloudFormatError("malformed multipart body: no boundary found")
    return parts


def _find_all(src: Source, needle: bytes) -> Iterator[int]:
    pos, keep = 0, len(needle) - 1
    while pos < src.size:
        buf = src.read_at(pos, CHUNK_BYTES)
        i = buf.find(needle)
        while i >= 0:
            yield pos + i
            i = buf.find(needle, i + 1)
        if pos + len(buf) >= src.size:
            return
        pos += len(buf) - keep  # overlap so a needle across the cut is seen once


def parse_upload(raw: Path, content_type: str, out: Path) -> dict[str, Any]:
    """Parse a spooled multipart upload into ``out``; the JSON-able outcome.

    ``{"ok": true, "n_points", "dropped", "bounds", "survey", "attributes" (names of the
    arrays written beside ``out``), "crs_wkt", "filename", "name"}`` or
    ``{"ok": false, "status": 400|422, "detail": "..."}``, with ``"log"``: a
    reader library's full report for the server's log, when it had one.
    """
    m = re.search(r'boundary="?([^";]+)"?', content_type)
    if m is None:
        return {"ok": False, "status": 400, "detail": "multipart body without a boundary"}
    fd = os.open(raw, os.O_RDONLY)
    try:
        body = FileSource(fd)
        try:
            parts = multipart_parts(body, m.group(1).encode("latin-1"))
        except CloudFormatError as exc:
            return {"ok": False, "status": 400, "detail": str(exc)}
        file = next((p for p in parts if p.name == "file" and p.filename is not None), None)
        if file is None:
            return {
                "ok": False,
                "status": 422,
                "detail": "multipart upload needs a 'file' field holding the cloud",
            }
        name_part = next((p for p in parts if p.name == "name" and p.filename is None), None)
        name: str | None = None
        if name_part is not None:
            name_bytes = body.read_at(name_part.start, min(name_part.end - name_part.start, 500))
            name = name_bytes.decode("utf-8", "replace").strip() or None
        units = "auto"
        units_part = next((p for p in parts if p.name == "units" and p.filename is None), None)
        if units_part is not None:
            raw_units = body.read_at(units_part.start, min(units_part.end - units_part.start, 20))
            units = raw_units.decode("utf-8", "replace").strip().lower() or "auto"
        if units not in UPLOAD_UNITS:
            return {
                "ok": False,
                "status": 422,
                "detail": f"units must be one of {', '.join(UPLOAD_UNITS)}; got {units!r}",
            }
        filename = file.filename or ""
        src = FileSource(fd, file.start, file.end)
        meta: dict[str, Any] = {}
        res: ParseResult | None = None
        try:
            res = parse_to_npy(src, filename, out, meta)
            if res.n_points < MIN_CLOUD_POINTS:
                _remove(out, res)
                return {
                    "ok": False,
                    "status": 422,
                    "detail": f"{filename or 'upload'}: {res.n_points} point(s) with finite "
                    f"x, y, z; a cloud needs at least {MIN_CLOUD_POINTS} points, fewer than "
                    "any plan kind can use",
                }
            fmt = detect_format(src.read_at(0, 8192), filename)
            try:
                survey = survey_of_npy(out, fmt, units, meta)
            except ValueError as exc:  # a CRS in degrees: the file is read, but unusable
                _remove(out, res)
                return {"ok": False, "status": 422, "detail": f"{filename or 'upload'}: {exc}"}
        except CloudFormatError as exc:
            if res is not None:
                _remove(out, res)
            refused = {"ok": False, "status": 400, "detail": f"{filename or 'upload'}: {exc}"}
            debug = getattr(exc.__cause__, "debug", "")
            if debug:
                refused["log"] = debug
            return refused
    finally:
        os.close(fd)
    survey["attributes"] = res.attributes
    notes = {k: v for k, v in meta.get("attribute_notes", {}).items() if k not in res.attributes}
    if notes:
        survey["attributes_not_kept"] = notes
    if meta.get("columns"):
        survey["columns"] = meta["columns"]
    if meta.get("columns_note"):
        survey["columns_note"] = meta["columns_note"]
    crs = meta.get("crs")
    return {
        "ok": True,
        "n_points": res.n_points,
        "dropped": res.dropped,
        "bounds": survey.pop("bounds"),
        "survey": survey,
        "attributes": list(res.attributes),
        "crs_wkt": None if crs is None else crs["wkt"],
        "filename": filename,
        "name": name,
    }


def _remove(out: Path, res: ParseResult) -> None:
    """Remove a parsed cloud and its attribute arrays (refused after parsing)."""
    out.unlink(missing_ok=True)
    for path in res.attribute_paths.values():
        path.unlink(missing_ok=True)


# ------------------------------------------------------------------ child process
def _own_peak_rss_kb() -> int:
    """This process's peak resident set since its exec (``VmHWM``).

    ``ru_maxrss`` is not that: a child forked from a large server keeps the
    parent's resident size as its starting maximum, across the exec.
    """
    with contextlib.suppress(OSError, ValueError):
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1])
    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)


def main(argv: list[str]) -> int:
    """``upload RAW CONTENT_TYPE OUT PARENT_PID``: one JSON line on stdout."""
    if len(argv) != 5 or argv[0] != "upload":
        print("usage: python -m server.cloud_io upload RAW CONTENT_TYPE OUT PARENT_PID",
              file=sys.stderr)  # fmt: skip
        return 2
    die_with_parent(int(argv[4]))
    with contextlib.suppress(OSError):
        os.nice(10)  # parsing yields the CPU to the API and the robot links
    outcome = parse_upload(Path(argv[1]), argv[2], Path(argv[3]))
    outcome["peak_rss_kb"] = _own_peak_rss_kb()
    print(json.dumps(outcome), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
