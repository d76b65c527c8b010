"""plan_inspection on hand-built StructureModels: transitions (mobile vs
inch-worm, S_pa/S_am/S_hc), route coverage and optimality against a brute-force
T-join, the jump-cost weighting, gaps, start/end choice and input errors."""

from __future__ import annotations

import itertools
import math
from collections import Counter

import networkx as nx
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from planners.errors import (
    DisconnectedGraphError,
    EmptyInputError,
    InvalidInputError,
    InvalidWeightError,
    UnknownVertexError,
)
from planners.inspection import ARA_JUMP_REACH_M, InspectionParams, plan_inspection
from planners.inspection.faces import driving_face
from planners.structure.model import StructureModel
from tests.inspection._models import structure

L_NODES = {0: (0, 0, 0), 1: (1, 0, 0), 2: (1, 0, 1)}


def _check_walk(plan, route) -> None:
    """The route is a walk in the routing graph from start to end."""
    assert route.vertices[0] == route.start and route.vertices[-1] == route.end
    for (u, v, k), a, b in zip(route.edges, route.vertices[:-1], route.vertices[1:], strict=True):
        assert (u, v) == (a, b)
        assert plan.graph.has_edge(u, v, k)


def _covered_spans(plan) -> Counter:
    return Counter(frozenset((u, v)) | {("key", k)} for u, v, k in plan.route.edges)


def _only(plan, kind):
    return [t for t in plan.transitions if t.kind == kind]


def test_ara_reach_is_the_straight_arm_plus_the_sole_offsets():
    # params.toml [arm]: 0.05 + 0.05 above the sole, links 0.15 + 0.20 + 0.15, 0.05 + 0.05 below.
    assert pytest.approx(0.70) == ARA_JUMP_REACH_M
    p = InspectionParams()
    assert (p.foot_length_m, p.foot_width_m, p.jump_reach_m) == (0.18, 0.12, ARA_JUMP_REACH_M)


def test_one_member_split_at_a_joint_drives_straight_on():
    m = structure({0: (0, 0, 0), 1: (1, 0, 0), 2: (2, 0, 0)}, [([0, 1, 2], {})])
    plan = plan_inspection(m)
    assert [t.kind for t in plan.transitions] == ["continue"]
    t = plan.transitions[0]
    assert t.mode == "mobile" and t.feasible and t.vertex == 1 and t.index_in_route == 1
    assert plan.jumps == 0 and plan.length_m == pytest.approx(2.0)


def test_two_collinear_members_with_coplanar_flanges_are_mobile():
    m = structure({0: (0, 0, 0), 1: (1, 0, 0), 2: (2, 0, 0)}, [([0, 1], {}), ([1, 2], {})])
    plan = plan_inspection(m)
    (t,) = plan.transitions
    assert (t.kind, t.mode, t.from_member, t.to_member) == ("member", "mobile", 0, 1)
    assert t.feasible and t.angle_deg == pytest.approx(0.0, abs=1e-6)
    assert t.availability["step_m"] == pytest.approx(0.0, abs=1e-9)
    assert plan.jumps == 0 and plan.route.deadhead == pytest.approx(0.0)


def test_flanges_coplanar_but_apart_are_not_a_mobile_transition():
    # Member 1's flange starts 0.1 m past the joint: same plane, outlines 10 cm apart.
    m = structure(
        {0: (0, 0, 0), 1: (1, 0, 0), 2: (2, 0, 0)},
        [([0, 1], {}), ([1, 2], {"flange_from": 0.1})],
    )
    (t,) = plan_inspection(m).transitions
    assert t.mode == "inchworm"
    assert t.availability["outline_gap_m"] == pytest.approx(0.1, abs=1e-6)
    assert t.feasible  # a 0.1 m gap is easily within reach


