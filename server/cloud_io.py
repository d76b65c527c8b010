"""Reading uploaded point clouds: PLY, PCD (ascii/binary), XYZ/CSV, NPY.

Every reader returns an (N,3) float64 array of x, y, z; rows with a
non-finite coordinate are dropped and counted; empty or unparseable input
raises :class:`CloudFormatError` with a message saying what was wrong.
"""

from __future__ import annotations

import io
import re

import numpy as np

FORMATS = ("ply", "pcd", "xyz", "csv", "txt", "npy")


class CloudFormatError(ValueError):
    """The upload is not a readable point cloud."""


_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}  # fmt: skip


def read_cloud(data: bytes, filename: str = "") -> tuple[np.ndarray, int]:
    """Parse ``data``; returns ``(points (N,3) float64, dropped_nonfinite)``."""
    if not data:
        raise CloudFormatError("the uploaded file is empty")
    fmt = detect_format(data, filename)
    reader = {"ply": _read_ply, "pcd": _read_pcd, "npy": _read_npy}.get(fmt, _read_text)
    try:
        pts = reader(data)
    except CloudFormatError:
        raise
    except Exception as exc:  # any parser failure becomes a readable 400
        raise CloudFormatError(f"could not parse {fmt.upper()} data: {exc}") from exc
    pts = np.asarray(pts, dtype=np.float64).reshape(-1, 3)
    finite = np.isfinite(pts).all(axis=1)
    dropped = int((~finite).sum())
    pts = pts[finite]
    if len(pts) == 0:
        raise CloudFormatError(
            f"the {fmt.upper()} file holds no points with finite x, y, z"
            + (f" ({dropped} non-finite rows dropped)" if dropped else "")
        )
    return np.ascontiguousarray(pts), dropped


def detect_format(data: bytes, filename: str) -> str:
    ext = filename.rsplit(".", 1)[-1].lower() if "." in filename else ""
    if data.startswith(b"ply"):
        return "ply"
    if data.startswith(b"\x93NUMPY"):
        return "npy"
    head = data[:2048].decode("latin-1")
    if re.search(r"^\s*(VERSION|FIELDS)\s", head, re.M) and "DATA" in data[:8192].decode("latin-1"):
        return "pcd"
    if ext in ("ply", "pcd", "npy"):
        raise CloudFormatError(f"file {filename!r} does not start like a {ext.upper()} file")
    return "xyz"


def _read_ply(data: bytes) -> np.ndarray:
    end = data.find(b"end_header")
    if end < 0:
        raise CloudFormatError("PLY header has no 'end_header' line")
    nl = data.find(b"\n", end)
    header = data[:end].decode("ascii", "replace").splitlines()
    body = data[nl + 1 :]
    fmt = None
    elements: list[tuple[str, int, list[tuple[str, str]]]] = []
    for line in header:
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "format":
            fmt = parts[1]
        elif parts[0] == "element":
            elements.append((parts[1], int(parts[2]), []))
        elif parts[0] == "property":
            if not elements:
                raise CloudFormatError("PLY property before any element")
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
    if fmt == "ascii":
        rows = body.decode("ascii", "replace").split("\n")[:n]
        if len(rows) < n:
            raise CloudFormatError(f"PLY header promises {n} vertices, file has {len(rows)}")
        arr = np.loadtxt(io.StringIO("\n".join(rows)), ndmin=2)
        if arr.shape[1] < len(names):
            raise CloudFormatError("PLY vertex rows have fewer values than properties")
        return arr[:, [names.index(c) for c in "xyz"]]
    endian = "<" if fmt == "binary_little_endian" else ">"
    dtype = np.dtype([(nm, endian + t) for nm, t in props])
    if len(body) < n * dtype.itemsize:
        raise CloudFormatError(
            f"PLY body too short: {n} vertices need {n * dtype.itemsize} bytes, got {len(body)}"
        )
    rec = np.frombuffer(body, dtype=dtype, count=n)
    return np.stack([rec[c].astype(np.float64) for c in "xyz"], axis=1)


