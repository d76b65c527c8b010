"""Cached pipeline runs and synthetic boundaries shared by the navigation
tests (keeps the suite fast)."""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from planners.navigation import NavigationParams, NavigationResult, plan_navigation
from planners.navigation.boundaries import star_polygon
from planners.navigation.synthetic import SyntheticStructure, make_structure

#: Generator seeds the unit tests use per shape (the benchmark runs 20).
TEST_SEEDS = (0, 1, 2)

#: A small inspection crawler that fits the 60–150 mm synthetic flanges; the
#: ARA's own footprint (0.68 × 0.16 m) fits none of them.
SMALL_ROBOT = {
    "footprint_length_m": 0.08,
    "footprint_width_m": 0.025,
    "footprint_center_x_m": 0.0,
}


@lru_cache(maxsize=64)
def structure(shape: str, seed: int, n_points: int = 20_000) -> SyntheticStructure:
    return make_structure(shape, seed, n_points=n_points)


@lru_cache(maxsize=64)
def route_only(shape: str, seed: int, segmentation: str = "default") -> NavigationResult:
    """The pipeline up to the route (no per-edge paths)."""
    st = structure(shape, seed)
    return plan_navigation(
        st.points, params=NavigationParams(segmentation=segmentation, plan_paths=False)
    )


@lru_cache(maxsize=16)
def with_paths(shape: str, seed: int) -> NavigationResult:
    st = structure(shape, seed)
    return plan_navigation(st.points, params=NavigationParams(**SMALL_ROBOT))


def bar_boundaries(rects) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Centres and star-polygon boundaries of axis-aligned bars ((x0, y0), (x1, y1)),
    each grown by 1 mm so neighbours overlap, as the pipeline's boundaries
    overlap across borders."""
    polys, centres = [], []
    for (x0, y0), (x1, y1) in rects:
        c = np.array([(x0 + x1) / 2, (y0 + y1) / 2])
        pts = np.array(
            [
                [x0 - 1e-3, y0 - 1e-3],
                [x1 + 1e-3, y0 - 1e-3],
                [x1 + 1e-3, y1 + 1e-3],
                [x0 - 1e-3, y1 + 1e-3],
            ]
        )
        polys.append(star_polygon(pts, c))
        centres.append(c)
    return centres, polys
