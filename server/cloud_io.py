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
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from server.lifetime import die_with_parent
from server.survey_io import SurveyReadError, read_e57, read_las, survey_of_npy

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
    for block, bad in _finite_blocks(BytesSource(data), filename):
        blocks.append(block)
        dropped += bad
    pts = np.concatenate(blocks) if blocks else np.zeros((0, 3))
    return np.ascontiguousarray(pts, dtype=np.float64), dropped


@dataclass
class ParseResult:
    n_points: int
    dropped: int
    bounds: dict[str, list[float]]


def parse_to_npy(src: Source, filename: str, out: Path) -> ParseResult:
    """Parse ``src`` into an (N,3) float64 ``.npy`` at ``out``, atomically.

    The rows go to a temporary file beside ``out`` behind a reserved header;
    the header is written once N is known, the file is fsynced and renamed
    over ``out``.  On any error the temporary file is removed.
    """
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=out.parent, prefix=".tmp-", suffix=".npy")
    n = dropped = 0
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(b"\0" * NPY_HEADER_BYTES)
            for block, bad in _finite_blocks(src, filename):
                dropped += bad
                if len(block):
                    fh.write(block.tobytes())
                    n += len(block)
                    np.minimum(lo, block.min(axis=0), out=lo)
                    np.maximum(hi, block.max(axis=0), out=hi)
            fh.seek(0)
            fh.write(npy_header(n))
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, out)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return ParseResult(n, dropped, {"min": lo.tolist(), "max": hi.tolist()})


def npy_header(n: int) -> bytes:
    """A version-1.0 ``.npy`` header for an (n,3) little-endian float64 array,
    padded to exactly :data:`NPY_HEADER_BYTES` (the format allows any padding
    that keeps the data 64-byte aligned and ends the header with a newline)."""
    d = f"{{'descr': '<f8', 'fortran_order': False, 'shape': ({n}, 3), }}"
    body_len = NPY_HEADER_BYTES - 10
    if len(d) + 1 > body_len:
        raise CloudFormatError(f"{n} points do not fit an .npy header")
    text = d.ljust(body_len - 1) + "\n"
    return b"\x93NUMPY\x01\x00" + body_len.to_bytes(2, "little") + text.encode("latin-1")


# ------------------------------------------------------------------ readers
def _finite_blocks(src: Source, filename: str) -> Iterator[tuple[np.ndarray, int]]:
    """(finite rows, number dropped) per chunk; raises if nothing finite is left."""
    if src.size == 0:
        raise CloudFormatError("the uploaded file is empty")
    head = src.read_at(0, 8192)
    fmt = detect_format(head, filename)
    reader = {
        "ply": _read_ply,
        "pcd": _read_pcd,
        "npy": _read_npy,
        "las": read_las,
        "e57": read_e57,
    }.get(fmt, _read_text)
    kept = dropped = 0
    try:
        for raw in reader(src):
            pts = np.asarray(raw, dtype=np.float64).reshape(-1, 3)
            finite = np.isfinite(pts).all(axis=1)
            bad = int(len(pts) - finite.sum())
            block = pts if bad == 0 else pts[finite]
            kept += len(block)
            dropped += bad
            yield block, bad
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
    if ext in ("ply", "pcd", "npy", "las", "laz", "e57"):
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


def _read_text(src: Source) -> Iterator[np.ndarray]:
    first: int | None = None  # header lines before the first numeric row
    skipped = 0
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
            if at is None:
                skipped += len(lines)
                continue
            first = skipped + at
            text = "".join(lines[at:])
        try:
            arr = _loadtxt(text.translate(_SEPARATORS), usecols=(0, 1, 2), comments="#")
        except ValueError as exc:
            raise CloudFormatError(
                f"rows must hold at least 3 numbers (x y z), after {first} header line(s): {exc}"
            ) from None
        if arr is not None:
            yield arr
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

    ``{"ok": true, "n_points", "dropped", "bounds", "survey", "filename", "name"}`` or
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
        if units not in ("auto", "m", "mm"):
            return {
                "ok": False,
                "status": 422,
                "detail": f"units must be 'auto', 'm' or 'mm', got {units!r}",
            }
        filename = file.filename or ""
        src = FileSource(fd, file.start, file.end)
        try:
            res = parse_to_npy(src, filename, out)
            if res.n_points < MIN_CLOUD_POINTS:
                out.unlink(missing_ok=True)
                return {
                    "ok": False,
                    "status": 422,
                    "detail": f"{filename or 'upload'}: {res.n_points} point(s) with finite "
                    f"x, y, z; a cloud needs at least {MIN_CLOUD_POINTS} points, fewer than "
                    "any plan kind can use",
                }
            survey = survey_of_npy(out, detect_format(src.read_at(0, 8192), filename), units)
        except CloudFormatError as exc:
            refused = {"ok": False, "status": 400, "detail": f"{filename or 'upload'}: {exc}"}
            debug = getattr(exc.__cause__, "debug", "")
            if debug:
                refused["log"] = debug
            return refused
    finally:
        os.close(fd)
    return {
        "ok": True,
        "n_points": res.n_points,
        "dropped": res.dropped,
        "bounds": survey.pop("bounds"),
        "survey": survey,
        "filename": filename,
        "name": name,
    }


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