def test_l_joint_horizontal_to_vertical_is_a_feasible_inchworm():
    plan = plan_inspection(structure(L_NODES, [([0, 1], {}), ([1, 2], {})]))
    (t,) = plan.transitions
    assert (t.mode, t.from_member, t.to_member) == ("inchworm", 0, 1)
    assert t.angle_deg == pytest.approx(90.0)
    av = t.availability
    assert av["plane"] and av["area"] and av["height"] and t.feasible
    # Standing foot centre ≥ l/2 before the flange end (x ≤ 0.91, z = 0.15); landing
    # on the column's outer flange x = 1.15: nearest is level with it.
    assert av["reach_distance_m"] == pytest.approx(math.hypot(1.15 - 0.91, 0.0), abs=0.021)
    assert plan.jumps == 1 and plan.length_m == pytest.approx(2.0)


def test_l_joint_onto_faces_all_narrower_than_the_foot_fails_area():
    m = structure(L_NODES, [([0, 1], {}), ([1, 2], {"width": 0.10, "depth": 0.10})])
    (t,) = plan_inspection(m).transitions
    av = t.availability
    assert t.mode == "inchworm" and av["plane"] and not av["area"] and not t.feasible
    assert av["footholds"] == 0 and "S_am" in t.reason


def test_l_joint_onto_narrow_flanges_lands_on_the_web_the_foot_fits():
    """An IPE 200-like column: 100 mm flanges take no 120 mm foot, its
    200 mm web does, and the driving face is the web."""
    m = structure(L_NODES, [([0, 1], {}), ([1, 2], {"width": 0.10, "depth": 0.20})])
    (t,) = plan_inspection(m).transitions
    web = next(f for f in m.members[1].faces if f.kind == "web")
    assert t.to_face == web.id
    assert t.availability["area"] and t.feasible
    assert driving_face(m.members[1]).kind == "flange"  # without a foot: the flange first


def test_l_joint_landing_beyond_the_reach_fails_height():
    # Standing flange stops 0.5 m before the joint, landing flange starts 0.4 m up.
    m = structure(
        L_NODES,
        [([0, 1], {"flange_to": 0.5}), ([1, 2], {"flange_from": 0.4})],
    )
    (t,) = plan_inspection(m).transitions
    av = t.availability
    assert av["plane"] and av["area"] and not av["height"] and not t.feasible
    # stand at x ≤ 0.41, z = 0.15; land on x = 1.15 at z ≥ 0.49
    assert av["reach_distance_m"] >= math.hypot(1.15 - 0.41, 0.49 - 0.15) - 0.03
    assert av["reach_distance_m"] > ARA_JUMP_REACH_M and "S_hc" in t.reason


def test_member_without_faces_is_infeasible_not_an_exception():
    m = structure(L_NODES, [([0, 1], {}), ([1, 2], {"faces": False})])
    plan = plan_inspection(m)
    (t,) = plan.transitions
    assert t.to_face is None and not t.availability["plane"] and not t.feasible
    assert "no faces" in t.reason and plan.covered_members == [0, 1]
    assert plan.infeasible == [t]


def _warren():
    """Three-panel Warren truss in the x-z plane: bottom chord one member of three
    spans, top chord one member of two spans, six diagonals."""
    nodes = {i: (float(i), 0.0, 0.0) for i in range(4)}
    nodes.update({4 + i: (i + 0.5, 0.0, 0.8) for i in range(3)})
    chains = [([0, 1, 2, 3], {}), ([4, 5, 6], {})]
    for a, b in [(0, 4), (4, 1), (1, 5), (5, 2), (2, 6), (6, 3)]:
        chains.append(([a, b], {"width": 0.2, "depth": 0.2}))
    return structure(nodes, chains)


