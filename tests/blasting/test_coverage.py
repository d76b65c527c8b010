"""Hexagonal pattern, Eq. 3.2 classes, raster metrics and boundary editing."""

from __future__ import annotations

import json

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree
from shapely.geometry import Point, Polygon

from planners.blasting import coverage as C
from planners.blasting import scenes
from tests.conftest import SHARED_DATA

R_DEFAULT = 0.015875  # Eq. 3.1, medium nozzle at 300 mm
R_SEED = 0.04  # seed §4.2.1


def star_polygon(seed: int, n: int = 9, size: float = 0.5) -> Polygon:
    """A random star-shaped (usually concave) polygon."""
    rng = np.random.default_rng(seed)
    t = np.sort(rng.uniform(0, 2 * np.pi, n))
    rad = rng.uniform(0.45, 1.0, n)
    return Polygon(np.stack([rad * np.cos(t), rad * np.sin(t)], axis=1) * size / 2)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 10_000), st.sampled_from([0.02, 0.04]), st.floats(0, np.pi))
def test_lattice_covers_the_surface_and_touches_it(seed, r, angle):
    poly = star_polygon(seed)
    c = C.hex_lattice(poly, r, angle=angle)
    # every disc touches the surface
    assert np.all(shapely.distance(poly, shapely.points(c)) < r)
    # nearest neighbours are √3 r apart (triangular lattice)
    d, _ = cKDTree(c).query(c, k=2)
    assert np.allclose(d[:, 1], np.sqrt(3) * r)
    # brute force: random surface points are within r of some centre
    pts = shapely.get_coordinates(
        shapely.points(np.random.default_rng(seed).uniform(-0.3, 0.3, (4000, 2)))
    )
    pts = pts[shapely.contains_xy(poly, pts[:, 0], pts[:, 1])]
    assert cKDTree(c).query(pts)[0].max() <= r * (1 + 1e-9)
    # grown from P: P itself is a lattice centre
    P = C.centre_point(poly)
    assert cKDTree(c).query(P)[0] < 1e-9


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 10_000))
def test_eq_3_2_classes_match_sampled_discs(seed):
    poly = star_polygon(seed)
    r = 0.04
    rng = np.random.default_rng(seed)
    c = rng.uniform(-0.35, 0.35, size=(60, 2))
    cls = C.classify(c, poly, r)
    for ci, k in zip(c, cls, strict=True):
        # Independent reference: shapely's polygonal disc (a 256-gon, within
        # r·(1 − cos(π/256)) ≈ 3 µm of the circle) against the polygon.
        disc = Point(*ci).buffer(r, quad_segs=64)
        margin = abs(poly.boundary.distance(Point(*ci)) - r)
        if margin < 1e-4:
            continue  # the polygonal disc cannot decide a disc that just touches the boundary
        if k == C.INSIDE:
            assert poly.contains(disc)
        elif k == C.OUTSIDE:
            assert not poly.intersects(disc)
        else:
            assert poly.intersects(disc) and not poly.contains(disc)


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 10_000))
def test_raster_area_matches_shapely(seed):
    poly = star_polygon(seed).difference(Point(0, 0).buffer(0.03))  # with a hole
    ras = C.Raster.of(poly, 0.002, pad=0.01)
    assert ras.inside.sum() * ras.h**2 == pytest.approx(poly.area, rel=0.01)


def test_measure_agrees_with_monte_carlo():
    poly = star_polygon(7)
    rng = np.random.default_rng(1)
    c = rng.uniform(-0.25, 0.25, (40, 2))
    radii = rng.uniform(0.02, 0.05, 40)
    m = C.measure(poly, c, radii)
    # independent estimate: uniform samples
    xy = rng.uniform(-0.4, 0.4, (120_000, 2))
    inside = shapely.contains_xy(poly, xy[:, 0], xy[:, 1])
    hit = (np.linalg.norm(xy[:, None, :] - c[None], axis=2) <= radii).any(axis=1)
    cov = (hit & inside).sum() / inside.sum()
    over = (hit & ~inside).sum() * 0.8**2 / len(xy) / poly.area
    assert m.coverage == pytest.approx(cov, abs=0.005)
    assert m.overspray == pytest.approx(over, abs=0.005)


