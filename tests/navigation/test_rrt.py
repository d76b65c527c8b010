"""Per-edge RRT-Connect in (x, y, yaw) with PIBC validity, and smoothing."""

from __future__ import annotations

import numpy as np
import shapely

from planners.navigation.pibc import BoundarySet, footprint_points, poses_valid, project_footprint
from planners.navigation.rrt import EdgePlanner, corridor_sampler, settle_pose, wrap

from ._shared import bar_boundaries

# An L of two 0.10 m wide bars meeting in a 0.10 m corner square.
RECTS = [((0.0, -0.05), (1.0, 0.05)), ((-0.05, 0.05), (0.05, 1.0)), ((-0.05, -0.05), (0.05, 0.05))]
FOOT = footprint_points(0.12, 0.03, spacing_m=0.02)


def _boundaries() -> tuple[BoundarySet, shapely.Geometry]:
    union = shapely.union_all([shapely.box(x0, y0, x1, y1) for (x0, y0), (x1, y1) in RECTS])
    return BoundarySet(*bar_boundaries(RECTS)), union.buffer(1.01e-3)


def _on_steel(poses: np.ndarray, union: shapely.Geometry) -> bool:
    pts = project_footprint(poses, FOOT).reshape(-1, 2)
    return bool(shapely.contains_xy(union, pts[:, 0], pts[:, 1]).all())


def _plan(seed: int):
    bset, _ = _boundaries()

    def valid(p: np.ndarray) -> np.ndarray:
        return poses_valid(p, FOOT, bset)

    planner = EdgePlanner(valid, yaw_radius_m=0.06, step_m=0.05, resolution_m=0.005)
    start = np.array([0.8, 0.0, np.pi])  # on the x bar, facing the corner
    goal = np.array([0.0, 0.8, np.pi / 2])  # on the y bar, facing away
    rng = np.random.default_rng(seed)
    sampler = corridor_sampler(
        np.array([0.8, 0.0]), np.array([0.0, 0.8]), rng, lateral_sigma_m=0.03, margin_m=0.1
    )
    path, iters = planner.plan(start, goal, sampler)
    return planner, path, iters, rng


def test_turns_the_corner_on_steel() -> None:
    planner, path, iters, rng = _plan(0)
    assert path is not None, "no path"
    assert iters > 0  # the straight motion leaves the steel
    _, union = _boundaries()
    dense = planner.densify(planner.shortcut(path, rng))
    assert np.allclose(dense[0], [0.8, 0.0, np.pi]) and np.allclose(
        dense[-1], [0.0, 0.8, np.pi / 2]
    )
    assert _on_steel(dense, union)  # exact check, independent of PIBC
    steps = planner.dist(dense[:-1], dense[1:])
    assert steps.max() <= 0.005 + 1e-9


def test_shortcut_keeps_validity_and_never_lengthens() -> None:
    planner, path, _, rng = _plan(1)
    assert path is not None
    dense = planner.densify(path)
    short = planner.densify(planner.shortcut(path, rng))
    assert (
        planner.dist(short[:-1], short[1:]).sum()
        <= planner.dist(dense[:-1], dense[1:]).sum() + 1e-9
    )
    assert np.all(planner.valid(short))


def test_deterministic_for_a_seed() -> None:
    _, a, _, _ = _plan(5)
    _, b, _, _ = _plan(5)
    assert a is not None and np.array_equal(a, b)


def test_infeasible_returns_none() -> None:
    bset, _ = _boundaries()
    wide = footprint_points(0.12, 0.14)  # wider than the bars

    def valid(p: np.ndarray) -> np.ndarray:
        return poses_valid(p, wide, bset)

    planner = EdgePlanner(valid, yaw_radius_m=0.06, max_iterations=50)
    rng = np.random.default_rng(0)
    sampler = corridor_sampler(np.zeros(2), np.ones(2), rng, lateral_sigma_m=0.03, margin_m=0.1)
    path, iters = planner.plan(np.array([0.5, 0.0, 0.0]), np.array([0.0, 0.5, 0.0]), sampler)
    assert path is None and iters == 50
    assert settle_pose(np.array([0.5, 0.0]), np.array([0.9, 0.0]), 0.0, valid) is None


def test_settle_pose_slides_in_from_a_bar_end() -> None:
    bset, _ = _boundaries()

    def valid(p: np.ndarray) -> np.ndarray:
        return poses_valid(p, FOOT, bset)

    pose = settle_pose(np.array([1.0, 0.0]), np.array([0.5, 0.0]), np.pi, valid)
    assert pose is not None
    # The footprint's half length (6 cm) must stay on the bar: x ≤ 1.0 - 0.06.
    assert 0.93 <= pose[0] <= 0.941 and abs(wrap(pose[2] - np.pi)) < 1e-9
