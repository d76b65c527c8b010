"""Scans as crews bring them (§2, §3): the CRS and its units, errors for
people, and per-point attributes (intensity, RGB, classification) through
upload, storage, the API and the scene.  Every file is written here by
laspy or pye57 (no mocks); expected metres are computed independently from
the unit definitions (international foot 0.3048 m, US survey foot 1200/3937 m)."""

from __future__ import annotations

import io
import socket
from pathlib import Path
from typing import Any

import laspy
import numpy as np
import pye57
import pyproj
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pye57 import libe57

from server.cloud_io import BytesSource, CloudFormatError, parse_to_npy, read_cloud
from server.scene import cloud_colours
from server.store.cleanup import referenced_arrays
from server.survey_io import survey_of_npy

FT = 0.3048
US_FT = 1200.0 / 3937.0
#: An international-feet projected CRS: NAD83 / Arizona East (ft).
INTL_FT_EPSG = 2222
#: NY State Plane, Long Island, US survey feet.
NY_FTUS_EPSG = 2263


def _strip(
    n: int = 20000, seed: int = 0, origin: tuple[float, ...] = (1_050_000.0, 190_000.0, 30.0)
) -> np.ndarray:
    """A 20 ft flange-like strip at State Plane magnitudes (~1e6 ft), feet."""
    rng = np.random.default_rng(seed)
    return np.array(origin) + rng.uniform([0, 0, 0], [20.0, 1.0, 0.03], (n, 3))


def _las(
    pts: np.ndarray,
    *,
    crs: Any = None,
    wkt: bool = True,
    scale: float = 0.001,
    point_format: int = 3,
    version: str = "1.4",
    compressed: bool = False,
    attrs: dict[str, np.ndarray] | None = None,
) -> bytes:
    header = laspy.LasHeader(point_format=point_format, version=version)
    header.scales = np.array([scale] * 3)
    header.offsets = np.floor(pts.min(axis=0))
    if crs is not None:
        header.add_crs(crs, keep_compatibility=not wkt)
    las = laspy.LasData(header)
    las.x, las.y, las.z = pts[:, 0], pts[:, 1], pts[:, 2]
    for name, values in (attrs or {}).items():
        setattr(las, name, values)
    buf = io.BytesIO()
    las.write(buf, do_compress=compressed)
    return buf.getvalue()


def _quantised(data: bytes) -> np.ndarray:
    """The coordinates the LAS file holds (after its scale and offset), in its unit."""
    las = laspy.read(io.BytesIO(data))
    return np.column_stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)])


def _points(api: Any, cid: str) -> np.ndarray:
    return np.load(io.BytesIO(api.get(f"/api/v1/clouds/{cid}/points.npy", "viewer").content))


def _attr(api: Any, cid: str, name: str) -> np.ndarray:
    r = api.get(f"/api/v1/clouds/{cid}/attributes/{name}", "viewer")
    assert r.status_code == 200, r.text
    return np.load(io.BytesIO(r.content))


