"""Synthetic TLS scans of steel structures: sections, scanner physics, truth, matching."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from planners.errors import InvalidInputError
from planners.structure.sections import (
    SECTIONS,
    member_frame,
    member_surface_points,
    outline_area,
    outline_radius,
    section_outline,
)
from planners.structure.synthetic import (
    NOISE_M,
    NOISE_PER_M,
    SCAN_KINDS,
    SCAN_SAMPLES,
    ScanStructure,
    _Grid,
    _Prism,
    _Scene,
    _scene_candidates,
    first_returns,
    make_scan,
    match_members,
    nearest_per_bin,
)


@cache
def scan(kind: str, seed: int, spacing: float = 0.1, units: str = "m") -> ScanStructure:
    return make_scan(kind, seed, spacing_m=spacing, units=units)


def seg_dist(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance of points (N, 3) to the segment a–b."""
    d = b - a
    t = np.clip((p - a) @ d / (d @ d), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[:, None] * d), axis=1)


def nn_dist(pts: np.ndarray) -> np.ndarray:
    """Distance of each point to its nearest other point."""
    d, _ = cKDTree(pts).query(pts, k=2)
    return np.asarray(d)[:, 1]


def local_uv(sc: ScanStructure, m: int, pts_m: np.ndarray) -> np.ndarray:
    """Points in member ``m``'s section plane coordinates (u, v), metres."""
    mem = sc.members[m]
    f = member_frame(mem.axis[0], mem.axis[1], mem.roll)
    return (pts_m - mem.axis[0]) @ f[:2].T


# --------------------------------------------------------------------------- sections


def test_section_table_dimensions() -> None:
    ipe = SECTIONS["IPE 300"]
    assert ipe.profile == "I"
    assert (ipe.h, ipe.b, ipe.tw, ipe.tf) == pytest.approx(
        (0.300, 0.150, 0.0071, 0.0107), rel=1e-12
    )
    heb = SECTIONS["HEB 300"]
    assert (heb.h, heb.b, heb.tw, heb.tf) == pytest.approx((0.300, 0.300, 0.011, 0.019), rel=1e-12)
    assert SECTIONS["L 100x100x10"].area_m2 == pytest.approx(19.2e-4)
    assert {s.profile for s in SECTIONS.values()} == {
        "I", "channel", "angle", "tee", "box", "tube", "plate",
    }  # fmt: skip


@pytest.mark.parametrize("name", sorted(SECTIONS))
def test_section_outline_area_and_centroid(name: str) -> None:
    s = SECTIONS[name]
    # sharp-cornered outline: a few per cent under the table (fillets, radii)
    assert 0.93 <= outline_area(s) / s.area_m2 <= 1.03
    poly = shapely.Polygon(section_outline(s))
    assert poly.is_valid
    c = poly.centroid
    assert abs(c.x) < 1e-9 and abs(c.y) < 1e-9
    r = outline_radius(s)
    assert max(s.h, s.b) / 2 <= r + 1e-9
    assert r <= np.hypot(s.h, s.b)
    minx, miny, maxx, maxy = poly.bounds
    assert maxx - minx == pytest.approx(s.b, rel=1e-3)
    assert maxy - miny == pytest.approx(s.h, rel=1e-3)