def _brute_force_length(g: nx.MultiGraph, s, t) -> float:
    """Shortest covering walk s → t: every edge once plus the cheapest edge
    subset whose repeats make s, t the only odd vertices (Euler), by enumeration."""
    edges = list(g.edges(keys=True, data="weight"))
    want = {s, t} if s != t else set()
    best = math.inf
    for r in range(len(edges) + 1):
        for sub in itertools.combinations(range(len(edges)), r):
            deg = Counter(dict(g.degree()))
            for i in sub:
                deg[edges[i][0]] += 1
                deg[edges[i][1]] += 1
            if {v for v, d in deg.items() if d % 2} == want:
                best = min(best, sum(edges[i][3] for i in sub))
    return sum(w for *_, w in edges) + best


def test_warren_truss_route_covers_every_span_and_is_optimal():
    m = _warren()
    plan = plan_inspection(m, params=InspectionParams(jump_cost_m=0.0))
    _check_walk(plan, plan.route)
    model_spans = Counter(frozenset((u, v)) | {("key", k)} for u, v, k in m.graph.edges(keys=True))
    assert set(_covered_spans(plan)) == set(model_spans)
    assert plan.lower_bound_m == pytest.approx(3 + 2 + 6 * math.hypot(0.5, 0.8))
    assert plan.length_m >= plan.lower_bound_m - 1e-9
    # No free ends: the far-apart fallback picks the two bottom chord ends.
    assert {plan.route.start, plan.route.end} == {0, 3}
    assert plan.length_m == pytest.approx(_brute_force_length(m.graph, 0, 3), abs=1e-9)
    assert plan.covered_members == list(range(8)) and plan.uncovered_members == []


def test_warren_truss_transitions():
    plan = plan_inspection(_warren())
    assert len(plan.transitions) == len(plan.route.edges) - 1
    assert plan.length_m >= _brute_force_length(_warren().graph, 0, 3) - 1e-9
    for t in plan.transitions:
        # Chord and diagonal flanges are tilted against each other (≥ 32°): every
        # change of member is a jump, every continuation or reversal drives on.
        assert (t.mode == "mobile") == (t.kind in ("continue", "turnaround")), t
        assert t.vertex == plan.route.vertices[t.index_in_route]
        if t.kind == "member":
            assert t.angle_deg > 30
    assert plan.jumps == len(_only(plan, "member")) > 0


def _detour(jump_cost: float):
    """S–A, then A to B two ways — flat members via C1 (2.83 m) or members rolled
    ±30° via C2 (2.76 m) — then B–E.  S, A, B, E are odd, so one way is driven twice."""
    nodes = {
        0: (-1, 0, 0),
        1: (0, 0, 0),
        2: (2, 0, 0),
        3: (3, 0, 0),
        4: (1, 1, 0),
        5: (1, -0.95, 0),
    }
    chains = [
        ([0, 1], {}),
        ([1, 4], {}),
        ([4, 2], {}),
        ([1, 5], {"roll_deg": 30}),
        ([5, 2], {"roll_deg": -30}),
        ([2, 3], {}),
    ]
    return plan_inspection(
        structure(nodes, chains), start=0, end=3, params=InspectionParams(jump_cost_m=jump_cost)
    )


def test_jump_cost_makes_the_route_repeat_the_flat_way():
    flat, rolled = {1, 2}, {3, 4}
    cheap = _detour(0.0)  # lengths only: repeat the shorter, rolled way
    assert {cheap.graph.edges[e]["member"] for e in cheap.route.added_edges} == rolled
    costly = _detour(0.5)  # 4 forced edge-ends · 0.25 m > 0.07 m shorter: repeat the flat way
    assert {costly.graph.edges[e]["member"] for e in costly.route.added_edges} == flat
    # Driving the rolled way once costs its 3 member changes; twice costs more
    # even when the second pass starts with a turnaround on a rolled member.
    assert costly.jumps == 3 < cheap.jumps
    assert costly.length_m > cheap.length_m
    for plan in (cheap, costly):
        for t in plan.transitions:
            on_rolled = bool(rolled & {t.from_member, t.to_member})
            assert (t.mode == "inchworm") == (t.kind == "member" and on_rolled), t


