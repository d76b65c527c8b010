"""planners.navigation.footprint_checks against a closed-form answer: on one
straight steel strip, a heading-aligned rectangle driven along the strip stays
on steel exactly when its extent lies inside the strip's."""

from __future__ import annotations

import numpy as np

from planners.navigation.footprint_checks import (
    Footprint,
    alg6_spacing_m,
    bars_covered,
    poses_on_steel,
    to_plane,
)

STRIP = np.array([[0.0, -0.05], [1.0, -0.05], [1.0, 0.05], [0.0, 0.05]])
FOOT = Footprint(length_m=0.08, width_m=0.025)


def _inside_strip(x: float, y: float) -> bool:
    hx, hy = FOOT.length_m / 2, FOOT.width_m / 2
    return bool(x - hx >= 0.0 and x + hx <= 1.0 and abs(y) + hy <= 0.05)


def test_straight_drives_match_the_closed_form() -> None:
    rng = np.random.default_rng(3)
    lists, expected = [], []
    for _ in range(12):
        y = rng.uniform(-0.06, 0.06)
        xs = np.sort(rng.uniform(-0.1, 1.1, size=6))
        # keep every extent ≥ 1 mm from the strip's edges: the test is exact,
        # the closing of steel_union may move an edge by far less than that
        ok_y = abs(abs(y) + FOOT.width_m / 2 - 0.05) > 1e-3
        xs = xs[
            (np.abs(xs - FOOT.length_m / 2) > 1e-3) & (np.abs(xs + FOOT.length_m / 2 - 1.0) > 1e-3)
        ]
        if not ok_y or len(xs) == 0:
            continue
        poses = np.column_stack([xs, np.full(len(xs), y), np.zeros(len(xs))])
        lists.append(poses)
        # pose k is on steel when it and the box swept from pose k-1 are: on a
        # straight drive both ends inside means the whole box is inside
        inside = [_inside_strip(x, y) for x in xs]
        expected += [inside[0]] + [inside[k] and inside[k - 1] for k in range(1, len(xs))]
    report = poses_on_steel(lists, [STRIP], FOOT)
    assert report.n_poses == len(expected) > 20
    assert report.on_steel.tolist() == expected
    assert report.fraction == np.mean(expected)
    first = int(np.argmin(expected))
    assert np.array_equal(report.first_off, np.vstack(lists)[first])


def test_each_edge_path_is_swept_on_its_own() -> None:
    """Two strips with a gap: a drive on each is on steel; stacked into one
    drive, the step across the gap would not be."""
    left = STRIP.copy()
    right = STRIP + [1.5, 0.0]
    a = np.array([[0.2, 0.0, 0.0], [0.8, 0.0, 0.0]])
    b = np.array([[1.7, 0.0, 0.0], [2.3, 0.0, 0.0]])
    report = poses_on_steel([a, b], [left, right], FOOT)
    assert report.on_steel.all() and report.first_off is None
    joined = poses_on_steel([np.vstack([a, b])], [left, right], FOOT)
    assert joined.on_steel.tolist() == [True, True, False, True]


def test_a_turn_in_place_is_checked_over_its_sweep() -> None:
    """Turning 90° in place at the strip's middle.  The check is conservative
    (hull of both rectangles grown by the corner arc's sagitta), so a
    rectangle whose swept area, hull and sagitta, stays inside the 0.10 m
    strip passes, and one that sticks out across it at 90° fails."""
    turn = np.array([[0.5, 0.0, 0.0], [0.5, 0.0, np.pi / 2]])
    small = Footprint(length_m=0.06, width_m=0.02)
    r = np.hypot(0.03, 0.01)
    assert 0.03 + r * (1 - np.cos(np.pi / 4)) < 0.05  # hull y extent + sagitta
    assert poses_on_steel([turn], [STRIP], small).on_steel.all()
    long = Footprint(length_m=0.12, width_m=0.025)  # 0.12 m across 0.10 m: off
    assert poses_on_steel([turn], [STRIP], long).on_steel.tolist() == [True, False]


def test_nothing_driven_counts_as_on_steel() -> None:
    report = poses_on_steel([np.zeros((0, 3))], [STRIP], FOOT)
    assert report.n_poses == 0 and report.fraction == 1.0 and report.first_off is None


def test_to_plane_inverts_the_lift() -> None:
    rng = np.random.default_rng(0)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    origin, e1, e2 = rng.normal(size=3), q[:, 0], q[:, 1]
    uv = rng.uniform(-2, 2, size=(50, 2))
    world = origin + uv[:, :1] * e1 + uv[:, 1:] * e2 + 0.3 * q[:, 2]  # off-plane part drops
    assert np.allclose(to_plane(world, origin, e1, e2), uv)


def test_alg6_spacing_and_bar_coverage() -> None:
    assert alg6_spacing_m(0.08, 0.025) == 0.01  # the contact patch: every centimetre
    assert alg6_spacing_m(0.68, 0.16) == 0.04  # the body: capped at 4 cm
    assert alg6_spacing_m(0.2, 0.1) == 0.025  # four across the short side
    assert bars_covered([1, 2, 3], [3, 3, 1, 7]) == 2
