"""Base placement for blasting a surface: the chosen base
reaches every target by an independent check (the arm placed there, full
pose IK, then forward kinematics back to the flange pose), stands clear,
and a region nothing reaches from is refused naming the best found."""

from __future__ import annotations

import numpy as np
import pytest

from planners.blasting import scenes
from planners.blasting.base_placement import BaseLimits, place_base, surface_targets
from planners.blasting.surface import Surface
from planners.errors import InvalidInputError, UnreachableError
from robots import load_robot

STANDOFF = 0.4


@pytest.fixture(scope="module")
def arm():
    return load_robot("denso_vm6083")


def _reaches_all(arm, surface: Surface, base: np.ndarray) -> bool:
    robot = arm.with_base(
        np.block([[np.eye(3), base[:, None]], [np.zeros((1, 3)), np.ones((1, 1))]])
    )
    n = surface.normal / np.linalg.norm(surface.normal)
    for t in surface_targets(surface):
        z = -n
        x = np.cross([0.0, 0.0, 1.0] if abs(z[2]) < 0.9 else [1.0, 0.0, 0.0], z)
        x /= np.linalg.norm(x)
        T = np.eye(4)
        T[:3, :3] = np.column_stack([x, np.cross(z, x), z])
        T[:3, 3] = t + STANDOFF * n
        q = robot.ik(T)
        if q is None or not np.allclose(robot.fk(q), T, atol=1e-6):
            return False
    return True


@pytest.mark.parametrize("k", [1, 2, 3])
def test_the_base_found_reaches_every_target_of_the_seed_surfaces(arm, k) -> None:
    surface = scenes.bridge_surface(k)
    boxes = list(scenes.bridge_obstacles())
    got = place_base(surface, arm, standoff_m=STANDOFF, boxes=boxes)
    assert _reaches_all(arm, surface, got.base_m)
    assert (got.base_m - surface.origin) @ surface.normal > 0
    for b in boxes:  # 0.3 m of free room around the base
        gap = np.maximum(np.abs(got.base_m - b.center) - b.half, 0.0)
        assert np.linalg.norm(gap) >= 0.3 - 1e-9
    assert 1 <= got.reaching <= got.standing <= got.candidates and got.margin_m >= 0


def test_obstacle_points_keep_the_base_clear(arm) -> None:
    surface = scenes.bridge_surface(1)
    free = place_base(surface, arm, standoff_m=STANDOFF)
    # a scan point right where the free search stood: it must stand elsewhere
    pts = free.base_m[None, :] + np.array([[0.0, 0.0, 0.05]])
    moved = place_base(surface, arm, standoff_m=STANDOFF, obstacle_points=pts)
    assert np.linalg.norm(moved.base_m - pts[0]) >= 0.3 - 1e-9
    assert _reaches_all(arm, surface, moved.base_m)


def test_a_region_out_of_reach_is_refused_naming_the_best(arm) -> None:
    surface = scenes.bridge_surface(2)
    far = BaseLimits(lo_m=(5.0, 5.0, 5.0), hi_m=(6.0, 6.0, 6.0))
    with pytest.raises(UnreachableError, match=r"no base position reaches the whole surface.*0 of"):
        place_base(surface, arm, standoff_m=STANDOFF, limits=far)
    # a region in reach of only part of a long surface: named, not chosen
    long = Surface(np.array([0.0, 0.5, 1.5]), np.array([1.0, 0.0, 0.0]),
                   np.array([[-3.0, -0.2], [3.0, -0.2], [3.0, 0.2], [-3.0, 0.2]]))  # fmt: skip
    with pytest.raises(UnreachableError, match=r"the best reaches [1-9]\d* of"):
        place_base(long, arm, standoff_m=STANDOFF)


def test_bad_limits_are_refused() -> None:
    for kw in (
        {"lo_m": (0, 0, 0)},
        {"lo_m": (0, 0, 0), "hi_m": (-1, 0, 0)},
        {"step_m": 0.0},
        {"clearance_m": -1.0},
    ):
        with pytest.raises(InvalidInputError):
            BaseLimits(**kw)  # type: ignore[arg-type]