def test_small_gap_is_joined_by_a_jump():
    m = structure(
        {0: (0, 0, 0), 1: (1, 0, 0), 2: (1.3, 0, 0), 3: (2.3, 0, 0)}, [([0, 1], {}), ([2, 3], {})]
    )
    plan = plan_inspection(m)
    (gap,) = plan.gaps
    assert gap.joined and gap.width_m == pytest.approx(0.3)
    assert (gap.vertex_a, gap.vertex_b) == (1, 2)  # end points: no split vertex
    np.testing.assert_allclose(gap.point_a, [1, 0, 0])
    np.testing.assert_allclose(gap.point_b, [1.3, 0, 0])
    assert len(plan.routes) == 1 and plan.uncovered_members == [] and plan.covered_members == [0, 1]
    (t,) = _only(plan, "gap")
    assert t.mode == "inchworm" and t.feasible and (t.vertex, t.landing_vertex) == (1, 2)
    assert plan.jumps == 1 and plan.length_m == pytest.approx(2.0) == plan.lower_bound_m
    _check_walk(plan, plan.route)


def test_gap_is_measured_between_spans_not_vertices():
    # A short member 0.4 m beside the middle of a long one: vertices are ≥ 0.447 m apart.
    m = structure(
        {0: (0, 0, 0), 1: (1, 0, 0), 2: (0.2, 0.4, 0), 3: (0.8, 0.4, 0)},
        [([0, 1], {}), ([2, 3], {})],
    )
    plan = plan_inspection(m)
    (gap,) = plan.gaps
    assert gap.joined and gap.width_m == pytest.approx(0.4, abs=1e-12)
    assert plan.graph.nodes[gap.vertex_a]["kind"] == "split"  # member 0 split mid-span
    steel = sum(d["steel_m"] for *_, d in plan.graph.edges(data=True))
    assert steel == pytest.approx(1.6) == plan.lower_bound_m
    assert plan.covered_members == [0, 1] and plan.length_m >= plan.lower_bound_m
    _check_walk(plan, plan.route)
    driven = {(min(u, v), max(u, v), k) for u, v, k in plan.route.edges}
    assert driven == {(min(u, v), max(u, v), k) for u, v, k in plan.graph.edges(keys=True)}


def test_wide_gap_leaves_two_routes():
    m = structure(
        {0: (0, 0, 0), 1: (1, 0, 0), 2: (2, 0, 0), 3: (4, 0, 0), 4: (5, 0, 0)},
        [([0, 1, 2], {}), ([3, 4], {})],
    )
    plan = plan_inspection(m)
    (gap,) = plan.gaps
    assert not gap.joined and gap.width_m == pytest.approx(2.0)
    assert (gap.component_a, gap.component_b) == (0, 1) and plan.components == [(0,), (1,)]
    assert (gap.vertex_a, gap.vertex_b) == (None, None)
    assert len(plan.routes) == 2 and plan.route is plan.routes[0]
    assert plan.covered_members == [0] and plan.uncovered_members == [1]
    assert plan.route.length == pytest.approx(2.0) and plan.routes[1].length == pytest.approx(1.0)
    assert plan.length_m == pytest.approx(3.0) == plan.lower_bound_m
    assert not any(d["kind"] == "jump" for *_, d in plan.graph.edges(data=True))


def test_three_pieces_give_two_spanning_gaps():
    # Pieces at x = 0..1, 1.5..2.5 and 10..11: gaps 0.5 (joined) and 7.5 (not).
    m = structure(
        {0: (0, 0, 0), 1: (1, 0, 0), 2: (1.5, 0, 0), 3: (2.5, 0, 0), 4: (10, 0, 0), 5: (11, 0, 0)},
        [([0, 1], {}), ([2, 3], {}), ([4, 5], {})],
    )
    plan = plan_inspection(m)
    widths = sorted((g.width_m, g.joined) for g in plan.gaps)
    assert widths == [(pytest.approx(0.5), True), (pytest.approx(7.5), False)]
    assert len(plan.routes) == 2 and plan.uncovered_members == [2]


