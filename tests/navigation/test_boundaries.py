"""Bar boundaries (Alg. 1 slices): a dropout hole at a flange edge must not
leave a spike narrower than the steel, and the fill must not grow the bar."""

from __future__ import annotations

import numpy as np
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from planners.navigation.boundaries import _bar_polygon


def _bar(
    rng: np.random.Generator, length: float, width: float, hole: tuple[float, float, float]
) -> np.ndarray:
    """Points of a bar along x with a dropout at its upper edge: ``hole`` =
    (start x, length along the bar, depth across it)."""
    pts = rng.uniform([0, -width / 2], [length, width / 2], size=(4000, 2))
    pts = np.vstack([pts, [[0.0, 0.0], [length, 0.0]]])  # slices start at x = 0
    x0, h, depth = hole
    out = (pts[:, 0] >= x0) & (pts[:, 0] <= x0 + h) & (pts[:, 1] > width / 2 - depth)
    return pts[~out]


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    width=st.floats(0.06, 0.15),
    where=st.floats(0.2, 0.8),
    frac=st.floats(0.3, 0.9),
)
def test_edge_hole_shorter_than_a_slice_is_filled(seed, width, where, frac) -> None:
    """A hole reaching ``frac`` of the way across the flange and 2.1 cm
    along it (so it can empty the top of one whole 2 cm slice): the boundary
    keeps (nearly) the full width there."""
    rng = np.random.default_rng(seed)
    length = 1.0
    pts = _bar(rng, length, width, (where * length, 0.021, frac * width))
    centre = pts.mean(axis=0)
    poly = shapely.Polygon(_bar_polygon(pts, centre, np.array([1.0, 0.0]), 0.02))
    assert poly.is_valid
    # every cross-section away from the ends spans the flange minus sampling gaps
    for x in np.linspace(0.05, 0.95, 37):
        cut = poly.intersection(shapely.LineString([(x, -1), (x, 1)]))
        assert cut.length >= width - 0.012, (x, cut.length, width)
    # and the fill never leaves the steel's own extent
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    xy = np.asarray(poly.exterior.coords)
    assert np.all(xy >= lo - 1e-12) and np.all(xy <= hi + 1e-12)


def test_without_the_fill_the_hole_is_a_spike() -> None:
    """The same bar with the fill off: the hole cuts the section (the test
    above can fail)."""
    rng = np.random.default_rng(3)
    width = 0.065
    pts = _bar(rng, 1.0, width, (0.4995, 0.021, 0.7 * width))  # empties slice [0.50, 0.52)
    poly0 = shapely.Polygon(_bar_polygon(pts, pts.mean(axis=0), np.array([1.0, 0.0]), 0.02, 0))
    poly1 = shapely.Polygon(_bar_polygon(pts, pts.mean(axis=0), np.array([1.0, 0.0]), 0.02, 1))

    def narrowest(p: shapely.Polygon) -> float:
        return min(
            p.intersection(shapely.LineString([(x, -1), (x, 1)])).length
            for x in np.linspace(0.45, 0.55, 41)
        )

    assert narrowest(poly0) < width - 0.012 <= narrowest(poly1)
