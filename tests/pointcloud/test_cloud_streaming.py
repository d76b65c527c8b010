"""The streaming cloud parser: chunk boundaries, the .npy sink, multipart ranges, memory.

Chunked readers are checked against the whole-buffer result with a tiny
chunk size (every record and line crosses a boundary somewhere); the upload
parser's peak memory is measured on ~60 MB files in its own child process
(``os.wait4`` rusage) against the bound of 2 × file size + 200 MB.
"""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from server import cloud_io
from server.cloud_io import BytesSource, CloudFormatError, multipart_parts, parse_to_npy, read_cloud

rng = np.random.default_rng(7)
PTS = rng.normal(size=(257, 3)).round(4)


def _files() -> dict[str, bytes]:
    out: dict[str, bytes] = {}
    out["a.xyz"] = ("# header\nx y z\n" + "".join(f"{a} {b} {c}\n" for a, b, c in PTS)).encode()
    out["b.csv"] = ("".join(f"{a},{b},{c},9\n" for a, b, c in PTS)).encode()
    head = (
        f"ply\nformat ascii 1.0\nelement vertex {len(PTS)}\nproperty float x\n"
        "property float y\nproperty float z\nelement face 1\n"
        "property list uchar int vertex_indices\nend_header\n"
    )
    out["c.ply"] = (head + "".join(f"{a} {b} {c}\n" for a, b, c in PTS) + "3 0 1 2\n").encode()
    bhead = head.replace("ascii", "binary_big_endian").replace("element face 1\n", "")
    bhead = bhead.replace("property list uchar int vertex_indices\n", "")
    out["d.ply"] = bhead.encode() + PTS.astype(">f4").tobytes()
    pcd = (
        "VERSION 0.7\nFIELDS x y z\nSIZE 8 8 8\nTYPE F F F\nCOUNT 1 1 1\n"
        f"WIDTH {len(PTS)}\nHEIGHT 1\nPOINTS {len(PTS)}\nDATA "
    )
    out["e.pcd"] = (pcd + "binary\n").encode() + PTS.astype("<f8").tobytes()
    out["f.pcd"] = (pcd + "ascii\n" + "".join(f"{a} {b} {c}\n" for a, b, c in PTS)).encode()
    for name, arr in (
        ("g.npy", np.hstack([PTS, np.ones((len(PTS), 2))]).astype("<f4")),
        ("h.npy", np.asfortranarray(PTS)),
        ("i.npy", PTS.astype(">i8")),
    ):
        buf = io.BytesIO()
        np.save(buf, arr)
        out[name] = buf.getvalue()
    return out


def _expected(name: str) -> np.ndarray:
    if name == "i.npy":
        return PTS.astype(np.int64).astype(np.float64)
    if name in ("d.ply", "g.npy"):
        return PTS.astype(np.float32).astype(np.float64)
    return PTS


@pytest.mark.parametrize("name", sorted(_files()))
def test_tiny_chunks_give_the_same_points(name: str, monkeypatch, tmp_path: Path) -> None:
    data = _files()[name]
    monkeypatch.setattr(cloud_io, "CHUNK_BYTES", 53)  # prime: boundaries land everywhere
    got, dropped = read_cloud(data, name)
    assert dropped == 0
    np.testing.assert_allclose(got, _expected(name), rtol=1e-6, err_msg=name)
    res = parse_to_npy(BytesSource(data), name, tmp_path / "out.npy")
    stored = np.load(tmp_path / "out.npy")
    np.testing.assert_array_equal(stored, got)
    assert res.n_points == len(PTS)
    assert res.bounds == {"min": got.min(axis=0).tolist(), "max": got.max(axis=0).tolist()}


def test_npy_sink_counts_dropped_rows_and_cleans_up_on_error(tmp_path: Path) -> None:
    res = parse_to_npy(BytesSource(b"1 2 3\nnan 1 1\n4 5 6\n"), "a.xyz", tmp_path / "a.npy")
    assert (res.n_points, res.dropped) == (2, 1)
    np.testing.assert_array_equal(np.load(tmp_path / "a.npy"), [[1, 2, 3], [4, 5, 6]])
    with pytest.raises(CloudFormatError, match="no points with finite"):
        parse_to_npy(BytesSource(b"nan nan nan\n"), "b.xyz", tmp_path / "b.npy")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.npy"]  # no .tmp-* left