def test_far_free_ends_are_the_default_start_and_end():
    nodes = {0: (0, 0, 0), 1: (1, 0, 0), 2: (3, 0, 0), 3: (1, 0.5, 0)}
    m = structure(nodes, [([0, 1, 2], {}), ([1, 3], {})])
    plan = plan_inspection(m)
    assert {plan.route.start, plan.route.end} == {0, 2}
    # One end fixed: the other is the free end furthest from it.
    assert plan_inspection(m, start=3).route.end == 2
    assert plan_inspection(m, end=0).route.start == 2


def test_bad_inputs_raise_typed_errors():
    m = structure(L_NODES, [([0, 1], {}), ([1, 2], {})])
    with pytest.raises(UnknownVertexError):
        plan_inspection(m, start=99)
    with pytest.raises(UnknownVertexError):
        plan_inspection(m, end=[1])  # unhashable
    empty = StructureModel([], [], nx.MultiGraph(), np.zeros(0, int), 0.01)
    with pytest.raises(EmptyInputError):
        plan_inspection(empty)
    with pytest.raises(InvalidInputError):
        plan_inspection(m, params=InspectionParams(foot_width_m=-1))
    bad = structure(L_NODES, [([0, 1], {}), ([1, 2], {})])
    bad.graph.edges[0, 1, 0]["weight"] = float("nan")
    with pytest.raises(InvalidWeightError):
        plan_inspection(bad)
    bad.graph.edges[0, 1, 0].update(weight=1.0, member=7)
    with pytest.raises(InvalidInputError):
        plan_inspection(bad)
    apart = structure(
        {0: (0, 0, 0), 1: (1, 0, 0), 2: (5, 0, 0), 3: (6, 0, 0)}, [([0, 1], {}), ([2, 3], {})]
    )
    with pytest.raises(DisconnectedGraphError):
        plan_inspection(apart, start=0, end=3)


def test_model_graph_is_left_untouched():
    m = structure(
        {0: (0, 0, 0), 1: (1, 0, 0), 2: (0.2, 0.4, 0), 3: (0.8, 0.4, 0)},
        [([0, 1], {}), ([2, 3], {})],
    )
    before = sorted(
        (u, v, k, tuple(sorted(d))) for u, v, k, d in m.graph.edges(keys=True, data=True)
    )
    plan_inspection(m)
    after = sorted(
        (u, v, k, tuple(sorted(d))) for u, v, k, d in m.graph.edges(keys=True, data=True)
    )
    assert before == after and m.graph.number_of_nodes() == 4


@settings(max_examples=25, deadline=None)
@given(roll=st.floats(-80, 80), width=st.floats(0.14, 0.4))
def test_rolled_collinear_member_is_mobile_iff_within_the_angle(roll, width):
    """Member 1 continues member 0 along the same axis with its flange rolled about
    the axis; the flanges still meet along the joint's edge line."""
    if 9.5 < abs(roll) < 10.5:  # the 10° threshold itself is left to rounding
        return
    m = structure(
        {0: (0, 0, 0), 1: (1, 0, 0), 2: (2, 0, 0)},
        [([0, 1], {"width": width}), ([1, 2], {"width": width, "roll_deg": roll})],
    )
    (t,) = plan_inspection(m).transitions
    assert t.angle_deg == pytest.approx(abs(roll), abs=1e-6)
    assert t.mode == ("mobile" if abs(roll) < 10 else "inchworm")
    assert t.feasible  # a wide enough flange right at the joint either way


