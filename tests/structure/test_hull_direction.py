"""The direction of a member of a few dozen points from its projected convex
hull (planners.structure.direction.hull_direction), and what it does to a
10 cm scan's posts."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from planners.structure import pipeline
from planners.structure.direction import RINGS_DEG, hull_direction, section_frames
from planners.structure.lines import fit_line
from tests.structure.test_direction import box_section_points
from tests.structure.test_sparse_rows import _scores


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    c = abs(float(a @ b)) / float(np.linalg.norm(a) * np.linalg.norm(b))
    return float(np.degrees(np.arccos(min(1.0, c))))


def _sparse_web_then_flange(rng: np.random.Generator, n: int, truth: np.ndarray) -> np.ndarray:
    """``n`` points of a 1.5 m channel along ``truth``, far from the origin:
    its web (0.2 m) seen over the first half, its flange (80 mm) over the
    second, 5 mm noise — a 10 cm scan's view of a post."""
    half = n // 2
    web = np.column_stack(
        [rng.uniform(0, 0.75, half), np.zeros(half), rng.uniform(-0.1, 0.1, half)]
    )
    flange = np.column_stack(
        [rng.uniform(0.75, 1.5, n - half), rng.uniform(0, 0.08, n - half), np.full(n - half, -0.1)]
    )
    local = np.vstack([web, flange]) + rng.normal(0, 0.005, (n, 3))
    (u,), (v,) = section_frames(truth[None])
    return local @ np.column_stack([truth, u, v]).T + np.array([5e5, 5e6, 100.0])


def test_sparse_members_get_surer_directions_than_least_squares() -> None:
    """200 such members of 30 points in random directions: the least-squares
    line follows the web at one end and the flange at the other (median
    6.5° off); the hull's direction halves the median error and does not
    worsen the worst tenth."""
    ls, hull = [], []
    for seed in range(200):
        rng = np.random.default_rng(seed)
        truth = rng.normal(size=3)
        truth /= np.linalg.norm(truth)
        pts = _sparse_web_then_flange(rng, 30, truth)
        _, d0, _, _, _ = fit_line(pts)
        ls.append(_angle_deg(d0, truth))
        hull.append(_angle_deg(hull_direction(pts, d0), truth))
    assert np.median(ls) > 5.0  # the case is real
    assert np.median(hull) < 0.6 * np.median(ls), (np.median(hull), np.median(ls))
    assert np.percentile(hull, 90) <= np.percentile(ls, 90)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 10_000), st.floats(0.0, 10.0))
def test_never_leaves_the_cone_and_keeps_a_true_axis(seed: int, tilt: float) -> None:
    """From a start ``tilt`` degrees off the axis of a box section seen by 50
    points on its four sides: the result lies within the search cone of the
    start, is never further from the truth than the start (beyond the fine
    step), and keeps the start's sense."""
    rng = np.random.default_rng(seed)
    pts = box_section_points(rng, 50, 1.5, 0.003)
    x = np.array([1.0, 0.0, 0.0])
    a = np.radians(tilt)
    start = np.cos(a) * x + np.sin(a) * np.array([0.0, np.cos(seed), np.sin(seed)])
    d = hull_direction(pts, start)
    assert _angle_deg(d, start) <= RINGS_DEG[-1] + 1.5
    assert _angle_deg(d, x) <= max(tilt, 1.5) + 0.25
    assert float(d @ start) > 0


def test_few_or_collinear_points_keep_the_first_estimate() -> None:
    """Three points have no hull to shrink; points on a line project to a
    point or a segment, area 0 along any direction: nothing can gain."""
    d0 = np.array([0.0, 0.6, 0.8])
    three = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    assert _angle_deg(hull_direction(three, d0), d0) == 0.0
    line = np.outer(np.linspace(0, 2, 20), [1.0, 2.0, 2.0]) / 3.0
    assert _angle_deg(hull_direction(line, d0), d0) == 0.0


def test_10_cm_pratt_posts_found_with_the_hull_direction(monkeypatch) -> None:
    """Pratt seeds 4 and 12 at 10 cm, whose channel posts are rows of 13–25
    points: with the hull direction recall is 0.92 and 0.84 and precision
    ≥ 0.94; with the least-squares line only, posts lean past 5° and
    recall is 0.85 and 0.74."""
    with_hull = {seed: _scores("pratt", seed) for seed in (4, 12)}
    assert with_hull[4][0] >= 0.92 and with_hull[12][0] >= 0.84, with_hull
    assert min(p for _, p in with_hull.values()) >= 0.94, with_hull
    monkeypatch.setattr(pipeline, "HULL_DIRECTION", False)
    for seed in (4, 12):
        assert _scores("pratt", seed)[0] < with_hull[seed][0] - 0.05, seed