# ------------------------------------------------------------------ CRS and units
@pytest.mark.parametrize(
    "epsg, wkt, metres_per_unit, unit, said",
    [
        (NY_FTUS_EPSG, False, US_FT, "us-ft", "US survey feet"),  # GeoTIFF keys (LAS 1.2)
        (INTL_FT_EPSG, True, FT, "ft", "international feet"),  # WKT VLR (LAS 1.4)
    ],
)
def test_a_feet_crs_is_applied_and_the_survey_says_why(
    api, epsg: int, wkt: bool, metres_per_unit: float, unit: str, said: str
) -> None:
    pts = _strip()
    version, fmt = ("1.4", 7) if wkt else ("1.2", 3)
    data = _las(pts, crs=pyproj.CRS.from_epsg(epsg), wkt=wkt, version=version, point_format=fmt)
    r = api.post("/api/v1/clouds", files={"file": ("span.las", data)})
    assert r.status_code == 201, r.text
    body = r.json()
    s = body["survey"]
    assert s["units"] == unit and s["units_from"] == "from the CRS"
    assert s["scale_to_m"] == pytest.approx(metres_per_unit, rel=1e-12)
    assert s["crs"]["epsg"] == epsg and str(epsg) in s["units_reason"] and said in s["units_reason"]
    assert "scale_to_m_z" not in s  # no vertical axis: z in the same unit
    expected = _quantised(data) * metres_per_unit  # independent of the server's arithmetic
    got = _points(api, body["id"])
    assert np.abs(got - expected).max() < 1e-3  # metres, at ~3e5 m from the origin
    np.testing.assert_allclose(got, expected, rtol=1e-12)
    np.testing.assert_allclose(body["bounds"]["min"], expected.min(axis=0), rtol=1e-12)
    assert 0.003 < s["spacing_m"] < 0.03  # a ~0.03 ft spacing, in metres
    # The CRS in full is kept with the cloud (for exports).
    rec = api.get(f"/api/v1/clouds/{body['id']}", "viewer").json()
    assert pyproj.CRS.from_wkt(rec["crs_wkt"]).to_epsg() == epsg
    # The request wins, and says the CRS disagreed.
    r = api.post("/api/v1/clouds", files={"file": ("span.las", data)}, data={"units": "m"})
    s = r.json()["survey"]
    assert s["units"] == "m" and s["units_from"] == "set by the request"
    assert said in s["units_reason"] or "foot" in s["units_reason"]
    np.testing.assert_allclose(_points(api, r.json()["id"]), _quantised(data), rtol=1e-12)


def test_a_compound_crs_scales_z_by_its_vertical_unit(tmp_path: Path) -> None:
    # NY Long Island (ftUS) + NAVD88 height (metres): x, y in US survey feet, z in metres.
    pts = _strip(3000)
    data = _las(pts, crs=pyproj.CRS("EPSG:2263+5703"), wkt=True, point_format=6)
    meta: dict[str, Any] = {}
    parse_to_npy(BytesSource(data), "a.las", tmp_path / "c.npy", meta)
    s = survey_of_npy(tmp_path / "c.npy", "las", "auto", meta)
    assert s["scale_to_m"] == pytest.approx(US_FT) and s["scale_to_m_z"] == 1.0
    expected = _quantised(data) * np.array([US_FT, US_FT, 1.0])
    np.testing.assert_allclose(np.load(tmp_path / "c.npy"), expected, rtol=1e-12)
    assert "z in metres" in s["units_reason"]


@pytest.mark.parametrize("units, factor", [("ft", FT), ("us-ft", US_FT), ("mm", 0.001)])
def test_units_set_by_the_request_without_a_crs(api, units: str, factor: float) -> None:
    pts = _strip(3000)
    data = _las(pts)
    r = api.post("/api/v1/clouds", files={"file": ("span.las", data)}, data={"units": units})
    assert r.status_code == 201, r.text
    s = r.json()["survey"]
    assert s["units"] == units and s["units_from"] == "set by the request" and s["crs"] is None
    np.testing.assert_allclose(_points(api, r.json()["id"]), _quantised(data) * factor, rtol=1e-12)
    r = api.post("/api/v1/clouds", files={"file": ("span.las", data)}, data={"units": "yards"})
    assert r.status_code == 422 and "us-ft" in r.json()["detail"]


def test_without_a_crs_the_units_are_detected(api) -> None:
    r = api.post("/api/v1/clouds", files={"file": ("span.las", _las(_strip(3000) - 1e6))})
    s = r.json()["survey"]
    assert s["units"] == "m" and s["units_from"] == "detected" and s["crs"] is None
    assert r.json()["crs_wkt"] is None


def test_a_geographic_crs_is_refused_with_the_reason(api) -> None:
    rng = np.random.default_rng(1)
    lonlat = np.array([-73.9, 40.7, 10.0]) + rng.uniform(0, 1e-4, (500, 3))
    data = _las(lonlat, crs=pyproj.CRS.from_epsg(4326), scale=1e-7, point_format=6)
    r = api.post("/api/v1/clouds", files={"file": ("geo.las", data)})
    assert r.status_code == 422 and "degrees" in r.json()["detail"], r.text
    assert api.get("/api/v1/clouds", "viewer").json() == []