@settings(max_examples=25, deadline=None)
@given(yaw=st.floats(-150, 150))
def test_turning_in_the_plane_of_the_flanges_is_mobile(yaw):
    """A horizontal member turning by any heading at a joint keeps its top flange
    in the same plane: the robot drives round the corner."""
    a = math.radians(yaw)
    m = structure(
        {0: (-1, 0, 0), 1: (0, 0, 0), 2: (math.cos(a), math.sin(a), 0)},
        [([0, 1], {}), ([1, 2], {})],
    )
    (t,) = plan_inspection(m).transitions
    assert t.mode == "mobile" and t.feasible and plan_inspection(m).jumps == 0


@settings(max_examples=20, deadline=None)
@given(width=st.one_of(st.floats(0.05, 0.115), st.floats(0.14, 0.5)))
def test_area_availability_follows_the_foot_width(width):
    """S_am on the column of an L: the 0.18 × 0.12 m foot fits iff the flange is
    at least 0.12 m wide (placements on a 2 cm grid: ≥ 0.14 m is sure to hit one);
    the column is as deep as wide, so its web is no wider."""
    m = structure(L_NODES, [([0, 1], {}), ([1, 2], {"width": width, "depth": width})])
    (t,) = plan_inspection(m).transitions
    assert t.availability["area"] == (width >= 0.12) == t.feasible


_coord = st.floats(-2, 2, allow_nan=False)
_point = st.tuples(_coord, _coord, _coord)


@settings(max_examples=60, deadline=None)
@given(a0=_point, a1=_point, b0=_point, b1=_point, flat=st.booleans())
def test_closest_segment_points_match_dense_sampling(a0, a1, b0, b1, flat):
    """Gap widths: the closed-form segment distance equals the minimum over a
    dense sampling of both segments (to the sampling resolution), and the
    returned parameters give that distance."""
    from planners.inspection.gaps import closest_segment_points

    a0, a1, b0, b1 = (np.array(p, float) for p in (a0, a1, b0, b1))
    if flat:  # parallel and degenerate cases
        b1 = b0 + (a1 - a0) * 0.5
    s, t, d = closest_segment_points(a0[None], a1[None], b0[None], b1[None])
    u = np.linspace(0, 1, 401)
    pa = a0 + u[:, None] * (a1 - a0)
    pb = b0 + u[:, None] * (b1 - b0)
    sampled = min(float(np.min(np.linalg.norm(pb - p, axis=1))) for p in pa)
    step = (np.linalg.norm(a1 - a0) + np.linalg.norm(b1 - b0)) / 400
    assert d[0, 0] <= sampled + 1e-9
    assert d[0, 0] >= sampled - step - 1e-9
    ca = a0 + s[0, 0] * (a1 - a0)
    cb = b0 + t[0, 0] * (b1 - b0)
    assert np.linalg.norm(ca - cb) == pytest.approx(d[0, 0], abs=1e-9)
    assert 0 <= s[0, 0] <= 1 and 0 <= t[0, 0] <= 1