@pytest.mark.parametrize(
    ("data", "msg"),
    [
        (b"ply\nformat ascii 1.0\nelement vertex -1\nproperty float x\nproperty float y\n"
         b"property float z\nend_header\n1 2 3\n", "≥ 0"),
        (b"ply\nformat ascii 1.0\nelement vertex many\nproperty float x\nend_header\n",
         "whole number"),
        (b"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nPOINTS -1\n"
         b"DATA ascii\n1 2 3\n", "POINTS must be"),
        (b"VERSION 0.7\nFIELDS x y z\nSIZE 4 4\nTYPE F F F\nCOUNT 1 1 1\nPOINTS 1\n"
         b"DATA binary\n", "one entry per field"),
    ],
)  # fmt: skip
def test_contradicting_headers_refused(data: bytes, msg: str) -> None:
    with pytest.raises(CloudFormatError, match=msg):
        read_cloud(data, "f")


@pytest.mark.parametrize(
    "arr",
    [
        np.ones((3, 3), np.complex64),
        np.zeros(3, dtype=[("x", "c8"), ("y", "f4"), ("z", "f4")]),
        np.zeros((3, 3), bool),
    ],
)
def test_npy_must_be_real(arr: np.ndarray) -> None:
    buf = io.BytesIO()
    np.save(buf, arr)
    with pytest.raises(CloudFormatError, match="real number"):
        read_cloud(buf.getvalue(), "a.npy")


def _multipart(boundary: str, parts: list[tuple[str, str | None, bytes]]) -> bytes:
    out = b""
    for name, filename, body in parts:
        disp = f'form-data; name="{name}"' + (f'; filename="{filename}"' if filename else "")
        out += f"--{boundary}\r\nContent-Disposition: {disp}\r\n\r\n".encode() + body + b"\r\n"
    return out + f"--{boundary}--\r\n".encode()


def test_multipart_ranges(monkeypatch) -> None:
    monkeypatch.setattr(cloud_io, "CHUNK_BYTES", 17)
    payload = b"0 0 0\r\n--notquite\r\n1 1 1\n"  # looks a little like a delimiter
    body = _multipart("XyZ", [("name", None, b"deck"), ("file", "a.xyz", payload)])
    parts = multipart_parts(BytesSource(body), b"XyZ")
    assert [(p.name, p.filename) for p in parts] == [("name", None), ("file", "a.xyz")]
    assert body[parts[0].start : parts[0].end] == b"deck"
    assert body[parts[1].start : parts[1].end] == payload


def _write_multipart(path: Path, name: str, write_body, units: str | None = None) -> str:
    boundary = "----steelpathtestboundary"
    with open(path, "wb") as fh:
        if units is not None:
            fh.write(
                f'--{boundary}\r\nContent-Disposition: form-data; name="units"\r\n\r\n'
                f"{units}\r\n".encode()
            )
        fh.write(
            f'--{boundary}\r\nContent-Disposition: form-data; name="file"; filename="{name}"\r\n'
            "Content-Type: application/octet-stream\r\n\r\n".encode()
        )
        write_body(fh)
        fh.write(f"\r\n--{boundary}--\r\n".encode())
    return f"multipart/form-data; boundary={boundary}"