@settings(max_examples=25, deadline=None)
@given(
    name=st.sampled_from(sorted(SECTIONS)),
    p0=st.tuples(*[st.floats(-5, 5)] * 3),
    d=st.tuples(*[st.floats(-3, 3)] * 3).filter(lambda v: np.linalg.norm(v) > 0.3),
    roll=st.floats(-np.pi, np.pi),
    seed=st.integers(0, 2**16),
)
def test_member_surface_on_outline_with_outward_normals(
    name: str, p0: tuple[float, ...], d: tuple[float, ...], roll: float, seed: int
) -> None:
    s = SECTIONS[name]
    a = np.array(p0)
    b = a + np.array(d)
    spacing = 0.01
    pts, nrm = member_surface_points(s, a, b, roll, spacing, np.random.default_rng(seed))
    f = member_frame(a, b, roll)
    assert np.allclose(f @ f.T, np.eye(3), atol=1e-12)
    uv = (pts - a) @ f[:2].T
    t = (pts - a) @ f[2]
    length = float(np.linalg.norm(b - a))
    assert t.min() >= -1e-9 and t.max() <= length + 1e-9
    poly = shapely.Polygon(section_outline(s))
    on = shapely.distance(shapely.points(uv), poly.exterior)
    assert on.max() < 1e-9
    assert np.allclose(np.linalg.norm(nrm, axis=1), 1.0)
    assert np.abs(nrm @ f[2]).max() < 1e-12  # normals lie in the section plane
    n_uv = nrm @ f[:2].T
    eps = 1e-4
    outside = ~shapely.contains_xy(poly, *(uv + eps * n_uv).T)
    inside = shapely.contains_xy(poly, *(uv - eps * n_uv).T)
    # corners of thin walls can put a shifted point across a neighbouring face
    assert outside.mean() > 0.97 and inside.mean() > 0.97
    expected = poly.exterior.length * length / spacing**2
    assert 0.8 * expected <= len(pts) <= 1.3 * expected + 2 * poly.exterior.length / spacing


def test_tube_normals_are_radial() -> None:
    s = SECTIONS["CHS 219.1x10"]
    a, b = np.array([1.0, 2.0, 3.0]), np.array([4.0, -1.0, 5.0])
    pts, nrm = member_surface_points(s, a, b, 0.3, 0.01, np.random.default_rng(1))
    d = (b - a) / np.linalg.norm(b - a)
    radial = (pts - a) - np.outer((pts - a) @ d, d)
    rlen = np.linalg.norm(radial, axis=1)
    assert np.abs(rlen - s.h / 2).max() < 0.001 * s.h
    assert np.min(np.einsum("ij,ij->i", radial / rlen[:, None], nrm)) > 0.999


# --------------------------------------------------------------------------- scans


def test_arguments_are_checked() -> None:
    with pytest.raises(InvalidInputError, match="unknown scan kind"):
        make_scan("howe", 0)
    with pytest.raises(InvalidInputError, match="spacing_m"):
        make_scan("warren", 0, spacing_m=0.0)
    with pytest.raises(InvalidInputError, match="spacing_m"):
        make_scan("warren", 0, spacing_m=float("nan"))
    with pytest.raises(InvalidInputError, match="units"):
        make_scan("warren", 0, units="ft")
    with pytest.raises(InvalidInputError, match="n_scanners"):
        make_scan("warren", 0, n_scanners=0)
    with pytest.raises(InvalidInputError, match="max_points"):
        make_scan("warren", 0, max_points=0)


@pytest.mark.parametrize("kind", SCAN_KINDS)
def test_deterministic_and_seed_dependent(kind: str) -> None:
    a = make_scan(kind, 3, spacing_m=0.1)
    b = make_scan(kind, 3, spacing_m=0.1)
    c = make_scan(kind, 4, spacing_m=0.1)
    assert np.array_equal(a.points, b.points)
    assert np.array_equal(a.labels, b.labels)
    assert np.array_equal(a.true_axes(), b.true_axes())
    assert a.points.shape != c.points.shape or not np.array_equal(a.points, c.points)
    assert not np.array_equal(a.frame_offset, c.frame_offset)