def _read_pcd(data: bytes) -> np.ndarray:
    header: dict[str, list[str]] = {}
    pos = 0
    while True:
        nl = data.find(b"\n", pos)
        if nl < 0:
            raise CloudFormatError("PCD header has no DATA line")
        line = data[pos:nl].decode("ascii", "replace").strip()
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
    sizes = [int(s) for s in header.get("SIZE", ["4"] * nf)]
    types = header.get("TYPE", ["F"] * nf)
    counts = [int(c) for c in header.get("COUNT", ["1"] * nf)]
    n = int(header.get("POINTS", header.get("WIDTH", ["0"]))[0])
    mode = header["DATA"][0].lower()
    if mode == "ascii":
        arr = np.loadtxt(io.StringIO(data[pos:].decode("ascii", "replace")), ndmin=2)
        cols, c = [], 0
        for f, cnt in zip(fields, counts, strict=True):
            if f in "xyz" and len(f) == 1:
                cols.append((f, c))
            c += cnt
        idx = dict(cols)
        return arr[:, [idx["x"], idx["y"], idx["z"]]]
    if mode == "binary":
        kinds = {"F": "f", "I": "i", "U": "u"}
        dt = []
        for f, s, t, cnt in zip(fields, sizes, types, counts, strict=True):
            name = f if f != "_" else f"_pad{len(dt)}"
            code = f"<{kinds[t.upper()]}{s}"
            dt.append((name, code, (cnt,)) if cnt > 1 else (name, code))
        dtype = np.dtype(dt)
        body = data[pos:]
        if len(body) < n * dtype.itemsize:
            raise CloudFormatError(
                f"PCD body too short: {n} points need {n * dtype.itemsize} bytes, got {len(body)}"
            )
        rec = np.frombuffer(body, dtype=dtype, count=n)
        return np.stack([rec[c].astype(np.float64) for c in "xyz"], axis=1)
    raise CloudFormatError(
        f"PCD DATA {mode!r} is not supported (use ascii or binary; "
        "binary_compressed can be converted with pcl_convert_pcd_ascii_binary)"
    )


def _read_npy(data: bytes) -> np.ndarray:
    arr = np.load(io.BytesIO(data), allow_pickle=False)
    if arr.dtype.names:
        missing = [c for c in "xyz" if c not in arr.dtype.names]
        if missing:
            raise CloudFormatError(f"structured NPY array lacks fields {missing}")
        return np.stack([arr[c].astype(np.float64).ravel() for c in "xyz"], axis=1)
    if arr.ndim != 2 or arr.shape[1] < 3:
        raise CloudFormatError(f"NPY array must have shape (N, 3) or (N, >3); got {arr.shape}")
    if not np.issubdtype(arr.dtype, np.number):
        raise CloudFormatError(f"NPY array must be numeric; got dtype {arr.dtype}")
    return arr[:, :3].astype(np.float64)


_NUM = re.compile(r"^[\s,;]*[-+]?(\d|\.\d|nan|inf)", re.I)


def _read_text(data: bytes) -> np.ndarray:
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise CloudFormatError(
            "not a recognised point-cloud file: it is binary but neither PLY, PCD nor NPY"
        ) from None
    lines = text.splitlines()
    # Skip comments and header lines (column names) before the first numeric row.
    first = next((i for i, ln in enumerate(lines) if _NUM.match(ln)), None)
    if first is None:
        raise CloudFormatError("no numeric rows found: expected lines of 'x y z' or 'x,y,z'")
    body = re.sub(r"[,;]", " ", "\n".join(lines[first:]))
    try:
        arr = np.loadtxt(io.StringIO(body), usecols=(0, 1, 2), ndmin=2, comments="#")
    except ValueError as exc:
        raise CloudFormatError(
            f"rows must hold at least 3 numbers (x y z), after {first} header line(s): {exc}"
        ) from None
    return arr
