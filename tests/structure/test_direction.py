"""The compact-direction search (planners.structure.direction)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

import planners.structure.direction as direction
from planners.structure.direction import (
    RINGS_DEG,
    _cone,
    _distinct_cells,
    compact_direction,
    occupied_cells,
    section_frames,
)
from planners.structure.lines import fit_line


def _frame(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    (u,), (v,) = section_frames(np.asarray(d, float)[None])
    return u, v


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    c = abs(float(a @ b)) / float(np.linalg.norm(a) * np.linalg.norm(b))
    return float(np.degrees(np.arccos(min(1.0, c))))


def _rotation_to(d: np.ndarray) -> np.ndarray:
    """A rotation taking x to unit ``d``."""
    u, v = _frame(d)
    return np.column_stack([d, u, v])


def _web_then_flange(rng: np.random.Generator, n: int = 3000) -> np.ndarray:
    """A 2 m channel along x seen as its web on one half and its flange on the
    other (0.3 m deep, 0.1 m wide), 2 mm noise."""
    half = n // 2
    web = np.column_stack([rng.uniform(0, 1, half), np.zeros(half), rng.uniform(-0.15, 0.15, half)])
    flange = np.column_stack([rng.uniform(1, 2, n - half), rng.uniform(0, 0.1, n - half),
                              np.full(n - half, -0.15)])  # fmt: skip
    return np.vstack([web, flange]) + rng.normal(0, 0.002, (n, 3))


def box_section_points(rng: np.random.Generator, n: int, length: float, noise: float) -> np.ndarray:
    """``n`` points on the four sides of a 0.2 m box section along x, ``length`` long."""
    side = rng.integers(0, 4, n)
    s = rng.uniform(-0.1, 0.1, n)
    yz = np.where(side[:, None] == 0, np.column_stack([s, np.full(n, 0.1)]),
         np.where(side[:, None] == 1, np.column_stack([s, np.full(n, -0.1)]),
         np.where(side[:, None] == 2, np.column_stack([np.full(n, 0.1), s]),
                  np.column_stack([np.full(n, -0.1), s]))))  # fmt: skip
    return np.column_stack([rng.uniform(0, length, n), yz]) + rng.normal(0, noise, (n, 3))


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10_000), st.floats(0.01, 0.5))
def test_occupied_cells_equals_brute_force(seed: int, cell: float) -> None:
    rng = np.random.default_rng(seed)
    rel = rng.normal(size=(300, 3)) * rng.uniform(0.1, 2, 3)
    dirs = _cone(np.array([0.0, 0.0, 1.0]), (3.0, 9.0), 5)
    dirs = np.vstack([dirs, _cone(rng.normal(size=3) / np.sqrt(3), (0.0, 5.0), 4)])
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    want = []
    for d in dirs:
        u, v = _frame(d)
        ij = np.floor(np.column_stack([rel @ u, rel @ v]) / cell).astype(np.int64)
        want.append(len(np.unique(ij, axis=0)))
    assert occupied_cells(rel, dirs, cell).tolist() == want


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10_000), st.integers(1, 40), st.integers(1, 6), st.integers(1, 200))
def test_distinct_cells_by_bitmap_and_by_sort_equal_brute_force(
    seed: int, n: int, k: int, spread: int
) -> None:
    """Both counting paths (the bitmap for small cell ranges, the sort for
    large ones) give the brute-force count of each column's distinct pairs."""
    rng = np.random.default_rng(seed)
    i = rng.integers(-spread, spread + 1, (n, k))
    j = rng.integers(-3 * spread, 1, (n, k))
    want = [
        len({(int(a), int(b)) for a, b in zip(i[:, c], j[:, c], strict=True)}) for c in range(k)
    ]
    assert _distinct_cells(i, j).tolist() == want
    saved = direction.BITMAP_CELLS_PER_POINT
    try:
        for forced in (0, 10**9):  # the sort only, then the bitmap only
            direction.BITMAP_CELLS_PER_POINT = forced
            assert _distinct_cells(i, j).tolist() == want
    finally:
        direction.BITMAP_CELLS_PER_POINT = saved


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 10_000))
def test_a_member_seen_as_web_then_flange_gets_its_axis_back(seed: int) -> None:
    """The least-squares line tilts by degrees (web at one end, flange at the
    other); the compact direction is the member's axis within the fine step."""
    rng = np.random.default_rng(seed)
    truth = rng.normal(size=3)
    truth /= np.linalg.norm(truth)
    pts = _web_then_flange(rng) @ _rotation_to(truth).T + rng.uniform(-1e3, 1e3, 3)
    _, d0, _, _, _ = fit_line(pts)
    assert _angle_deg(d0, truth) > 3.0  # the least-squares line is off
    d = compact_direction(pts, d0, 0.02)
    assert _angle_deg(d, truth) <= 1.5
    assert float(d @ d0) > 0  # the first estimate's sense is kept


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 10_000), st.floats(0.0, 10.0))
def test_never_leaves_the_cone_and_keeps_a_true_axis(seed: int, tilt: float) -> None:
    """From a start ``tilt`` degrees off a whole box section's axis: the
    result is within the search cone of the start and within the fine step of the truth."""
    rng = np.random.default_rng(seed)
    pts = box_section_points(rng, 4000, 3.0, 0.002)
    x = np.array([1.0, 0.0, 0.0])
    a = np.radians(tilt)
    start = np.cos(a) * x + np.sin(a) * np.array([0.0, np.cos(seed), np.sin(seed)])
    d = compact_direction(pts, start, 0.02)
    assert _angle_deg(d, start) <= RINGS_DEG[-1] + 1.5
    assert _angle_deg(d, x) <= 1.5


def test_a_blob_keeps_the_first_estimate() -> None:
    """Nothing collapses a ball: no direction gains the required share of cells."""
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(3000, 3))
    d0 = np.array([0.0, 0.6, 0.8])
    assert compact_direction(pts, d0, 0.2) is not None
    assert _angle_deg(compact_direction(pts, d0, 0.2), d0) == 0.0