@pytest.mark.parametrize("kind", SCAN_KINDS)
def test_labels_lie_on_their_members(kind: str) -> None:
    sc = scan(kind, 1)
    pts = sc.points / sc.scale
    assert pts.dtype == np.float64 and sc.labels.shape == (len(pts),)
    r_max = float(np.linalg.norm(pts - sc.scanners[sc.scanner_index], axis=1).max())
    margin = 6 * (NOISE_M + NOISE_PER_M * r_max)
    lab = sc.labels
    assert set(np.unique(lab)) <= {-1, *range(len(sc.members))}
    near_any = np.zeros(len(pts), dtype=bool)
    for m in sc.members:
        d = seg_dist(pts, m.axis[0], m.axis[1])
        reach = outline_radius(m.section) + margin
        own = lab == m.id
        near_any |= d <= reach
        if not own.any():  # hidden from every scanner
            continue
        assert d[own].max() <= reach, m
        # the point sits on the section outline, which checks the roll and the survey frame
        uv = local_uv(sc, m.id, pts[own])
        ring = shapely.Polygon(section_outline(m.section)).exterior
        assert shapely.distance(shapely.points(uv), ring).max() <= margin
    # far from every member: clutter, and clutter exists (ground, blobs, person, outliers)
    assert (lab[~near_any] == -1).all()
    assert (lab == -1).sum() > 0.05 * len(lab)
    ground = np.abs(pts[:, 2] - sc.ground_z) < margin
    assert ground.sum() > 100 and (lab[ground & ~near_any] == -1).all()


def test_without_clutter_every_point_is_a_member() -> None:
    sc = make_scan("pratt", 2, spacing_m=0.1, clutter=False)
    assert (sc.labels >= 0).all()
    assert (sc.member_point_counts() > 0).sum() >= 0.8 * len(sc.members)


@pytest.mark.parametrize("kind", SCAN_KINDS)
def test_front_faces_only_and_scanners_placed(kind: str) -> None:
    sc = scan(kind, 0)
    pts = sc.points / sc.scale
    s = sc.scanners[sc.scanner_index]
    assert (np.einsum("ij,ij->i", sc.normals, s - pts) > 0).all()
    h = sc.scanners[:, 2] - sc.ground_z
    assert ((h >= 1.5) & (h <= 2.0)).all()
    axes = sc.true_axes().reshape(-1, 3)
    horiz = np.linalg.norm(sc.scanners[:, None, :2] - axes[None, :, :2], axis=2).min(axis=1)
    if kind == "deck":
        # one scanner under the deck, the others on both sides of it
        assert 3 <= len(sc.scanners) <= 5
        assert (horiz[1:] >= 4.5).all() and (horiz <= 26).all()
        return
    assert 2 <= len(sc.scanners) <= 4
    assert (horiz >= 4.5).all() and (horiz <= 26).all()


def test_units_mm_are_metres_times_1000() -> None:
    m = make_scan("frame", 5, spacing_m=0.1, units="m")
    mm = make_scan("frame", 5, spacing_m=0.1, units="mm")
    assert mm.scale == 1000.0 and m.scale == 1.0
    assert np.array_equal(mm.points, m.points * 1000.0)
    assert np.array_equal(mm.labels, m.labels)
    assert np.array_equal(mm.true_axes(), m.true_axes())


def test_survey_frame_is_far_and_rigid() -> None:
    sc = scan("grillage", 0)
    assert sc.points[:, 0].min() > 3e5 and sc.points[:, 1].min() > 5e6
    # undo the offset and yaw: the ground is z = 0 and members keep their lengths
    c, s = np.cos(-sc.yaw), np.sin(-sc.yaw)
    rot = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    local = (sc.true_axes() - sc.frame_offset) @ rot.T
    main = [m.id for m in sc.members if m.role == "main"]
    assert np.allclose(local[main, :, 1], local[main, :, 1][:, :1])  # mains run along local x
    assert local[:, :, 2].min() > 0.5