def _parse_in_child(raw: Path, ctype: str, out: Path) -> tuple[dict, int]:
    """Run the upload parser as the server does; its outcome and peak RSS in bytes."""
    p = subprocess.Popen(
        [sys.executable, "-m", "server.cloud_io", "upload", str(raw), ctype, str(out),
         str(os.getpid())],
        stdout=subprocess.PIPE,
    )  # fmt: skip
    try:
        stdout = p.stdout.read() if p.stdout else b""
        _, status, usage = os.wait4(p.pid, 0)
        p.returncode = os.waitstatus_to_exitcode(status)
    finally:
        if p.returncode is None:
            p.kill()
            p.wait()
        if p.stdout:
            p.stdout.close()
    assert p.returncode == 0
    outcome = json.loads(stdout.decode().strip().splitlines()[-1])
    # The child's own VmHWM: wait4's ru_maxrss starts from the forking parent's
    # size (this test process can be a gigabyte late in a full run).
    assert 0 < outcome["peak_rss_kb"] <= usage.ru_maxrss
    return outcome, outcome["peak_rss_kb"] * 1024


BOUND_EXTRA = 200 * 2**20


def test_parser_memory_xyz_60mb(tmp_path: Path) -> None:
    block = "".join(f"{a:.5f} {b:.5f} {c:.5f}\n" for a, b, c in rng.normal(size=(50_000, 3)))
    block_b = block.encode()
    reps = (60 * 2**20) // len(block_b) + 1

    def body(fh) -> None:
        for _ in range(reps):
            fh.write(block_b)
        fh.write(b"nan 0 0\n")

    raw = tmp_path / "up.part"
    ctype = _write_multipart(raw, "big.xyz", body)
    size = raw.stat().st_size
    outcome, peak = _parse_in_child(raw, ctype, tmp_path / "out.npy")
    assert outcome["ok"], outcome
    assert (outcome["n_points"], outcome["dropped"]) == (50_000 * reps, 1)
    assert peak <= 2 * size + BOUND_EXTRA, f"peak {peak / 2**20:.0f} MB for {size / 2**20:.0f} MB"
    stored = np.load(tmp_path / "out.npy", mmap_mode="r")
    assert stored.shape == (50_000 * reps, 3)
    np.testing.assert_allclose(stored[-3:], np.loadtxt(io.StringIO(block)).reshape(-1, 3)[-3:])


@pytest.mark.parametrize("units", ["m", "auto"])
def test_parser_memory_binary_ply_60mb(tmp_path: Path, units: str) -> None:
    """60 MB of binary PLY parse within the memory bound, stated in metres or
    left to the detection: points 1.41 units apart over 4M units read as
    millimetres, and rescaling the stored array to metres (in place, chunked)
    stays within the same bound."""
    n = (60 * 2**20) // 16
    dt = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("i", "<u4")])
    chunk = np.zeros(1 << 20, dt)

    def body(fh) -> None:
        fh.write(
            f"ply\nformat binary_little_endian 1.0\nelement vertex {n}\nproperty float x\n"
            "property float y\nproperty float z\nproperty uint i\nend_header\n".encode()
        )
        for start in range(0, n, len(chunk)):
            k = min(len(chunk), n - start)
            idx = np.arange(start, start + k, dtype=np.float32)
            chunk["x"][:k], chunk["y"][:k], chunk["z"][:k] = idx, -idx, 1.5
            fh.write(chunk[:k].tobytes())

    raw = tmp_path / "up.part"
    ctype = _write_multipart(raw, "big.ply", body, units)
    size = raw.stat().st_size
    outcome, peak = _parse_in_child(raw, ctype, tmp_path / "out.npy")
    assert outcome["ok"] and outcome["n_points"] == n, outcome
    assert peak <= 2 * size + BOUND_EXTRA, f"peak {peak / 2**20:.0f} MB for {size / 2**20:.0f} MB"
    scale = 1.0 if units == "m" else 0.001
    assert outcome["survey"]["units"] == ("m" if units == "m" else "mm")
    want = np.array([[0, 0, 1.5], [n - 1, -(n - 1), 1.5]]) * scale
    np.testing.assert_allclose(outcome["bounds"]["min"], [0.0, want[1, 1], want[0, 2]], rtol=1e-15)
    np.testing.assert_allclose(outcome["bounds"]["max"], [want[1, 0], 0.0, want[0, 2]], rtol=1e-15)
    stored = np.load(tmp_path / "out.npy", mmap_mode="r")
    np.testing.assert_allclose(stored[[0, n - 1]], want, rtol=1e-15)
