"""Cloud uploads: formats, samples, limits and refusals."""

from __future__ import annotations

import io

import numpy as np


def test_upload_xyz_with_nonfinite_rows(api) -> None:
    data = b"# scan\n0 0 0\n1 0 0\nnan 1 1\n0 1 0.5\n"
    r = api.post("/api/v1/clouds", files={"file": ("scan.xyz", data)})
    assert r.status_code == 201, r.text
    body = r.json()
    assert body["n_points"] == 3 and body["dropped_nonfinite"] == 1
    assert body["bounds"] == {"min": [0.0, 0.0, 0.0], "max": [1.0, 1.0, 0.5]}
    got = api.get(f"/api/v1/clouds/{body['id']}", "viewer").json()
    assert got["name"] == "scan.xyz"
    raw = api.get(f"/api/v1/clouds/{body['id']}/points.npy", "viewer").content
    assert np.load(io.BytesIO(raw)).shape == (3, 3)


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
    small = api.post("/api/v1/clouds", files={"file": ("ok.xyz", b"1 2 3\n")})
    assert small.status_code == 201


def test_unknown_cloud(api) -> None:
    assert api.get("/api/v1/clouds/cl_nope").status_code == 404
    assert api.delete("/api/v1/clouds/cl_nope").status_code == 404


def test_delete_cloud(api) -> None:
    cid = api.post("/api/v1/clouds", json={"sample": "demo_plane"}).json()["id"]
    assert api.delete(f"/api/v1/clouds/{cid}", "viewer").status_code == 403
    assert api.delete(f"/api/v1/clouds/{cid}").status_code == 204
    assert api.get(f"/api/v1/clouds/{cid}").status_code == 404