@pytest.mark.parametrize("kind", SCAN_KINDS)
def test_joints_sit_where_their_members_meet(kind: str) -> None:
    sc = scan(kind, 2)
    assert sc.joints
    for j in sc.joints:
        assert len(j.members) >= 2
        for mid in j.members:
            m = sc.members[mid]
            depth = max(sc.members[k].section.h for k in j.members)
            d = m.axis[1] - m.axis[0]
            w = j.pos - m.axis[0]
            line = np.linalg.norm(w - (w @ d) / (d @ d) * d)
            assert line <= depth / 2 + 1e-9
            assert seg_dist(j.pos[None], m.axis[0], m.axis[1])[0] <= depth + 0.7


@pytest.mark.parametrize(
    ("kind", "spacing"), [(k, 0.1) for k in SCAN_KINDS] + [(k, 0.02) for k in SCAN_KINDS]
)
def test_spacing_close_to_target(kind: str, spacing: float) -> None:
    sc = scan(kind, 0, spacing)
    pts = sc.points[sc.labels >= 0]
    nn = nn_dist(pts)
    assert spacing / 2 <= float(np.median(nn)) <= 2 * spacing


def test_max_points_and_samples() -> None:
    sc = make_scan("warren", 0, spacing_m=0.05, max_points=2000)
    assert len(sc.points) == 2000 == len(sc.labels) == len(sc.normals)
    assert set(SCAN_SAMPLES) == {f"scan_{k}" for k in SCAN_KINDS}
    pts = SCAN_SAMPLES["scan_pratt"](1)
    assert pts.ndim == 2 and pts.shape[1] == 3 and 10_000 <= len(pts) <= 300_000


# --------------------------------------------------------------------------- occlusion


@settings(max_examples=40, deadline=None)
@given(
    bins=st.lists(st.integers(0, 30), min_size=1, max_size=200),
    seed=st.integers(0, 2**16),
    ties=st.booleans(),
)
def test_nearest_per_bin_against_brute_force(bins: list[int], seed: int, ties: bool) -> None:
    b = np.array(bins, dtype=np.int64)
    rng = np.random.default_rng(seed)
    r = rng.integers(0, 3, len(b)).astype(float) if ties else rng.random(len(b))
    keep = nearest_per_bin(b, r)
    assert list(b[keep]) == sorted(set(bins))
    for i in keep:
        same = np.flatnonzero(b == b[i])
        assert i == same[np.argmin(r[same])]  # nearest, lowest index on a tie


def test_first_returns_chunked_equals_whole() -> None:
    sc_scene = _Scene(
        prisms=[
            _Prism(SECTIONS["HEB 300"], np.array([6.0, -2, 1]), np.array([6.0, 2, 1]), 0.0, 0),
            _Prism(SECTIONS["CHS 168.3x8"], np.array([8.0, -1, 0]), np.array([8.0, 1, 3]), 0.0, 1),
        ],
        ground=(4.0, 10.0, -3.0, 3.0),
        blobs=[(np.array([9.0, 2.0, 0.5]), np.array([0.5, 0.4, 0.4]))],
        centre=np.array([7.0, 0, 1]),
    )
    origin = np.array([0.0, 0.0, 1.7])
    dtheta = 0.02 / 7.0
    grid = _Grid(origin, dtheta)
    cands = list(_scene_candidates(sc_scene, grid, np.random.default_rng(0)))
    whole = first_returns(origin, dtheta, iter(cands), merge_at=10**12)
    chunked = first_returns(origin, dtheta, iter(cands), merge_at=5000)
    assert np.array_equal(whole.pts, chunked.pts)
    # brute force on a few bins: the kept point is the nearest candidate of that bin
    allp = np.concatenate([c.pts for c in cands])
    b_all, r_all = grid.bins(allp)
    b_kept, r_kept = grid.bins(whole.pts)
    assert len(np.unique(b_kept)) == len(b_kept) == len(np.unique(b_all))
    for i in np.random.default_rng(1).choice(len(b_kept), 50, replace=False):
        assert r_kept[i] == r_all[b_all == b_kept[i]].min()


