"""Girder geometry and the boustrophedon inspection path (seed 003 §3, Fig. 4, 9)."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from planners.errors import InfeasibleError, InvalidInputError
from planners.sbg import corner
from planners.sbg.girder import CROSSBEAM0, CROSSBEAM1, ROOF, Girder, sample_girders
from planners.sbg.path import (
    CORNER_DOWN,
    CORNER_UP,
    LANE,
    S1,
    S2,
    S3,
    TURN,
    lane_order,
    plan_path,
    turn_depth,
)
from planners.sbg.robot import ClimberParams

ROBOT = ClimberParams()


def test_girder_lanes_and_welds() -> None:
    g = Girder()  # 4 ribs at 600 mm, 300 mm top width → 3 lanes 300 mm wide
    assert g.n_lanes == 3
    assert g.lane_width_m == pytest.approx(0.3)
    assert float(g.lane_centre_y(1)) == pytest.approx(0.9)
    assert g.weld_y(1) == pytest.approx((0.75, 1.05))
    # Webs taper 300 → 180 mm over 280 mm: at 70 mm depth the rib half width is
    # 0.15 − 0.06·70/280 = 0.135 and the lane half width 0.3 − 0.135 = 0.165.
    assert float(g.lane_half_width(0.07)) == pytest.approx(0.165)


@pytest.mark.parametrize("wall", [ROOF, CROSSBEAM0, CROSSBEAM1])
def test_wall_frames_are_right_handed_and_face_inward(wall: int) -> None:
    g = Girder()
    f = g.wall(wall)
    assert np.dot(f.ex, f.ey) == 0
    centre = np.array([g.length_m / 2, 0.9, -0.4])  # a point inside the girder
    # The normal points from the wall into the free space.
    assert np.dot(centre - f.origin, f.n) > 0
    x, y = f.to_wall(f.to_world(0.3, -0.2))
    assert (float(x), float(y)) == pytest.approx((0.3, -0.2))


def test_girder_validation() -> None:
    with pytest.raises(InvalidInputError, match="n_ribs"):
        Girder(n_ribs=1).validate()
    with pytest.raises(InvalidInputError, match="rib_top_width_m"):
        Girder(rib_top_width_m=0.7).validate()
    with pytest.raises(InvalidInputError, match="length_m"):
        Girder(length_m=-1.0).validate()


def test_lane_order() -> None:
    assert lane_order(5, 0, 1) == [0, 1, 2, 3, 4]
    assert lane_order(5, 4, -1) == [4, 3, 2, 1, 0]
    assert lane_order(5, 2, 1) == [2, 3, 4, 1, 0]
    assert lane_order(5, 2, -1) == [2, 1, 0, 3, 4]


@given(st.integers(1, 7), st.data())
def test_every_lane_once(n_lanes: int, data: st.DataObject) -> None:
    start = data.draw(st.integers(0, n_lanes - 1))
    direction = data.draw(st.sampled_from([1, -1]))
    order = lane_order(n_lanes, start, direction)
    assert sorted(order) == list(range(n_lanes)) and order[0] == start


def test_turn_depth_hand_value() -> None:
    # rib depth 0.28 + cut-out clearance 0.01 + 0.03 + half diagonal sqrt(0.115² + 0.105²) = 0.155724
    assert turn_depth(Girder(), ROBOT, 0.03) == pytest.approx(0.475724, abs=1e-6)


def test_path_structure_and_lengths() -> None:
    g = Girder()
    p = plan_path(g, ROBOT)
    kinds = [s.kind for s in p.segments]
    uturn = [CORNER_DOWN, S1, TURN, S2, TURN, S3, CORNER_UP]
    assert kinds == [LANE, *uturn, LANE, *uturn, LANE]
    assert p.lane_order == [0, 1, 2]
    assert p.lane_dirs == {0: 1, 1: -1, 2: 1}
    # Lane: crossbeam face to face minus half the robot at each end: 2.0 − 0.23 = 1.77 m.
    lanes = [s for s in p.segments if s.kind == LANE]
    assert all(s.length_m == pytest.approx(1.77) for s in lanes)
    # S1 = S3 = turn depth − n/2 = 0.475724 − 0.115; S2 = rib spacing 0.6 m.
    s1 = [s for s in p.segments if s.kind == S1]
    assert all(s.length_m == pytest.approx(0.360724, abs=1e-6) for s in s1)
    assert all(s.length_m == pytest.approx(0.6) for s in p.segments if s.kind == S2)
    # Total: 3 lanes + 2·(2·S1 + S2) + 4 corner arcs.
    corner_len = next(s.length_m for s in p.segments if s.kind == CORNER_DOWN)
    total = 3 * 1.77 + 2 * (2 * 0.360724 + 0.6) + 4 * corner_len
    assert p.total_length_m == pytest.approx(total, abs=1e-5)
    # The path is continuous.
    pts = [s.points for s in p.segments]
    for a, b in itertools.pairwise(pts):
        np.testing.assert_allclose(a[-1], b[0], atol=1e-12)


def test_uturn_turns_left_toward_higher_lanes_then_right() -> None:
    # Lane 0 runs +X to crossbeam 1 (n = −X).  Heading down then toward +Y:
    # seen from inside, that is a turn to the robot's right (−90°); the
    # return sweep on crossbeam 0 turns the other way.
    p = plan_path(Girder(), ROBOT)
    turns = [s.turn_rad for s in p.segments if s.kind == TURN]
    assert [math.degrees(t) for t in turns] == pytest.approx([-90, -90, 90, 90])
    walls = [s.wall for s in p.segments if s.kind == S2]
    assert walls == [CROSSBEAM1, CROSSBEAM0]


def test_corner_points_follow_eq3_geometry() -> None:
    p = plan_path(Girder(), ROBOT)
    seg = next(s for s in p.segments if s.kind == CORNER_DOWN)
    # Starts at the lane end on the roof, ends n/2 down the crossbeam.
    np.testing.assert_allclose(seg.points[0], [2.0 - 0.115, 0.3, 0.0], atol=1e-12)
    np.testing.assert_allclose(seg.points[-1], [2.0, 0.3, -0.115], atol=1e-12)
    o, _, _ = corner.base_pose(
        np.linspace(0, math.pi / 2, len(seg.points)), ROBOT.wheelbase_m, ROBOT.wheel_radius_m
    )
    np.testing.assert_allclose(seg.points[:, 0], 2.0 + o[:, 0], atol=1e-12)
    np.testing.assert_allclose(seg.points[:, 2], -o[:, 1], atol=1e-12)


def test_start_in_the_middle_transfers_back() -> None:
    g = sample_girders()["deck_bay"]  # 5 lanes
    p = plan_path(g, ROBOT, start_lane=2, direction=1, start_end=1)
    assert p.lane_order == [2, 3, 4, 1, 0]
    assert p.lane_dirs[2] == -1
    s2 = [s.length_m for s in p.segments if s.kind == S2]
    # 4 → 1 crosses three lane pitches.
    assert s2 == pytest.approx([0.6, 0.6, 1.8, 0.6])


def test_bad_inputs() -> None:
    g = Girder()
    with pytest.raises(InvalidInputError, match="start_lane"):
        plan_path(g, ROBOT, start_lane=3)
    with pytest.raises(InvalidInputError, match="direction"):
        plan_path(g, ROBOT, direction=0)
    with pytest.raises(InvalidInputError, match="start_end"):
        plan_path(g, ROBOT, start_end=2)
    with pytest.raises(InfeasibleError, match="lane width"):
        plan_path(Girder(rib_spacing_m=0.5), ROBOT)
    with pytest.raises(InfeasibleError, match="crossbeam_depth_m"):
        plan_path(Girder(crossbeam_depth_m=0.5), ROBOT)
