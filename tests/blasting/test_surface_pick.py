"""planners.blasting.surface_pick on a cloud whose planes are known: a large
horizontal plate and a smaller vertical one, apart."""

from __future__ import annotations

import numpy as np
import pytest

from planners.blasting.surface import Surface
from planners.blasting.surface_pick import nozzle_tip, outline_world, pick_surface
from planners.errors import InvalidInputError, NoPlaneError

BASE = np.array([0.5, 0.4, 1.0])  # above the plate, on the +x side of the wall


def _cloud(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(points, truth) with truth 0 = plate z = 0 over [0, 1] × [0, 0.8],
    1 = wall x = 1.5 over y ∈ [0, 0.4], z ∈ [0.2, 0.5]; 1 mm noise."""
    rng = np.random.default_rng(seed)
    u, v = np.meshgrid(np.arange(0, 1.0001, 0.02), np.arange(0, 0.8001, 0.02))
    plate = np.column_stack([u.ravel(), v.ravel(), np.zeros(u.size)])
    y, z = np.meshgrid(np.arange(0, 0.4001, 0.02), np.arange(0.2, 0.5001, 0.02))
    wall = np.column_stack([np.full(y.size, 1.5), y.ravel(), z.ravel()])
    pts = np.vstack([plate, wall])
    pts = pts + rng.normal(scale=0.001, size=pts.shape)
    return pts, np.r_[np.zeros(len(plate), int), np.ones(len(wall), int)]


def _covers(obstacles: np.ndarray, points: np.ndarray) -> None:
    """Every point has an obstacle point in its 2 cm voxel's reach (brute force)."""
    d = np.linalg.norm(points[:, None, :] - obstacles[None, :, :], axis=2).min(axis=1)
    assert d.max() < 0.02 * np.sqrt(3)


def test_index_0_is_the_largest_plane_and_the_rest_are_obstacles() -> None:
    pts, truth = _cloud()
    got = pick_surface(pts, plane_index=0, threshold_m=0.01, toward=BASE)
    assert [pl.points for pl in got.planes] == sorted(
        (pl.points for pl in got.planes), reverse=True
    )
    assert abs(abs(got.surface.normal[2]) - 1.0) < 1e-3
    assert got.surface.normal[2] > 0  # toward the base above the plate
    assert got.surface.area == pytest.approx(0.8, rel=0.05)
    assert got.obstacle_points is not None and len(got.obstacle_points) > 0
    # the obstacles are the whole wall, plus the few plate points the facing
    # and outlier filters took off the patch (its rim), never the patch itself
    _covers(got.obstacle_points, pts[truth == 1])
    on_plate = np.abs(got.obstacle_points[:, 2]) < 0.005
    assert on_plate.sum() < 0.1 * np.sum(truth == 0)
    # every cloud point is labelled with its own plane
    assert np.mean(got.cloud_label == truth) > 0.98


def test_index_1_picks_the_wall_facing_the_base() -> None:
    pts, truth = _cloud()
    got = pick_surface(pts, plane_index=1, threshold_m=0.01, toward=BASE)
    assert abs(abs(got.surface.normal[0]) - 1.0) < 1e-3
    assert got.surface.normal[0] < 0  # the base is at x = 0.5 < 1.5
    assert got.surface.area == pytest.approx(0.4 * 0.3, rel=0.08)
    assert got.obstacle_points is not None
    _covers(got.obstacle_points, pts[truth == 0])


def test_no_obstacles_when_asked_and_errors() -> None:
    pts, _ = _cloud()
    got = pick_surface(pts, plane_index=0, threshold_m=0.01, toward=BASE, obstacles_from_rest=False)
    assert got.obstacle_points is None
    with pytest.raises(InvalidInputError, match="out of range"):
        pick_surface(pts, plane_index=7, threshold_m=0.01, toward=BASE)
    scatter = np.random.default_rng(1).uniform(-1, 1, size=(80, 3))
    with pytest.raises(NoPlaneError):
        pick_surface(scatter, plane_index=0, threshold_m=0.01, toward=BASE)


def test_outline_world_lies_on_the_plane_at_the_boundary() -> None:
    boundary = np.array([[0.0, 0.0], [0.6, 0.0], [0.6, 0.4], [0.0, 0.4]])
    hole = np.array([[0.2, 0.1], [0.3, 0.1], [0.3, 0.2], [0.2, 0.2]])
    origin, normal = np.array([1.0, 2.0, 0.5]), np.array([0.0, 1.0, 1.0])
    s = Surface(origin, normal, boundary, holes=[hole])
    ring, holes = outline_world(s)
    n = normal / np.linalg.norm(normal)
    assert np.allclose((ring - origin) @ n, 0.0) and len(holes) == 1
    # brute: every corner of the given boundary is a vertex of the ring
    uv = np.column_stack([(ring - s.origin) @ s.x_axis, (ring - s.origin) @ s.y_axis])
    for corner in boundary:
        assert np.min(np.linalg.norm(uv - corner, axis=1)) < 1e-9
    huv = np.column_stack([(holes[0] - s.origin) @ s.x_axis, (holes[0] - s.origin) @ s.y_axis])
    assert huv.min(axis=0) == pytest.approx([0.2, 0.1]) and huv.max(axis=0) == pytest.approx(
        [0.3, 0.2]
    )


def test_nozzle_tip_is_along_the_flange_z_axis() -> None:
    F = np.tile(np.eye(4), (2, 1, 1))
    F[1, :3, :3] = [[0, 0, 1], [0, 1, 0], [-1, 0, 0]]  # its z axis (column 2) is world +x
    F[:, :3, 3] = [[1.0, 2.0, 3.0], [0.0, 0.0, 0.0]]
    tip, axis = nozzle_tip(F, 0.1)
    assert np.allclose(axis, [[0, 0, 1], [1, 0, 0]])
    assert np.allclose(tip, [[1.0, 2.0, 3.1], [0.1, 0.0, 0.0]])