def test_seed_editing_moves_boundary_discs_tangent_to_straight_edges():
    square = Polygon([(0, 0), (0.5, 0), (0.5, 0.5), (0, 0.5)])
    lat = C.hex_lattice(square, R_SEED)
    cls = C.classify(lat, square, R_SEED)
    c, kept = C.edit_seed(lat, square, R_SEED)
    assert len(c) == np.count_nonzero(cls != C.OUTSIDE)
    assert not (kept == C.OUTSIDE).any()
    moved = c[kept == C.BOUNDARY]
    d_edge = np.minimum.reduce([moved[:, 0], moved[:, 1], 0.5 - moved[:, 0], 0.5 - moved[:, 1]])
    # each moved disc touches its fitted line from inside; away from the
    # corners the line is the edge itself
    away = (
        np.minimum.reduce([np.abs(moved[:, 0] - 0.25), np.abs(moved[:, 1] - 0.25)])
        < 0.25 - 2 * R_SEED
    )
    np.testing.assert_allclose(d_edge[away], R_SEED, atol=1e-9)
    assert C.measure(square, moved[away], R_SEED).overspray < 1e-4
    # at the corners the fitted line averages two edges and the disc sticks out
    assert C.measure(square, c, R_SEED).overspray > 1e-3


def _targets_met(poly: Polygon, r: float) -> tuple[float, float]:
    e = C.edit_improved(poly, r, small_r=r * 9.625 / 15.875, coverage_target=0.993)
    m = C.measure(poly, e.centers, e.radii)
    return m.coverage, m.overspray


@pytest.mark.parametrize("shape", ["trapezoid", "circle", "arbitrary"])
@pytest.mark.parametrize("r", [R_DEFAULT, R_SEED])
def test_improved_editing_meets_targets_on_seed_shapes(shape, r):
    poly = Polygon(scenes.seed_shape(shape, 0.5))
    cov, over = _targets_met(poly, r)
    assert cov >= 0.99 and over <= 0.005
    # the seed's editing, for contrast, misses the coverage target here
    lat = C.hex_lattice(poly, r)
    c, _ = C.edit_seed(lat, poly, r)
    assert C.measure(poly, c, r).coverage < 0.99


def _real_outlines() -> dict[str, tuple[list[np.ndarray], bool]]:
    d = SHARED_DATA / "polygons"
    if not d.is_dir():
        pytest.skip(f"shared polygons not found at {d}")
    out = {}
    g = shapely.wkt.loads((d / "ee_field_130.wkt").read_text())
    out["ee_field_130"] = (
        [np.asarray(g.exterior.coords), *[np.asarray(h.coords) for h in g.interiors]],
        True,
    )
    for f in ("test.json", "test_2_cell.json"):
        for i, ft in enumerate(json.loads((d / f).read_text())["features"]):
            out[f"{f}#{i}"] = ([np.asarray(r) for r in ft["geometry"]["coordinates"]], True)
    ring = json.loads((d / "test_ring.json").read_text())["features"][0]["geometry"]["coordinates"]
    out["test_ring"] = ([np.asarray(r) for r in ring], False)  # plain units, not lon/lat
    return out


@pytest.mark.parametrize("size", [0.5, 1.0])
def test_improved_editing_meets_targets_on_real_outlines(size):
    import shapely.wkt

    for name, (rings, geo) in _real_outlines().items():
        if size > 0.5 and name not in ("ee_field_130", "test_ring"):
            continue  # the larger size costs seconds per outline: the two hardest only
        ext, holes = scenes.outline_from_lonlat(rings, size, geographic=geo)
        poly = shapely.make_valid(Polygon(ext, holes))
        cov, over = _targets_met(poly, R_DEFAULT)
        assert cov >= 0.99, (name, size, cov)
        assert over <= 0.005, (name, size, over)


