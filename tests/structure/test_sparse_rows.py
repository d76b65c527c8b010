"""Sparse member rows (:mod:`planners.structure.sparse`): rows of single
points found among the points no candidate explains, scan rings on the
ground left alone."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

import planners.structure.pipeline as pipeline
import planners.structure.sparse as sparse
from planners.structure import StructureParams, model_structure
from planners.structure.synthetic import make_scan, match_members

SPACING = 0.1


def _row(origin: np.ndarray, d: np.ndarray, length: float, step: float, rng) -> np.ndarray:
    t = np.arange(0.0, length + 1e-9, step)
    noise = rng.normal(scale=0.2 * SPACING, size=(len(t), 3))
    return origin + np.outer(t, d) + noise


def _rings(z: float, n_rings: int = 8, ring_gap: float = 0.5) -> np.ndarray:
    """Scan rings on flat ground: circles ``ring_gap`` apart, a point every spacing."""
    out = []
    for k in range(n_rings):
        r = 2.0 + k * ring_gap
        a = np.arange(0.0, 2 * np.pi, SPACING / r)
        out.append(np.column_stack([r * np.cos(a), r * np.sin(a), np.full(len(a), z)]))
    return np.vstack(out)


@settings(max_examples=25, deadline=None)
@given(
    theta=st.floats(0.0, np.pi),
    phi=st.floats(0.0, 2 * np.pi),
    step=st.floats(0.12, 0.35),
    count=st.integers(10, 25),
    seed=st.integers(0, 2**16),
)
def test_a_sparse_row_is_found_along_its_line(
    theta: float, phi: float, step: float, count: int, seed: int
) -> None:
    """One row of ``count`` single points a few spacings apart, any
    direction, far from the origin: one candidate, along the row within 3°, over ≥ 90 % of
    its length, within two spacings of it."""
    rng = np.random.default_rng(seed)
    d = np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])
    origin = np.array([500.0, -300.0, 40.0])
    length = (count - 1) * step
    pts = _row(origin, d, length, step, rng)
    rows = sparse.sparse_rows(pts, np.ones(len(pts), bool), SPACING, 0.7)
    assert len(rows) == 1
    c = rows[0]
    assert abs(float(c.direction @ d)) >= np.cos(np.radians(3.0))
    assert c.length >= 0.9 * length
    ends_t = (c.ends - origin) @ d
    perp = np.linalg.norm(c.ends - origin - np.outer(ends_t, d), axis=1)
    assert perp.max() <= 2 * SPACING


def test_scan_rings_on_the_ground_are_not_rows(monkeypatch) -> None:
    """Rings on flat ground half a metre apart are lines locally (a point's
    nearest neighbours lie on its own ring); the plane test sees the next
    rings beside them.  With the plane test off the same cloud gives rows
    (the test can fail); a sparse post standing on the ground is still found."""
    ground = _rings(0.0)
    rows = sparse.sparse_rows(ground, np.ones(len(ground), bool), SPACING, 0.7)
    assert rows == []
    with monkeypatch.context() as m:
        m.setattr(sparse, "SPARSE_PLANE_MAX", 1e9)
        assert len(sparse.sparse_rows(ground, np.ones(len(ground), bool), SPACING, 0.7)) > 0
    post = _row(
        np.array([0.0, 0.0, 0.3]), np.array([0.0, 0.0, 1.0]), 2.0, 0.2, np.random.default_rng(1)
    )
    pts = np.vstack([ground, post])
    rows = sparse.sparse_rows(pts, np.ones(len(pts), bool), SPACING, 0.7)
    assert len(rows) == 1
    assert abs(rows[0].direction[2]) >= np.cos(np.radians(3.0))


def test_points_not_free_are_left_alone_and_the_result_is_deterministic() -> None:
    rng = np.random.default_rng(3)
    a = _row(np.zeros(3), np.array([1.0, 0.0, 0.0]), 3.0, 0.2, rng)
    b = _row(np.array([0.0, 2.0, 0.0]), np.array([0.0, 0.0, 1.0]), 3.0, 0.2, rng)
    pts = np.vstack([a, b])
    free = np.r_[np.ones(len(a), bool), np.zeros(len(b), bool)]
    first = sparse.sparse_rows(pts, free, SPACING, 0.7)
    assert len(first) == 1 and abs(first[0].direction[0]) > 0.99
    again = sparse.sparse_rows(pts, free, SPACING, 0.7)
    assert np.allclose(first[0].ends, again[0].ends)
    assert sparse.sparse_rows(pts, np.zeros(len(pts), bool), SPACING, 0.7) == []


def _scores(kind: str, seed: int) -> tuple[float, float]:
    scan = make_scan(kind, seed, spacing_m=0.1)
    model = model_structure(scan.points / scan.scale)
    found = np.array([m.axis for m in model.members])
    mm = match_members(scan.true_axes(), scan.true_depths(), found)
    return mm.recall, mm.precision


def test_sparse_rows_find_members_a_10_cm_scan_s_features_missed(monkeypatch) -> None:
    """Warren seed 1 and Pratt seed 4 at 10 cm: with the sparse rows every
    Warren member is found and 10 of 13 Pratt members; without them recall
    is 0.83 and 0.54 (verticals and diagonals whose voxels never looked
    linear)."""
    recall, precision = _scores("warren", 1)
    assert recall == 1.0 and precision >= 0.94, (recall, precision)
    recall, precision = _scores("pratt", 4)
    assert recall >= 0.75 and precision >= 0.8, (recall, precision)
    monkeypatch.setattr(pipeline, "SPARSE_ROWS", False)
    # the bridging rows (a later stage) take some of these members between
    # chords another way (Pratt 4: 0.62 without the sparse rows); the sparse
    # rows are measured without them
    monkeypatch.setattr(pipeline, "BRIDGE_ROWS", False)
    assert _scores("warren", 1)[0] < 0.9
    assert _scores("pratt", 4)[0] < 0.6


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(min(1.0, abs(float(a @ b))))))


def test_a_short_core_takes_its_direction_from_all_its_points(monkeypatch) -> None:
    """A 10 cm scan of a 1.2 m channel post: 17 points scattered over the
    0.2 × 0.075 m section; the chords at its ends took 7 of them, leaving a
    core of the middle 10.  Over 200 draws the direction through all 17
    points is off by less than the core's alone, on the median and in the
    worst tenth (the core alone leaned 11° in Pratt seed 12)."""
    rng = np.random.default_rng(0)
    z = np.array([0.0, 0.0, 1.0])
    errors: dict[int, list[float]] = {0: [], 12: []}
    for _ in range(200):
        t = np.sort(rng.uniform(0.0, 1.2, 17))
        across = np.column_stack([rng.uniform(-0.1, 0.1, 17), rng.uniform(-0.04, 0.04, 17)])
        pts = np.column_stack([across, t]) + np.array([100.0, 50.0, 0.0])
        core = pts[4:14]
        for cut in errors:
            monkeypatch.setattr(pipeline, "SHORT_CORE_POINTS", cut)
            fit = pipeline._refit(core, pts, 0.1)
            assert fit is not None
            errors[cut].append(_angle_deg(fit[1], z))
    for q in (50, 90):
        assert np.percentile(errors[12], q) < np.percentile(errors[0], q), q


def test_the_rows_are_looked_for_when_the_features_find_no_candidate(monkeypatch) -> None:
    """Two sparse posts over dense ground, the features' candidates taken
    away: the posts are still found (every point is free), upright and full
    length; the ground stays clutter.  (The posts start 0.6 m up: a row
    whose walk steps onto the surface it stands on is refitted into that
    surface and dropped with it when no candidate holds the surface; leaving
    a row's non-linear end points out cost the 10 cm Warren 0.007 recall.)"""
    rng = np.random.default_rng(0)
    g = np.mgrid[0:6:0.05, 0:6:0.05].reshape(2, -1).T
    ground = np.column_stack([g, np.zeros(len(g))]) + rng.normal(0, 0.003, (len(g), 3))
    z = np.arange(0.6, 3.05, 0.2)
    posts = [
        np.column_stack([np.full(len(z), x), np.full(len(z), y), z])
        + rng.normal(0, 0.01, (len(z), 3))
        for x, y in ((1.0, 1.0), (4.0, 4.0))
    ]
    origin = np.array([5e5, 5e6, 100.0])
    pts = np.vstack([ground, *posts]) + origin
    monkeypatch.setattr(pipeline, "candidates_from_regions", lambda *a, **k: [])
    # two posts meeting nothing: kept down to the former 2 m lone length
    # (the default at this 5 cm ground's spacing is 2.8 m, 60 spacings)
    model = model_structure(pts, params=StructureParams(min_free_length_m=2.0))
    assert len(model.members) == 2
    for m in model.members:
        axis = m.axis - origin
        assert np.degrees(np.arccos(abs(m.direction[2]))) < 2.0
        assert m.length_m >= 2.2
        assert min(np.linalg.norm(axis[0, :2] - p) for p in ((1.0, 1.0), (4.0, 4.0))) < 0.05
    monkeypatch.setattr(pipeline, "SPARSE_ROWS", False)
    assert model_structure(pts, params=StructureParams(min_free_length_m=2.0)).members == []


def _strip(origin: np.ndarray, width: float, length: float, step: float, rng) -> np.ndarray:
    """A web seen at 10 cm: two columns of points ``width`` apart along z."""
    z = np.arange(0.0, length + 1e-9, step)
    cols = [np.column_stack([np.full_like(z, x), np.zeros_like(z), z]) for x in (0.0, width)]
    pts = np.vstack(cols)
    return origin + pts + rng.normal(scale=0.05 * SPACING, size=pts.shape)


def test_a_web_two_points_wide_seeds_rows(monkeypatch) -> None:
    """A 1.2 m channel post seen at 10 cm as two columns 0.15 m apart: the
    eight nearest neighbours of a point span 0.4 × 0.15 m, (λ1 − λ2)/λ1 ≈
    0.7: seeds at a linearity of 0.6, none at 0.8 (the 10 cm Pratt posts of
    seeds 12 and 14)."""
    origin = np.array([300.0, 200.0, 10.0])
    pts = _strip(origin, 0.15, 1.2, SPACING, np.random.default_rng(0))
    rows = sparse.sparse_rows(pts, np.ones(len(pts), bool), SPACING, 0.7)
    assert rows, "no row"
    for c in rows:
        assert abs(float(c.direction[2])) >= np.cos(np.radians(3.0))
        assert c.length >= 1.1
    monkeypatch.setattr(sparse, "SPARSE_LINEARITY", 0.8)
    assert sparse.sparse_rows(pts, np.ones(len(pts), bool), SPACING, 0.7) == []


def test_a_rejected_row_leaves_its_points_to_the_seeds_after_it(monkeypatch) -> None:
    """Pratt seeds 6 and 14 at 10 cm: every member is found.  Retiring a
    rejected row's points with it (walks across a post from off it, too
    short or on a plane, took its points a few at a time) loses a post in
    seeds 4, 6 and 12: recall 0.92 → 0.77, 1.0 → 0.89, 0.84 → 0.68."""
    for seed in (6, 14):
        recall, precision = _scores("pratt", seed)
        assert recall == 1.0 and precision >= 0.9, (seed, recall, precision)
    # the bridging rows walk the points left free again and take the lost
    # post of seed 6 back between its chords: the first walk is measured
    # without them, both ways
    monkeypatch.setattr(pipeline, "BRIDGE_ROWS", False)
    kept = {seed: _scores("pratt", seed)[0] for seed in (4, 6, 12)}
    monkeypatch.setattr(sparse, "RETIRE_REJECTED", True)
    for seed in (4, 6, 12):
        assert _scores("pratt", seed)[0] < kept[seed] - 0.1, (seed, kept[seed])