def test_front_member_casts_a_shadow() -> None:
    """A 0.3 m wide HEB column 5 m in front of a wide plate hides the plate behind it."""
    col = SECTIONS["HEB 300"]
    plate = SECTIONS["FL 300x20"]
    scene = _Scene(
        prisms=[
            _Prism(col, np.array([5.0, 0, 0]), np.array([5.0, 0, 3]), 0.0, 0),
            # a vertical wall: plate width (b) along y, thickness along x
            _Prism(plate, np.array([10.0, -3, 1.5]), np.array([10.0, 3, 1.5]), np.pi / 2, 1),
        ],
        ground=None,
        blobs=[],
        centre=np.array([7.5, 0, 1.5]),
    )
    origin = np.array([0.0, 0.0, 1.5])
    dtheta = 0.01 / 7.5
    hits = first_returns(
        origin, dtheta, _scene_candidates(scene, _Grid(origin, dtheta), np.random.default_rng(3))
    )
    wall = hits.pts[hits.lab == 1]
    assert len(wall) > 1000 and (hits.lab == 0).sum() > 100
    # the column (|y| ≤ 0.15, 4.85 ≤ x ≤ 5.15, 0 ≤ z ≤ 3) blocks every ray with
    # |y|/x < 0.15/5.15 on its way to the 0.3 m tall wall at z 1.35–1.65
    slope = np.abs(wall[:, 1]) / (wall[:, 0] - origin[0])
    assert not (slope < 0.15 / 5.15 * 0.95).any()
    # just outside the shadow the wall is seen
    assert ((slope > 0.15 / 4.85 * 1.1) & (slope < 0.05)).sum() > 20


def test_density_falls_with_range() -> None:
    sc = scan("frame", 1, 0.02)
    pts = sc.points[sc.labels >= 0] / sc.scale
    one = sc.scanner_index[sc.labels >= 0] == 0
    p = pts[one]
    r = np.linalg.norm(p - sc.scanners[0], axis=1)
    nn = nn_dist(p)
    near, far = r < np.quantile(r, 0.25), r > np.quantile(r, 0.75)
    assert np.median(nn[far]) > 1.3 * np.median(nn[near])


# --------------------------------------------------------------------------- matching


def brute_match(
    ta: np.ndarray, depth: np.ndarray, fa: np.ndarray, n: int = 64
) -> tuple[float, float]:
    """The criterion read literally, one pair at a time."""

    def dist(p: np.ndarray, seg: np.ndarray) -> float:
        return float(seg_dist(p[None], seg[0], seg[1])[0])

    def angle(a: np.ndarray, b: np.ndarray) -> float:
        u, v = a[1] - a[0], b[1] - b[0]
        c = abs(u @ v) / np.linalg.norm(u) / np.linalg.norm(v)
        return float(np.degrees(np.arccos(min(c, 1.0))))

    def cover(src: np.ndarray, dst: np.ndarray, tol: float) -> float:
        ts = (np.arange(n) + 0.5) / n
        return float(np.mean([dist(src[0] + t * (src[1] - src[0]), dst) <= tol for t in ts]))

    tol = [max(0.05, 0.6 * d) for d in depth]
    found_t, good_f = set(), set()
    for t in range(len(ta)):
        for f in range(len(fa)):
            if angle(ta[t], fa[f]) <= 5.0:
                if cover(ta[t], fa[f], tol[t]) >= 0.8:
                    found_t.add(t)
                    good_f.add(f)
                if cover(fa[f], ta[t], tol[t]) >= 0.8:
                    good_f.add(f)
    return len(found_t) / len(ta), len(good_f) / len(fa)


def rot_about_mid(ax: np.ndarray, deg: float, axis: np.ndarray) -> np.ndarray:
    mid = ax.mean(axis=0)
    k = axis / np.linalg.norm(axis)
    a = np.radians(deg)
    v = ax - mid
    v = v * np.cos(a) + np.cross(k, v) * np.sin(a) + np.outer(v @ k, k) * (1 - np.cos(a))
    return mid + v