def test_narrow_band_is_filled_with_small_discs_and_checked_independently():
    """The seed's 0.04 m discs on the ring outline at 0.5 m (band 0.05 m wide):
    no full disc fits across without overspray, but the fill's continuum of
    radii down to the 100 mm-stream disc (Ø 48.5 mm < 50 mm) does, so the
    targets are met.  Coverage and overspray are confirmed by an exact
    shapely union of the discs (polygonised with 1024 segments), independent
    of the raster metric."""
    rings = [
        np.array([[0, 0], [10, 0], [10, 10], [0, 10]]),
        np.array([[1, 1], [9, 1], [9, 9], [1, 9]]),
    ]
    ext, holes = scenes.outline_from_lonlat(rings, 0.5, geographic=False)
    poly = Polygon(ext, holes)
    r_small = R_SEED * 9.625 / 15.875
    e = C.edit_improved(poly, R_SEED, small_r=r_small, coverage_target=0.993)
    m = C.measure(poly, e.centers, e.radii)
    assert m.coverage >= 0.99 and m.overspray <= 0.005
    assert e.radii.min() >= r_small * (1 - 1e-9) and e.radii.max() <= R_SEED
    discs = [Point(c).buffer(r, quad_segs=256) for c, r in zip(e.centers, e.radii, strict=True)]
    union = shapely.union_all(discs)
    cov = union.intersection(poly).area / poly.area
    over = union.difference(poly).area / poly.area
    assert cov >= 0.99 and over <= 0.005
    assert abs(cov - m.coverage) < 0.002 and abs(over - m.overspray) < 0.001


@pytest.mark.parametrize("shape", ["trapezoid", "arbitrary"])
def test_improved_editing_same_whatever_the_scoring_chunk(shape, monkeypatch):
    """The greedy candidates scored in chunks (only those that can
    gain kept) give the one-pass answer exactly, down to one per chunk."""
    poly = Polygon(scenes.seed_shape(shape, 0.5))
    kw = {"small_r": R_DEFAULT * 9.625 / 15.875, "coverage_target": 0.993}
    monkeypatch.setattr(C, "EDIT_CHUNK_PX", 10**12)
    one = C.edit_improved(poly, R_DEFAULT, **kw)
    monkeypatch.setattr(C, "EDIT_CHUNK_PX", 1)
    many = C.edit_improved(poly, R_DEFAULT, **kw)
    for f in ("centers", "radii", "classes", "small"):
        np.testing.assert_array_equal(getattr(one, f), getattr(many, f))


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 10_000), st.floats(0.005, 0.05))
def test_disc_far_from_every_pixel_centre_covers_none(seed, rad):
    """The premise of the greedy's candidate filter: a disc whose centre is
    farther than its radius from every pixel centre of a set covers none
    of them (its pixels are those whose centre lies within the radius)."""
    rng = np.random.default_rng(seed)
    poly = Polygon([(0, 0), (0.3, 0), (0.3, 0.2), (0, 0.2)])
    ras = C.Raster.of(poly, rad / 8.0, pad=rad + 0.01)
    flat = rng.choice(ras.nx * ras.ny, size=50, replace=False)
    pc = np.stack(
        [ras.x0 + (flat % ras.nx + 0.5) * ras.h, ras.y0 + (flat // ras.nx + 0.5) * ras.h], 1
    )
    cen = rng.uniform([-0.01, -0.01], [0.31, 0.21], size=(200, 2))
    d = np.min(np.linalg.norm(cen[:, None] - pc[None], axis=-1), axis=1)
    idx, _ = ras.disc_pixels(cen, np.full(len(cen), rad))
    hit = np.isin(idx, flat).any(axis=1)
    assert not (hit & (d > rad * (1.0 + 1e-6))).any()


@pytest.mark.parametrize(
    "poly, r_min, budget",
    [
        (Polygon([(0, 0), (2, 0), (2, 2), (0, 2)]), 0.024, 0.004),  # large: both skipped
        (Polygon([(0, 0), (0.3, 0), (0.3, 0.3), (0, 0.3)]), 0.024, 0.004),  # small square
        (Polygon([(0, 0), (0.5, 0), (0.5, 0.02), (0.25, 0.02), (0.25, 0.3), (0, 0.3)]), 0.02, 0.0),
        (star_polygon(3, size=0.4), 0.02, 0.004),
        (star_polygon(5, size=0.6), 0.015, 0.001),
    ],
)
def test_pointwise_bound_shortcuts_change_nothing(poly, r_min, budget):
    """The coverage bound's skipped convolution / distance
    transform give the full computation's answer (it is 1 exactly when they
    are skipped), including a slit narrower than the disc with no budget."""
    from planners.blasting.bound import pointwise_bound

    full = pointwise_bound(poly, r_min, budget, shortcut=False)
    fast = pointwise_bound(poly, r_min, budget)
    assert fast == full
