"""The tube query along a line (planners.structure.assign.near_line) against brute force."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

import planners.structure.assign as assign
from planners.structure.assign import near_line


def _tube(
    pts: np.ndarray, c: np.ndarray, d: np.ndarray, lo: float, hi: float, r: float
) -> set[int]:
    """Brute force: the points within 2 r of the line whose parameter lies in [lo, hi]."""
    t = (pts - c) @ d
    perp = np.linalg.norm(pts - c - np.outer(t, d), axis=1)
    return set(np.flatnonzero((t >= lo) & (t <= hi) & (perp <= 2 * r)).tolist())


@settings(max_examples=60, deadline=None)
@given(
    st.integers(0, 10_000),
    st.floats(0.01, 0.5),
    st.floats(0.0, 6.0),
    st.sampled_from([0.0, 1e9]),
)
def test_near_line_holds_the_tube_and_reports_exact_t_and_perp(
    seed: int, r: float, length: float, one_ball: float
) -> None:
    """Every point of the tube is returned (one ball for a short stretch,
    a ball a sample for a long one: both forced here), indices ascending and
    distinct, with their exact parameter and distance."""
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-3, 3, (800, 3))
    d = rng.normal(size=3)
    d /= np.linalg.norm(d)
    c = rng.uniform(-1, 1, 3)
    # a row of points along the line so that the tube is never empty
    pts = np.vstack([pts, c + np.outer(rng.uniform(-3, 3, 50), d) + rng.normal(0, r, (50, 3))])
    lo = float(rng.uniform(-3, 0))
    hi = lo + length
    saved = assign.NEAR_LINE_ONE_BALL
    try:
        assign.NEAR_LINE_ONE_BALL = one_ball
        idx, t, perp = near_line(pts, cKDTree(pts), c, d, lo, hi, r)
    finally:
        assign.NEAR_LINE_ONE_BALL = saved
    assert np.all(np.diff(idx) > 0)
    rel = pts[idx] - c
    np.testing.assert_allclose(t, rel @ d, atol=1e-12)
    np.testing.assert_allclose(perp, np.linalg.norm(rel - np.outer(t, d), axis=1), atol=1e-12)
    got = set(idx[(t >= lo) & (t <= hi) & (perp <= 2 * r)].tolist())
    assert got == _tube(pts, c, d, lo, hi, r)