vec = st.tuples(*[st.floats(-10, 10)] * 3).map(np.array)


@settings(max_examples=40, deadline=None)
@given(p0=vec, d=vec.filter(lambda v: np.linalg.norm(v) > 1.0), depth=st.floats(0.05, 0.5),
       frac=st.floats(0.0, 0.95), seed=st.integers(0, 2**16))  # fmt: skip
def test_match_self_shift_and_rotation(
    p0: np.ndarray, d: np.ndarray, depth: float, frac: float, seed: int
) -> None:
    t = np.array([[p0, p0 + d]])
    tol = max(0.05, 0.6 * depth)
    assert match_members(t, [depth], t) == (1.0, 1.0, [(0, 0)])
    perp = np.cross(d, np.random.default_rng(seed).normal(size=3))
    perp /= np.linalg.norm(perp)
    near = match_members(t, [depth], t + frac * tol * perp)
    assert near.recall == 1.0 and near.precision == 1.0
    far = match_members(t, [depth], t + 1.05 * tol * perp)
    assert far.recall == 0.0 and far.precision == 0.0
    turned = match_members(t, [depth], rot_about_mid(t[0], 5.5, perp)[None])
    assert turned.recall == 0.0 and turned.precision == 0.0


def test_match_fragment_counts_for_precision_only() -> None:
    t = np.array([[[0.0, 0, 0], [10.0, 0, 0]]])
    frag = np.array([[[2.0, 0, 0], [5.0, 0.01, 0]]])
    res = match_members(t, [0.3], frag)
    assert res.recall == 0.0 and res.precision == 1.0 and res.pairs == []
    assert match_members(t, [0.3], np.zeros((0, 2, 3))) == (0.0, 1.0, [])
    assert match_members(np.zeros((0, 2, 3)), [], frag) == (1.0, 0.0, [])
    with pytest.raises(InvalidInputError):
        match_members(t, [0.3, 0.2], frag)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n_t=st.integers(1, 5), n_f=st.integers(1, 6))
def test_match_against_brute_force(seed: int, n_t: int, n_f: int) -> None:
    rng = np.random.default_rng(seed)
    ta = rng.uniform(-3, 3, (n_t, 2, 3))
    depth = rng.uniform(0.05, 0.5, n_t)
    # found: perturbed, cut or turned copies of true members, plus random ones
    src = ta[rng.integers(n_t, size=n_f)]
    tt = rng.uniform(-0.1, 0.3, (n_f, 1, 1)) * np.array([1, -1])[None, :, None]
    fa = src + tt * (src[:, 1:] - src[:, :1]) + rng.normal(0, 0.05, (n_f, 2, 3))
    wild = rng.random(n_f) < 0.3
    fa[wild] = rng.uniform(-3, 3, (int(wild.sum()), 2, 3))
    res = match_members(ta, depth, fa)
    assert (res.recall, res.precision) == pytest.approx(brute_match(ta, depth, fa))


def test_scan_match_on_its_own_truth() -> None:
    sc = scan("frame", 2)
    ax = sc.true_axes()
    d = ax[:, 1:] - ax[:, :1]
    assert sc.match(ax) == (1.0, 1.0, [(i, i) for i in range(len(ax))])
    cut = np.concatenate([ax[:, :1] + 0.08 * d, ax[:, 1:] - 0.08 * d], axis=1)
    assert sc.match(cut).recall == 1.0
    # distances are to the found *segment*: a cut end still covers tol past it
    tol = np.maximum(0.05, 0.6 * sc.true_depths())[:, None, None]
    u = d / np.linalg.norm(d, axis=2, keepdims=True)
    short = np.concatenate([ax[:, :1] + 0.15 * d + tol * u, ax[:, 1:] - 0.15 * d - tol * u], axis=1)
    res = sc.match(short)
    assert res.recall == 0.0 and res.precision == 1.0
