"""planners.switching.jump_checks against brute-force loops and hand cases."""

from __future__ import annotations

import numpy as np
import shapely

from planners.switching.jump_checks import foot_inside_surface, joint_limit_excess, speed_ratio


def test_joint_limit_excess_matches_a_loop() -> None:
    rng = np.random.default_rng(0)
    q = rng.uniform(-3, 3, size=(40, 6))
    limits = np.column_stack([rng.uniform(-3, -1, 6), rng.uniform(1, 3, 6)])
    worst = 0.0
    for row in q:
        for j, v in enumerate(row):
            worst = max(worst, limits[j, 0] - v, v - limits[j, 1])
    assert joint_limit_excess(q, limits) == worst > 0
    assert joint_limit_excess(np.clip(q, limits[:, 0], limits[:, 1]), limits) == 0.0


def test_speed_ratio_matches_a_loop() -> None:
    rng = np.random.default_rng(1)
    q = np.cumsum(rng.normal(size=(30, 4)), axis=0)
    t = np.cumsum(rng.uniform(0.05, 0.5, size=30))
    vmax = rng.uniform(0.5, 2.0, size=4)
    worst = max(
        abs(q[k + 1, j] - q[k, j]) / (t[k + 1] - t[k]) / vmax[j]
        for k in range(29)
        for j in range(4)
    )
    assert np.isclose(speed_ratio(q, t, vmax), worst)
    assert speed_ratio(q[:1], t[:1], vmax) == 0.0


def test_foot_inside_surface() -> None:
    origin, ex, ey = np.zeros(3), np.array([1.0, 0, 0]), np.array([0, 1.0, 0])
    hull = shapely.box(0.0, 0.0, 1.0, 1.0)
    surface = (origin, ex, ey, hull)
    foot = (0.2, 0.1)

    def at(x: float, y: float, yaw: float = 0.0) -> np.ndarray:
        T = np.eye(4)
        c, s = np.cos(yaw), np.sin(yaw)
        T[:2, :2] = [[c, -s], [s, c]]
        T[:3, 3] = [x, y, 0.3]  # height above the plane does not matter
        return T

    assert foot_inside_surface(at(0.5, 0.5), foot, surface, 0.0)
    assert not foot_inside_surface(at(0.92, 0.5), foot, surface, 0.0)  # 0.02 m over the edge
    assert foot_inside_surface(at(0.92, 0.5), foot, surface, 0.025)  # within the tolerance
    # turned 90°: the 0.2 m length runs along y, so x = 0.92 fits (0.05 half-width)
    assert foot_inside_surface(at(0.92, 0.5, np.pi / 2), foot, surface, 0.0)
