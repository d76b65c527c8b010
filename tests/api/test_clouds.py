"""Cloud uploads: formats, samples, limits and refusals."""

from __future__ import annotations

import io

import numpy as np


def test_upload_xyz_with_nonfinite_rows(api) -> None:
    # ten finite rows: a cloud needs MIN_CLOUD_POINTS (10)
    data = b"# scan\n0 0 0\n1 0 0\nnan 1 1\n0 1 0.5\n" + b"0.5 0.5 0.25\n" * 7
    r = api.post("/api/v1/clouds", files={"file": ("scan.xyz", data)})
    assert r.status_code == 201, r.text
    body = r.json()
    assert body["n_points"] == 10 and body["dropped_nonfinite"] == 1
    assert body["bounds"] == {"min": [0.0, 0.0, 0.0], "max": [1.0, 1.0, 0.5]}
    got = api.get(f"/api/v1/clouds/{body['id']}", "viewer").json()
    assert got["name"] == "scan.xyz"
    raw = api.get(f"/api/v1/clouds/{body['id']}/points.npy", "viewer").content
    assert np.load(io.BytesIO(raw)).shape == (10, 3)


def test_upload_npy_and_list(api) -> None:
    buf = io.BytesIO()
    np.save(buf, np.random.default_rng(1).random((100, 4)))
    r = api.post("/api/v1/clouds", files={"file": ("a.npy", buf.getvalue())}, data={"name": "deck"})
    assert r.status_code == 201 and r.json()["name"] == "deck" and r.json()["n_points"] == 100
    assert [c["id"] for c in api.get("/api/v1/clouds", "viewer").json()] == [r.json()["id"]]


def test_samples(api) -> None:
    assert "demo_plane" in api.get("/api/v1/clouds/samples", "viewer").json()
    r = api.post("/api/v1/clouds", json={"sample": "demo_plane", "seed": 3})
    assert r.status_code == 201 and r.json()["n_points"] == 5000
    assert r.json()["source"] == "sample:demo_plane:3"
    r = api.post("/api/v1/clouds", json={"sample": "nope"})
    assert r.status_code == 422 and "available" in r.json()["detail"]
    r = api.post("/api/v1/clouds", json={"seed": 1})
    assert r.status_code == 422


def test_malformed_uploads_are_refused_with_reason(api) -> None:
    r = api.post("/api/v1/clouds", files={"file": ("bad.ply", b"ply\nformat ascii 1.0\n")})
    assert (
        r.status_code == 400
        and "bad.ply" in r.json()["detail"]
        and "end_header" in r.json()["detail"]
    )
    r = api.post("/api/v1/clouds", files={"file": ("empty.xyz", b"")})
    assert r.status_code == 400 and "empty" in r.json()["detail"]
    r = api.post("/api/v1/clouds", files={"other": ("x.xyz", b"1 2 3\n")})
    assert r.status_code == 422 and "'file'" in r.json()["detail"]
    r = api.post("/api/v1/clouds", content=b"1 2 3", headers={"Content-Type": "text/plain"})
    assert r.status_code == 415
    assert api.get("/api/v1/clouds").json() == []  # nothing half-stored


def test_oversize_upload_413(make_api) -> None:
    api = make_api(max_upload_mb=0.01)  # ~10 kB
    big = b"1 2 3\n" * 5000
    r = api.post("/api/v1/clouds", files={"file": ("big.xyz", big)})
    assert r.status_code == 413 and "upload limit" in r.json()["detail"]
    small = api.post("/api/v1/clouds", files={"file": ("ok.xyz", b"1 2 3\n" * 10)})
    assert small.status_code == 201


def test_unknown_cloud(api) -> None:
    assert api.get("/api/v1/clouds/cl_nope").status_code == 404
    assert api.delete("/api/v1/clouds/cl_nope").status_code == 404


def test_delete_cloud(api) -> None:
    cid = api.post("/api/v1/clouds", json={"sample": "demo_plane"}).json()["id"]
    assert api.delete(f"/api/v1/clouds/{cid}", "viewer").status_code == 403
    assert api.delete(f"/api/v1/clouds/{cid}").status_code == 204
    assert api.get(f"/api/v1/clouds/{cid}").status_code == 404


# ----------------------------------------------------------------
def _upload_files(api, name: str, data: bytes):
    return api.post("/api/v1/clouds", files={"file": (name, data)})


