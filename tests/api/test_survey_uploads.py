"""Survey formats on upload: LAS, LAZ and E57 read in chunks,
millimetres detected from the measured spacing and stored as metres, an
override, and the survey record in the response."""

from __future__ import annotations

import io
from pathlib import Path

import laspy
import numpy as np
import pye57
import pytest
from scipy.spatial import cKDTree

from planners.pointcloud.spacing import measure_spacing
from server import survey_io


def _beam(n: int = 20000, seed: int = 0) -> np.ndarray:
    """A 6 m flange-like strip far from the origin (survey frame), metres."""
    rng = np.random.default_rng(seed)
    return np.array([512_300.0, 5_401_200.0, 35.0]) + rng.uniform(
        [0, 0, 0], [6.0, 0.3, 0.01], (n, 3)
    )


def _las_bytes(points: np.ndarray, scale: float, compressed: bool) -> bytes:
    header = laspy.LasHeader(point_format=3, version="1.4")
    header.scales = np.array([scale] * 3)
    header.offsets = np.floor(points.min(axis=0))
    las = laspy.LasData(header)
    las.x, las.y, las.z = points[:, 0], points[:, 1], points[:, 2]
    buf = io.BytesIO()
    las.write(buf, do_compress=compressed)
    return buf.getvalue()


def _e57_bytes(tmp_path: Path, scans: list[tuple[np.ndarray, np.ndarray]]) -> bytes:
    """Scans given in their station frame with a translation each."""
    path = tmp_path / "scan.e57"
    e = pye57.E57(str(path), mode="w")
    for pts, t in scans:
        e.write_scan_raw(
            {"cartesianX": pts[:, 0], "cartesianY": pts[:, 1], "cartesianZ": pts[:, 2]},
            translation=t,
            rotation=np.array([1.0, 0.0, 0.0, 0.0]),
        )
    e.close()
    return path.read_bytes()


@pytest.mark.parametrize("compressed", [False, True])
def test_las_and_laz_in_metres(api, compressed: bool) -> None:
    pts = _beam()
    name = "span.laz" if compressed else "span.las"
    r = api.post("/api/v1/clouds", files={"file": (name, _las_bytes(pts, 0.0005, compressed))})
    assert r.status_code == 201, r.text
    body = r.json()
    assert body["n_points"] == len(pts)
    s = body["survey"]
    assert s["format"] == "las" and s["units"] == "m" and s["scale_to_m"] == 1.0
    raw = api.get(f"/api/v1/clouds/{body['id']}/points.npy", "viewer").content
    np.testing.assert_allclose(np.load(io.BytesIO(raw)), pts, atol=2.6e-4)  # LAS quantum / 2
    assert 0.003 < s["spacing_m"] < 0.03


def test_las_in_millimetres_is_detected_and_stored_in_metres(api) -> None:
    pts = _beam()
    mm = pts * 1000.0
    r = api.post("/api/v1/clouds", files={"file": ("span_mm.las", _las_bytes(mm, 0.1, False))})
    assert r.status_code == 201, r.text
    body = r.json()
    s = body["survey"]
    assert s["units"] == "mm" and s["scale_to_m"] == 0.001 and "millimetres" in s["units_reason"]
    raw = api.get(f"/api/v1/clouds/{body['id']}/points.npy", "viewer").content
    np.testing.assert_allclose(np.load(io.BytesIO(raw)), pts, atol=1e-4)
    np.testing.assert_allclose(body["bounds"]["min"], pts.min(axis=0), atol=1e-4)
    assert 0.003 < s["spacing_m"] < 0.03
    # the uploader can say otherwise
    r = api.post(
        "/api/v1/clouds",
        files={"file": ("span_mm.las", _las_bytes(mm, 0.1, False))},
        data={"units": "m"},
    )
    assert r.status_code == 201 and r.json()["survey"]["units"] == "m"
    assert "uploader" in r.json()["survey"]["units_reason"]
    r = api.post(
        "/api/v1/clouds",
        files={"file": ("span_mm.las", _las_bytes(mm, 0.1, False))},
        data={"units": "feet"},
    )
    assert r.status_code == 422 and "units" in r.json()["detail"]


def test_e57_with_two_stations_lands_in_one_frame(api, tmp_path: Path) -> None:
    pts = _beam() - np.array([512_300.0, 5_401_200.0, 0.0])  # E57 floats: a local frame
    a, b = pts[:10000], pts[10000:]
    t = np.array([3.0, -2.0, 0.5])
    data = _e57_bytes(tmp_path, [(a, np.zeros(3)), (b - t, t)])
    r = api.post("/api/v1/clouds", files={"file": ("bridge.e57", data)})
    assert r.status_code == 201, r.text
    body = r.json()
    assert body["n_points"] == len(pts) and body["survey"]["format"] == "e57"
    raw = np.load(io.BytesIO(api.get(f"/api/v1/clouds/{body['id']}/points.npy", "viewer").content))
    np.testing.assert_allclose(raw, pts, atol=1e-5)


def test_a_truncated_las_is_a_clear_400(api) -> None:
    data = _las_bytes(_beam(2000), 0.001, False)[:5000]
    r = api.post("/api/v1/clouds", files={"file": ("cut.las", data)})
    assert r.status_code == 400 and "cut.las" in r.json()["detail"]


def test_samples_carry_their_measured_spacing(api) -> None:
    r = api.post("/api/v1/clouds", json={"sample": "demo_plane"})
    s = r.json()["survey"]
    assert s["format"] == "sample" and s["units"] == "m" and s["spacing_m"] > 0


def test_measured_spacing_equals_the_brute_force_median_in_any_chunking() -> None:
    rng = np.random.default_rng(3)
    pts = rng.uniform(0, 1, (3000, 3))
    pts = np.vstack([pts, pts[:50]])  # exact duplicates do not count as neighbours
    d, _ = cKDTree(pts).query(pts, k=3)
    nearest = np.where(d[:, 1] > 0, d[:, 1], d[:, 2])
    for chunk in (7, 500, 10_000):
        got = measure_spacing(pts, n_queries=len(pts), chunk=chunk)
        assert got == pytest.approx(float(np.median(nearest)), rel=1e-12)


def test_units_decision() -> None:
    assert survey_io.decide_units(0.01, 40.0, 10_000)[0] == "m"
    assert survey_io.decide_units(10.0, 40_000.0, 10_000)[0] == "mm"
    assert survey_io.decide_units(2.0, 40.0, 10_000)[0] == "m"  # sparse but small: metres
    assert survey_io.decide_units(5.0, 5000.0, 20)[0] == "m"  # too few to tell
    assert survey_io.decide_units(0.01, 40.0, 10_000, "mm")[0] == "mm"
    with pytest.raises(ValueError, match="units"):
        survey_io.decide_units(0.01, 40.0, 10_000, "inch")
