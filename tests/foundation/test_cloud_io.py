"""Point-cloud readers against files written independently here."""

from __future__ import annotations

import io

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from server.cloud_io import CloudFormatError, read_cloud

finite = st.floats(-1e4, 1e4, allow_nan=False, width=32)
clouds = arrays(np.float32, st.tuples(st.integers(1, 40), st.just(3)), elements=finite)


def ply_ascii(p: np.ndarray, extra: bool = False) -> bytes:
    head = ["ply", "format ascii 1.0", f"element vertex {len(p)}",
            "property float x", "property float y", "property float z"]  # fmt: skip
    if extra:
        head.append("property uchar red")
    head += ["element face 0", "property list uchar int vertex_indices", "end_header"]
    rows = [" ".join(repr(float(v)) for v in r) + (" 7" if extra else "") for r in p]
    return ("\n".join(head + rows) + "\n").encode()


def ply_binary(p: np.ndarray, endian: str) -> bytes:
    fmt = "binary_little_endian" if endian == "<" else "binary_big_endian"
    dt = np.dtype(
        [
            ("intensity", endian + "u2"),
            ("x", endian + "f8"),
            ("y", endian + "f8"),
            ("z", endian + "f8"),
        ]
    )
    rec = np.zeros(len(p), dtype=dt)
    rec["x"], rec["y"], rec["z"] = p[:, 0], p[:, 1], p[:, 2]
    head = (
        f"ply\nformat {fmt} 1.0\nelement vertex {len(p)}\nproperty ushort intensity\n"
        "property double x\nproperty double y\nproperty double z\nend_header\n"
    )
    return head.encode() + rec.tobytes()


def pcd(p: np.ndarray, mode: str) -> bytes:
    head = (
        "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z rgb\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\n"
        f"WIDTH {len(p)}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(p)}\nDATA {mode}\n"
    )
    if mode == "ascii":
        body = "".join(f"{float(a)!r} {float(b)!r} {float(c)!r} 0\n" for a, b, c in p).encode()
    else:
        rec = np.zeros((len(p), 4), "<f4")
        rec[:, :3] = p
        body = rec.tobytes()
    return head.encode() + body


@settings(max_examples=40, deadline=None)
@given(clouds)
def test_round_trips(p: np.ndarray) -> None:
    expect = p.astype(np.float64)
    cases = {
        "a.ply": ply_ascii(p, extra=True),
        "b.ply": ply_binary(p, "<"),
        "c.ply": ply_binary(p, ">"),
        "d.pcd": pcd(p, "ascii"),
        "e.pcd": pcd(p, "binary"),
        "f.csv": (
            "x,y,z\n" + "".join(f"{a!r},{b!r},{c!r}\n" for a, b, c in expect.tolist())
        ).encode(),
        "g.xyz": "".join(f"{a!r} {b!r} {c!r} 1 2\n" for a, b, c in expect.tolist()).encode(),
    }
    buf = io.BytesIO()
    np.save(buf, expect)
    cases["h.npy"] = buf.getvalue()
    for name, data in cases.items():
        got, dropped = read_cloud(data, name)
        assert dropped == 0, name
        np.testing.assert_allclose(got, expect, rtol=1e-6, atol=1e-6, err_msg=name)


def test_nonfinite_rows_dropped_and_counted() -> None:
    got, dropped = read_cloud(b"1 2 3\nnan 0 0\n4 inf 6\n7 8 9\n", "p.xyz")
    assert dropped == 2
    np.testing.assert_array_equal(got, [[1, 2, 3], [7, 8, 9]])


def test_structured_npy() -> None:
    rec = np.zeros(3, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("i", "u1")])
    rec["z"] = [1, 2, 3]
    buf = io.BytesIO()
    np.save(buf, rec)
    got, _ = read_cloud(buf.getvalue(), "s.npy")
    np.testing.assert_array_equal(got[:, 2], [1, 2, 3])


@pytest.mark.parametrize(
    ("data", "name", "msg"),
    [
        (b"", "a.ply", "empty"),
        (b"hello world\nno numbers here\n", "a.txt", "no numeric rows"),
        (b"1 2\n3 4\n", "a.xyz", "at least 3 numbers"),
        (b"nan nan nan\n", "a.xyz", "no points with finite"),
        (
            b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1\n2\n3\n",
            "a.ply",
            "lacks properties",
        ),
        (
            b"ply\nformat binary_little_endian 1.0\nelement vertex 100\nproperty float x\nproperty float y\nproperty float z\nend_header\n\x00\x00",
            "a.ply",
            "too short",
        ),
        (b"ply\nelement vertex 1\n", "a.ply", "end_header"),
        (
            b"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nPOINTS 1\nDATA binary_compressed\n\x00",
            "a.pcd",
            "not supported",
        ),
        (b"\x00\x01\x02\xff\xfe", "a.bin", "binary"),
        (b"not a ply", "a.ply", "does not start like"),
    ],
)
def test_bad_files_are_refused_with_a_reason(data: bytes, name: str, msg: str) -> None:
    with pytest.raises(CloudFormatError, match=msg):
        read_cloud(data, name)


@settings(max_examples=100, deadline=None)
@given(st.binary(max_size=300), st.sampled_from(["a.ply", "a.pcd", "a.xyz", "a.npy", "a"]))
def test_garbage_never_crashes(data: bytes, name: str) -> None:
    try:
        pts, dropped = read_cloud(data, name)
    except CloudFormatError:
        return
    assert pts.ndim == 2 and pts.shape[1] == 3 and np.isfinite(pts).all() and dropped >= 0