def test_an_unreadable_crs_record_is_ignored_with_a_note(api) -> None:
    pts = _strip(2000) - 1e6
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.scales, header.offsets = np.array([0.001] * 3), np.floor(pts.min(axis=0))
    header.vlrs.append(laspy.vlrs.known.WktCoordinateSystemVlr('PROJCS["broken'))
    header.global_encoding.wkt = True
    las = laspy.LasData(header)
    las.x, las.y, las.z = pts.T
    buf = io.BytesIO()
    las.write(buf)
    r = api.post("/api/v1/clouds", files={"file": ("odd.las", buf.getvalue())})
    assert r.status_code == 201, r.text
    s = r.json()["survey"]
    assert s["crs"] is None and "could not be read" in s["crs_note"] and s["units"] == "m"
    assert "proj_create" not in str(s) and "Internal Proj" not in str(s)


@settings(
    max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    east=st.floats(1e5, 4e6),
    north=st.floats(1e4, 2e6),
    up=st.floats(-100.0, 3000.0),
    size=st.floats(1.0, 300.0),
    epsg=st.sampled_from([NY_FTUS_EPSG, INTL_FT_EPSG, 32618]),
    seed=st.integers(0, 2**16),
)
def test_stored_metres_are_right_to_a_millimetre_anywhere(
    tmp_path: Path, east: float, north: float, up: float, size: float, epsg: int, seed: int
) -> None:
    rng = np.random.default_rng(seed)
    pts = np.array([east, north, up]) + rng.uniform(0, size, (400, 3))
    crs = pyproj.CRS.from_epsg(epsg)
    data = _las(pts, crs=crs, wkt=True, point_format=6, scale=0.001)
    meta: dict[str, Any] = {}
    out = tmp_path / f"c{seed}.npy"
    parse_to_npy(BytesSource(data), "a.las", out, meta)
    s = survey_of_npy(out, "las", "auto", meta)
    factor = {NY_FTUS_EPSG: 1200.0 / 3937.0, INTL_FT_EPSG: 0.3048, 32618: 1.0}[epsg]
    expected = _quantised(data) * factor
    got = np.load(out)
    assert np.abs(got - expected).max() < 1e-3  # a millimetre, wherever the cloud is
    np.testing.assert_allclose(got, expected, rtol=1e-12)
    # and the file's numbers (not just what laspy reads back) are the points, to a quantum
    assert np.abs(got / factor - pts).max() <= 0.0005 + 1e-9 * np.abs(pts).max()
    assert s["scale_to_m"] == pytest.approx(factor, rel=1e-15)


# ------------------------------------------------------------------ errors for people
def _no_leaks(message: str) -> None:
    for leak in ("/", "\\", "Traceback", "lazrs", "IoError", "struct", "buffer size", "Debug"):
        assert leak not in message, message


@pytest.mark.parametrize(
    "name, cut, expect",
    [
        ("cut.las", lambda d: d[:5000], "not a readable LAS file: the file is truncated"),
        ("cut.las", lambda d: d[:100], "the file is truncated"),
        ("bad.las", lambda d: b"XXXX" + d[4:], "not a LAS file: bad signature"),
        ("bad.las", lambda d: d[:24] + bytes([9, 9]) + d[26:], "version 9.9"),
    ],
)
def test_damaged_las_files_say_what_is_wrong(name: str, cut: Any, expect: str) -> None:
    data = cut(_las(_strip(2000)))
    with pytest.raises(CloudFormatError) as exc:
        read_cloud(data, name)
    assert expect in str(exc.value)
    _no_leaks(str(exc.value))