def _ply_header(n: int, fmt: str = "binary_little_endian") -> bytes:
    return (
        f"ply\nformat {fmt} 1.0\nelement vertex {n}\n"
        "property float x\nproperty float y\nproperty float z\nend_header\n"
    ).encode()


def test_self_contradicting_files_are_refused(api) -> None:
    """The fuzzer's finds: negative counts read the whole body, complex NPY lost its imaginary part."""
    r = _upload_files(api, "neg.ply", _ply_header(-1) + np.zeros((4, 3), "<f4").tobytes())
    assert r.status_code == 400 and "≥ 0" in r.json()["detail"], r.text
    pcd = (
        b"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 4\n"
        b"HEIGHT 1\nPOINTS -1\nDATA binary\n" + np.zeros((4, 3), "<f4").tobytes()
    )
    r = _upload_files(api, "neg.pcd", pcd)
    assert r.status_code == 400 and "POINTS" in r.json()["detail"], r.text
    buf = io.BytesIO()
    np.save(buf, np.ones((5, 3), np.complex128))
    r = _upload_files(api, "c.npy", buf.getvalue())
    assert r.status_code == 400 and "real numbers" in r.json()["detail"], r.text
    assert api.get("/api/v1/clouds").json() == []


def test_upload_leaves_no_spool_or_array_files(make_api, tmp_path) -> None:
    api = make_api(max_upload_mb=0.01)
    data_dir = api.services.store.data_dir
    assert _upload_files(api, "big.xyz", b"1 2 3\n" * 5000).status_code == 413
    assert _upload_files(api, "bad.ply", b"ply\nformat ascii 1.0\n").status_code == 400
    ok = _upload_files(api, "ok.xyz", b"1 2 3\n4 5 6\n" * 5)
    assert ok.status_code == 201
    files = sorted(p.relative_to(data_dir).as_posix() for p in data_dir.rglob("*") if p.is_file())
    arrays = [f for f in files if f.startswith(("arrays/", "uploads/"))]
    assert arrays == [f"arrays/clouds/{ok.json()['id']}.npy"]


def test_binary_ply_upload_round_trip(api) -> None:
    pts = np.random.default_rng(2).normal(size=(1000, 3)).astype("<f4")
    r = _upload_files(api, "b.ply", _ply_header(len(pts)) + pts.tobytes())
    assert r.status_code == 201, r.text
    assert r.json()["bounds"]["min"] == [float(v) for v in pts.min(axis=0)]
    raw = api.get(f"/api/v1/clouds/{r.json()['id']}/points.npy", "viewer").content
    np.testing.assert_array_equal(np.load(io.BytesIO(raw)), pts.astype(np.float64))


GATE_WRAPPER = """
import pathlib, sys, time
gate = pathlib.Path(sys.argv[1])
pathlib.Path(sys.argv[2]).touch()          # the parse has started
while not gate.exists():                   # ...and is held until the test opens the gate
    time.sleep(0.01)
from server.cloud_io import main
sys.exit(main(sys.argv[3:]))
"""


def test_health_is_served_while_an_upload_parses(api, tmp_path, monkeypatch) -> None:
    """Ordering, not timing: /health completes while the upload's parse is held open."""
    import sys
    import threading

    from server.routers import clouds

    gate, started = tmp_path / "gate", tmp_path / "started"
    script = tmp_path / "gated_parser.py"
    script.write_text(GATE_WRAPPER)
    monkeypatch.setattr(clouds, "PARSER", [sys.executable, str(script), str(gate), str(started)])
    result: dict = {}

    def upload() -> None:
        result["r"] = _upload_files(api, "held.xyz", b"0 0 0\n1 1 1\n" * 5)

    t = threading.Thread(target=upload)
    t.start()
    try:
        for _ in range(3000):  # up to 30 s for the child to start
            if started.exists():
                break
            t.join(0.01)
        assert started.exists(), "the parser child never started"
        for _ in range(3):
            h = api.get("/api/v1/health")
            assert h.status_code == 200 and h.json()["status"] == "ok"
        assert api.get("/api/v1/clouds", "viewer").json() == []
        assert t.is_alive() and "r" not in result  # the upload is still parsing
    finally:
        gate.touch()
        t.join(60)
    assert not t.is_alive()
    assert result["r"].status_code == 201 and result["r"].json()["n_points"] == 10