@settings(max_examples=30, deadline=None)
@given(
    radii=st.lists(st.floats(0.05, 0.6), min_size=5, max_size=12),
    heading=st.floats(-math.pi, math.pi),
)
def test_foot_centres_by_erosion_match_rectangle_containment(radii, heading):
    """S_am's erosion shortcut against the direct test: every centre it accepts
    has a foot rectangle (at one of the headings) inside the face, and every
    centre whose rectangle fits with 0.1 mm to spare is accepted."""
    import shapely

    from planners.inspection.faces import FaceGeom, foot_centres
    from planners.structure.model import Face

    ang = np.linspace(0, 2 * np.pi, len(radii), endpoint=False)
    star = np.column_stack([np.cos(ang), np.sin(ang)]) * np.asarray(radii)[:, None]
    face = Face(
        0, 0, "flange", np.zeros(3), np.array([0, 0, 1.0]), np.array([1.0, 0, 0]), star, 1.0, 0
    )
    g = FaceGeom.of(face)
    params = InspectionParams(placement_spacing_m=0.03)
    direction = np.array([math.cos(heading), math.sin(heading), 0.0])
    got = foot_centres(g, np.zeros(3), direction, params)[:, :2]
    region = g.near(np.zeros(3), params.jump_reach_m)
    if region.is_empty:
        assert len(got) == 0
        return
    x0, y0, x1, y1 = region.bounds
    gx, gy = np.meshgrid(np.arange(x0, x1 + 1e-12, 0.03), np.arange(y0, y1 + 1e-12, 0.03))
    grid = np.column_stack([gx.ravel(), gy.ravel()])
    hl, hw = 0.09, 0.06
    local = np.array([[hl, hw], [-hl, hw], [-hl, -hw], [hl, -hw], [hl, hw]])
    loose, tight = np.zeros(len(grid), bool), np.zeros(len(grid), bool)
    for k in range(params.placement_headings):
        a = heading + k * math.pi / params.placement_headings
        rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
        polys = shapely.polygons(grid[:, None, :] + (local @ rot.T)[None])
        loose |= np.asarray(shapely.covers(region, polys))
        tight |= np.asarray(shapely.covers(region, shapely.buffer(polys, 1e-4, join_style="mitre")))
    accepted = {tuple(np.round(c, 9)) for c in got}
    for c, lo, ti in zip(grid, loose, tight, strict=True):
        key = tuple(np.round(c, 9))
        if key in accepted:
            assert lo, c
        elif ti:
            pytest.fail(f"centre {c} fits with margin but was rejected")


@settings(max_examples=40, deadline=None)
@given(gap=st.floats(0.0, 0.2), slack=st.floats(0.0, 0.1))
def test_flush_faces_continue_when_their_outlines_are_within_tolerance_plus_slack(gap, slack):
    """Two coplanar rectangles ``gap`` apart along x: the outline gap is
    measured exactly, and they continue iff it is within
    ``contact_tolerance_m`` + ``outline_slack_m`` (two point spacings in a plan)."""
    from planners.inspection.faces import FaceGeom, face_continuity
    from planners.structure.model import Face

    def rect(x0: float, x1: float, fid: int) -> FaceGeom:
        outline = np.array([[x0, -0.1], [x1, -0.1], [x1, 0.1], [x0, 0.1]])
        z, x = np.array([0, 0, 1.0]), np.array([1.0, 0, 0])
        return FaceGeom.of(Face(fid, fid, "flange", np.zeros(3), z, x, outline, 1.0, 0))

    a, b = rect(-1.0, 0.0, 0), rect(gap, 1.0 + gap, 1)
    params = InspectionParams()
    c = face_continuity(a, b, np.zeros(3), params, slack)
    assert c.outline_gap_m == pytest.approx(gap, abs=1e-9)
    assert c.angle_deg == pytest.approx(0.0, abs=1e-6) and c.step_m == pytest.approx(0.0)
    limit = params.contact_tolerance_m + slack
    if abs(gap - limit) > 1e-9:
        assert c.continues == (gap <= limit)


def test_the_default_start_is_on_a_member_the_foot_fits():
    """Two far-apart free ends, one on a member whose faces are all narrower
    than the foot (100 mm): the route starts at the other, where the crew
    can set the ARA down (by vertex order alone it started on the narrow
    one).  With the end fixed there, no placeable start is left and the
    far end is taken as before; a start given is kept."""
    m = structure(L_NODES, [([0, 1], {"width": 0.10, "depth": 0.10}), ([1, 2], {})])
    plan = plan_inspection(m)
    assert (plan.route.start, plan.route.end) == (2, 0)
    assert plan_inspection(m, end=2).route.start == 0
    assert plan_inspection(m, start=0).route.start == 0
    # a piece where no member fits the foot: far-apart ends by vertex order
    narrow = {"width": 0.10, "depth": 0.10}
    m2 = structure(L_NODES, [([0, 1], narrow), ([1, 2], narrow)])
    assert (plan_inspection(m2).route.start, plan_inspection(m2).route.end) == (0, 2)
