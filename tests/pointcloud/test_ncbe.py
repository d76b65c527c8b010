"""NCBE (seed Alg. 1) boundary points lie on, and cover, known outlines."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from planners.errors import EmptyInputError, InvalidInputError
from planners.pointcloud import alpha_shape, ncbe_boundary, ncbe_boundary_indices, order_boundary


def _sample(poly: shapely.Geometry, n: int, rng: np.random.Generator) -> np.ndarray:
    """Uniform points inside ``poly`` by rejection (vectorised)."""
    x0, y0, x1, y1 = poly.bounds
    out = np.empty((0, 2))
    while len(out) < n:
        cand = rng.uniform((x0, y0), (x1, y1), (4 * n, 2))
        out = np.vstack([out, cand[shapely.contains_xy(poly, cand[:, 0], cand[:, 1])]])
    return out[:n]


def _check_boundary(poly, pts, alpha, spacing):
    bnd = ncbe_boundary(pts, sliding_factor=alpha)
    outline = poly.boundary
    # Near: every NCBE point is within a few point spacings of the true outline.
    d_near = shapely.distance(outline, shapely.points(bnd))
    assert d_near.max() < 3.0 * spacing, d_near.max()
    # Cover: every sample of the true outline has an NCBE point within ~αs.
    along = np.linspace(0, outline.length, 400, endpoint=False)
    ref = shapely.get_coordinates(shapely.line_interpolate_point(outline, along))
    gap = np.min(np.linalg.norm(ref[:, None] - bnd[None], axis=-1), axis=1)
    assert gap.max() < 1.5 * alpha + 3.0 * spacing, gap.max()
    return bnd


@settings(max_examples=15, deadline=None)
@given(st.integers(0, 10_000), st.floats(0.3, 1.2), st.floats(0.2, 0.8))
def test_rectangle_boundary(seed, w, h):
    rng = np.random.default_rng(seed)
    poly = shapely.box(0, 0, w, h)
    n = int(w * h / 0.008**2)  # ~8 mm spacing
    pts = _sample(poly, n, rng)
    _check_boundary(poly, pts, alpha=0.03, spacing=0.008)


@settings(max_examples=15, deadline=None)
@given(st.integers(0, 10_000), st.floats(0.4, 1.0), st.floats(0.15, 0.35))
def test_l_shape_boundary(seed, size, arm):
    rng = np.random.default_rng(seed)
    poly = shapely.union(shapely.box(0, 0, size, arm), shapely.box(0, 0, arm, size))
    pts = _sample(poly, int(poly.area / 0.008**2), rng)
    bnd = _check_boundary(poly, pts, alpha=0.03, spacing=0.008)
    # Non-convexity is kept: points hug the inner corner, which the convex
    # hull would bridge.
    inner = np.array([arm, arm])
    assert np.min(np.linalg.norm(bnd - inner, axis=1)) < 1.5 * 0.03 + 3 * 0.008


def test_rectangle_matches_brute_force_slices():
    """Indices equal a per-slice brute-force O(k²) diameter search."""
    rng = np.random.default_rng(7)
    pts = rng.uniform(0, 1, (600, 2)) * [0.5, 0.3]
    alpha = 0.05
    want = set()
    for axis in range(2):
        c = pts[:, axis]
        dmin, dmax = c.min(), c.max()
        i, sl = 1, -np.inf
        while sl < dmax:
            sl = dmin + i * alpha
            members = np.nonzero((c >= sl - alpha / 2) & (c < sl + alpha / 2))[0]
            if len(members):
                best, pair = -1.0, None
                for a in members:
                    for b in members:
                        d = np.sum((pts[a] - pts[b]) ** 2)
                        if d > best:
                            best, pair = d, (a, b)
                want.update(pair)
            i += 1
    got = set(ncbe_boundary_indices(pts, sliding_factor=alpha).tolist())
    assert got == want


def test_3d_input_and_order_boundary():
    rng = np.random.default_rng(8)
    pts = rng.uniform(0, 1, (3000, 2)) * [0.6, 0.4]
    bnd = ncbe_boundary(np.c_[pts, np.zeros(len(pts))], sliding_factor=0.03)
    assert bnd.shape[1] == 3
    b2 = ncbe_boundary(pts, sliding_factor=0.03)
    ring = order_boundary(b2)
    assert sorted(ring.tolist()) == list(range(len(b2)))
    closed = np.vstack([b2[ring], b2[ring[:1]]])
    perim = np.linalg.norm(np.diff(closed, axis=0), axis=1).sum()
    assert abs(perim - 2.0) < 0.25  # true perimeter 2 m


def test_alpha_shape_keeps_concavity_and_holes():
    rng = np.random.default_rng(9)
    sq = shapely.box(0, 0, 1, 1).difference(shapely.Point(0.5, 0.5).buffer(0.15))
    pts = _sample(sq, 20000, rng)
    hull = alpha_shape(pts, 0.03)
    assert abs(hull.area - sq.area) / sq.area < 0.03
    assert not hull.contains(shapely.Point(0.5, 0.5))
    assert hull.contains(shapely.Point(0.1, 0.1))


def test_ncbe_errors():
    with pytest.raises(EmptyInputError):
        ncbe_boundary(np.zeros((0, 2)))
    with pytest.raises(InvalidInputError):
        ncbe_boundary(np.zeros((5, 2)), sliding_factor=-1)
    with pytest.raises(InvalidInputError):
        ncbe_boundary(np.zeros((5, 4)))


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    n=st.integers(10, 400),
    alpha=st.floats(0.02, 0.5),
)
def test_alpha_shape_equals_the_plain_union_of_its_triangles(seed: int, n: int, alpha: float):
    """The fast coverage union is the same region as shapely's general union."""
    from scipy.spatial import Delaunay

    pts = np.random.default_rng(seed).uniform(0, 1, (n, 2))
    hull = alpha_shape(pts, alpha)
    tri = Delaunay(pts)
    c = pts[tri.simplices]
    a = np.linalg.norm(c[:, 1] - c[:, 2], axis=1)
    b = np.linalg.norm(c[:, 0] - c[:, 2], axis=1)
    cc = np.linalg.norm(c[:, 0] - c[:, 1], axis=1)
    e1, e2 = c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]
    area2 = np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    with np.errstate(divide="ignore", invalid="ignore"):
        keep = np.isfinite(r := a * b * cc / (2 * area2)) & (r < alpha)
    ref = shapely.union_all(shapely.polygons(np.concatenate([c[keep], c[keep][:, :1]], axis=1)))
    assert abs(hull.area - ref.area) <= 1e-12 + 1e-9 * ref.area
    assert hull.symmetric_difference(ref).area <= 1e-9 * max(ref.area, 1e-12)
