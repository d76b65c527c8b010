"""Cached pipeline runs shared by the navigation tests (keeps the suite fast)."""

from __future__ import annotations

from functools import lru_cache

from planners.navigation import NavigationParams, NavigationResult, plan_navigation
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