def test_a_damaged_laz_says_so(api) -> None:
    data = _las(_strip(20000), compressed=True)
    r = api.post("/api/v1/clouds", files={"file": ("scan.laz", data[: len(data) // 2])})
    assert r.status_code == 400
    detail = r.json()["detail"]
    assert detail.startswith("scan.laz: not a readable LAZ file: ") and "damaged" in detail
    _no_leaks(detail.removeprefix("scan.laz: "))


def test_a_truncated_e57_says_it_is_truncated(tmp_path: Path) -> None:
    data = _e57(tmp_path, [np.random.default_rng(0).uniform(0, 5, (3000, 3))])
    with pytest.raises(CloudFormatError) as exc:
        read_cloud(data[: len(data) // 2], "bridge.e57")
    assert str(exc.value) == (
        "not a readable E57 file: the file is truncated (its length is not what its header says)"
    )
    with pytest.raises(CloudFormatError, match="not an E57 file: bad signature"):
        read_cloud(b"not e57 at all" * 10, "bridge.e57")


# ------------------------------------------------------------------ attributes
def test_las_intensity_rgb_and_classification_are_kept_served_and_removed(api) -> None:
    n = 5000
    rng = np.random.default_rng(4)
    pts = _strip(n)
    intensity = rng.integers(1, 65535, n).astype(np.uint16)
    rgb = rng.integers(0, 65535, (n, 3)).astype(np.uint16)  # 16-bit colour
    cls = rng.choice([2, 6, 9], n).astype(np.uint8)
    attrs: dict[str, np.ndarray] = {
        "intensity": intensity,
        "red": rgb[:, 0],
        "green": rgb[:, 1],
        "blue": rgb[:, 2],
        "classification": cls,
    }
    data = _las(pts, crs=pyproj.CRS.from_epsg(NY_FTUS_EPSG), wkt=True, point_format=7, attrs=attrs)
    r = api.post("/api/v1/clouds", files={"file": ("span.las", data)})
    assert r.status_code == 201, r.text
    body = r.json()
    cid = body["id"]
    assert body["attributes"] == ["intensity", "rgb", "classification"]
    info = body["survey"]["attributes"]
    assert info["rgb"]["bits"] == 16 and info["intensity"]["dtype"] == "uint16"
    assert info["classification"]["classes"] == {str(c): int((cls == c).sum()) for c in (2, 6, 9)}
    got_i = _attr(api, cid, "intensity")
    assert got_i.dtype == np.uint16 and np.array_equal(got_i, intensity)  # as given
    got_rgb = _attr(api, cid, "rgb")
    assert got_rgb.shape == (n, 3) and np.array_equal(got_rgb, rgb)
    assert np.array_equal(_attr(api, cid, "classification"), cls)
    assert api.get(f"/api/v1/clouds/{cid}/attributes/normals", "viewer").status_code == 404
    store = api.services.store
    files = [store.arrays.path(f"clouds/{cid}.{a}.npy") for a in body["attributes"]]
    assert all(f.is_file() for f in files)
    assert {f"clouds/{cid}.{a}.npy" for a in body["attributes"]} <= referenced_arrays(store)
    assert api.delete(f"/api/v1/clouds/{cid}").status_code == 204
    assert not any(f.exists() for f in files)


def test_fields_a_las_writer_left_zero_are_not_kept(api) -> None:
    r = api.post("/api/v1/clouds", files={"file": ("span.las", _las(_strip(3000)))})
    body = r.json()
    assert body["attributes"] == []
    assert "zero for every point" in body["survey"]["attributes_not_kept"]["intensity"]


def _e57(
    tmp_path: Path, scans: list[np.ndarray], *, metadata: str = "", colour: bool = False
) -> bytes:
    """An E57 written by pye57 (its root's coordinateMetadata set to ``metadata``)."""

    class E57WithCRS(pye57.E57):
        def write_default_header(self) -> None:
            imf = self.image_file
            imf.extensionsAdd("", libe57.E57_V1_0_URI)
            self.root.set("formatName", libe57.StringNode(imf, "ASTM E57 3D Imaging Data File"))
            self.root.set("guid", libe57.StringNode(imf, "{6a1d0f3e-0000-4000-8000-000000000001}"))
            self.root.set("versionMajor", libe57.IntegerNode(imf, libe57.E57_FORMAT_MAJOR))
            self.root.set("versionMinor", libe57.IntegerNode(imf, libe57.E57_FORMAT_MINOR))
            self.root.set("e57LibraryVersion", libe57.StringNode(imf, libe57.E57_LIBRARY_ID))
            self.root.set("coordinateMetadata", libe57.StringNode(imf, metadata))
            when = libe57.StructureNode(imf)
            when.set("dateTimeValue", libe57.FloatNode(imf, 0.0))
            when.set("isAtomicClockReferenced", libe57.IntegerNode(imf, 0))
            self.root.set("creationDateTime", when)
            self.root.set("data3D", libe57.VectorNode(imf, True))
            self.root.set("images2D", libe57.VectorNode(imf, True))

    path = tmp_path / "scan.e57"
    e = E57WithCRS(str(path), mode="w")
    for k, pts in enumerate(scans):
        d: dict[str, np.ndarray] = {
            "cartesianX": pts[:, 0],
            "cartesianY": pts[:, 1],
            "cartesianZ": pts[:, 2],
        }
        if colour:
            d["intensity"] = np.linspace(0.0, 1.0, len(pts)) + k
            d["colorRed"] = np.full(len(pts), 200, np.uint8)
            d["colorGreen"] = (np.arange(len(pts)) % 256).astype(np.uint8)
            d["colorBlue"] = np.full(len(pts), 7, np.uint8)
        e.write_scan_raw(d, translation=np.zeros(3), rotation=np.array([1.0, 0.0, 0.0, 0.0]))
    e.close()
    return path.read_bytes()


def test_e57_colour_intensity_and_crs(api, tmp_path: Path) -> None:
    rng = np.random.default_rng(2)
    a, b = rng.uniform(0, 6, (3000, 3)), rng.uniform(0, 6, (2000, 3))
    data = _e57(tmp_path, [a, b], metadata="EPSG:2263", colour=True)
    r = api.post("/api/v1/clouds", files={"file": ("bridge.e57", data)})
    assert r.status_code == 201, r.text
    body = r.json()
    s = body["survey"]
    # E57 coordinates are metres by the standard: the CRS is kept, its unit not applied.
    assert s["crs"]["epsg"] == NY_FTUS_EPSG and s["units"] == "m" and s["scale_to_m"] == 1.0
    assert "E57 stores coordinates in metres" in s["units_reason"]
    assert pyproj.CRS.from_wkt(body["crs_wkt"]).to_epsg() == NY_FTUS_EPSG
    np.testing.assert_allclose(_points(api, body["id"]), np.vstack([a, b]), atol=1e-6)
    assert body["attributes"] == ["intensity", "rgb"] and s["attributes"]["rgb"]["bits"] == 8
    rgb = _attr(api, body["id"], "rgb")
    assert (rgb[:, 0] == 200).all() and (rgb[:, 2] == 7).all()
    assert np.array_equal(rgb[:3000, 1], np.arange(3000) % 256)
    inten = _attr(api, body["id"], "intensity")
    assert inten.dtype == np.float32 and inten[0] == 0.0 and inten[-1] == pytest.approx(2.0)


def test_an_e57_with_an_unknown_coordinate_metadata_is_read(api, tmp_path: Path) -> None:
    data = _e57(
        tmp_path, [np.random.default_rng(3).uniform(0, 6, (500, 3))], metadata="site grid B"
    )
    r = api.post("/api/v1/clouds", files={"file": ("bridge.e57", data)})
    assert r.status_code == 201, r.text
    s = r.json()["survey"]
    assert (
        s["crs"] is None and "coordinateMetadata" in s["crs_note"] and s["units_from"] == "detected"
    )


# ------------------------------------------------------------------ text columns
def _rows(rows: np.ndarray, fmt: str) -> bytes:
    return "\n".join(fmt.format(*r) for r in rows).encode() + b"\n"


@settings(max_examples=20, deadline=None)
@given(
    n=st.integers(10, 300),
    cols=st.sampled_from([4, 6, 7]),
    sep=st.sampled_from([" ", ",", ";", "\t"]),
    seed=st.integers(0, 2**16),
    offset=st.floats(-1e6, 1e6),
)
def test_text_columns_by_count(n: int, cols: int, sep: str, seed: int, offset: float) -> None:
    rng = np.random.default_rng(seed)
    xyz = offset + rng.uniform(0, 50, (n, 3))
    rgb = rng.integers(0, 256, (n, 3))
    inten = rng.uniform(0, 4000, n)
    parts = [xyz] + ([rgb] if cols >= 6 else []) + ([inten[:, None]] if cols in (4, 7) else [])
    table = np.hstack(parts)
    text = "\n".join(sep.join(repr(float(v)) for v in row) for row in table).encode() + b"\n"
    out = Path(f"/tmp/sp-text-{seed}-{cols}.npy")
    try:
        meta: dict[str, Any] = {}
        res = parse_to_npy(BytesSource(text), "a.xyz", out, meta)
        np.testing.assert_allclose(np.load(out), xyz, rtol=1e-15)
        if cols >= 6:
            assert np.array_equal(np.load(res.attribute_paths["rgb"]), rgb)
        if cols in (4, 7) and inten.max() > 0:
            np.testing.assert_allclose(
                np.load(res.attribute_paths["intensity"]), inten.astype(np.float32)
            )
    finally:
        out.unlink(missing_ok=True)
        for name in ("rgb", "intensity", "classification"):
            out.with_name(f"{out.stem}.{name}.npy").unlink(missing_ok=True)


def test_text_columns_by_header_names_and_bad_colour(api) -> None:
    rng = np.random.default_rng(5)
    xyz = rng.uniform(0, 10, (200, 3))
    body = b"//intensity,X,Y,Z,Red,Green,Blue\n" + _rows(
        np.column_stack([np.arange(200) + 1, xyz, np.full((200, 3), 9)]), "{},{},{},{},{},{},{}"
    )
    r = api.post("/api/v1/clouds", files={"file": ("pts.txt", body)})
    assert r.status_code == 201, r.text
    out = r.json()
    np.testing.assert_allclose(_points(api, out["id"]), xyz, rtol=1e-12)
    assert out["attributes"] == ["intensity", "rgb"]
    np.testing.assert_array_equal(_attr(api, out["id"], "intensity"), np.arange(200) + 1)
    # 6 columns whose "colour" is not whole numbers 0–65535: x y z only, and why
    body = _rows(np.column_stack([xyz, rng.uniform(0, 1, (200, 3))]), "{} {} {} {} {} {}")
    r = api.post("/api/v1/clouds", files={"file": ("pts.xyz", body)})
    assert r.status_code == 201 and r.json()["attributes"] == []
    assert "whole numbers" in r.json()["survey"]["attributes_not_kept"]["rgb"]
    # 5 columns: no rule, x y z only, the rule is named
    body = _rows(np.column_stack([xyz, xyz[:, :2]]), "{} {} {} {} {}")
    r = api.post("/api/v1/clouds", files={"file": ("pts.xyz", body)})
    assert r.status_code == 201 and "x y z r g b" in r.json()["survey"]["columns_note"]


# ------------------------------------------------------------------ scene colours
def test_colours_by_rgb_intensity_and_height() -> None:
    assert cloud_colours.resolve("auto", ["intensity", "rgb"]) == "rgb"
    assert cloud_colours.resolve("auto", ["intensity"]) == "height"
    rgb16 = np.array([[65535, 256, 0]], dtype=np.uint16)
    assert cloud_colours.by_rgb(rgb16, 16).tolist() == [[255, 1, 0]]
    assert cloud_colours.by_rgb(np.array([[200, 3, 0]], np.uint16), 8).tolist() == [[200, 3, 0]]
    g = cloud_colours.by_intensity(np.linspace(0, 1000, 101))
    assert g.shape == (101, 3) and g[0, 0] < g[50, 0] < g[-1, 0]
    assert cloud_colours.by_height(np.zeros((0, 3))).shape == (0, 3)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_the_scene_colours_a_cloud_by_its_rgb_by_default(make_api) -> None:
    api = make_api(scene_port=_free_port())
    n = 2000
    rgb = np.tile(np.array([[10, 20, 30]], np.uint16), (n, 1))
    data = _las(
        _strip(n) - 1e6,
        point_format=2,
        version="1.2",
        attrs={"red": rgb[:, 0], "green": rgb[:, 1], "blue": rgb[:, 2]},
    )
    cid = api.post("/api/v1/clouds", files={"file": ("c.las", data)}).json()["id"]
    r = api.post("/api/v1/scene/show", json={"cloud_id": cid})
    assert r.status_code == 200 and r.json()["colour_by"] == "rgb", r.text
    handle = api.services.scene.server.scene.get_handle_by_name("/cloud")
    assert np.asarray(handle.colors).reshape(-1, 3)[0].tolist() == [10, 20, 30]
    r = api.post("/api/v1/scene/show", json={"cloud_id": cid, "colour_by": "height"})
    assert r.json()["colour_by"] == "height"
    r = api.post("/api/v1/scene/show", json={"cloud_id": cid, "colour_by": "intensity"})
    assert r.status_code == 404 and "intensity" in r.json()["detail"]
    r = api.post("/api/v1/scene/show", json={"cloud_id": cid, "colour_by": "plaid"})
    assert r.status_code == 422


# ------------------------------------------------------------------ ara.inspect in feet
def _box(p0: Any, p1: Any, seed: int, spacing: float = 0.03) -> np.ndarray:
    """The four faces of a 0.3 × 0.2 m hollow section from ``p0`` to ``p1``, metres."""
    a, b = np.asarray(p0, float), np.asarray(p1, float)
    length = float(np.linalg.norm(b - a))
    x = (b - a) / length
    y = np.cross([0.0, 0.0, 1.0], x)
    y /= np.linalg.norm(y)
    z = np.cross(x, y)
    t = np.arange(0.0, length, spacing)
    faces = []
    for sign in (-1.0, 1.0):
        for across, size, normal in ((y, 0.3, z * 0.1), (z, 0.2, y * 0.15)):
            u = np.arange(-size / 2, size / 2 + 1e-9, spacing)
            tt, uu = (g.reshape(-1, 1) for g in np.meshgrid(t, u))
            faces.append(a + tt * x + uu * across + sign * normal)
    pts = np.vstack(faces)
    return pts + np.random.default_rng(seed).normal(0.0, 0.001, pts.shape)


def test_ara_inspect_takes_a_cloud_in_us_survey_feet(api) -> None:
    survey_m = np.array([304_800.0, 60_960.0, 9.0])
    ell_m = np.vstack([_box([0, 0, 0], [4, 0, 0], 1), _box([4, 0.15, 0], [4, 4, 0], 2)])
    buf = io.BytesIO()
    np.save(buf, (ell_m + survey_m) / US_FT)  # numbers in US survey feet
    r = api.post("/api/v1/clouds", files={"file": ("ell.npy", buf.getvalue())}, data={"units": "m"})
    cid = r.json()["id"]
    p = api.wait(api.submit("ara.inspect", {"cloud_id": cid, "units": "us-ft"})["id"], timeout=240)
    assert p["result"]["units"] == {
        "unit": "us-ft",
        "scale_to_m": pytest.approx(US_FT, rel=1e-15),
        "reason": "set by the request (us-ft)",
    }
    lengths = sorted(m["length_m"] for m in p["result"]["members"])
    assert lengths == [pytest.approx(4.0, abs=0.35), pytest.approx(4.0, abs=0.35)]
    bad = api.post(
        "/api/v1/plans", json={"kind": "ara.inspect", "params": {"cloud_id": cid, "units": "yd"}}
    )
    assert bad.status_code == 422
