"""S_hc of an inch-worm transition: the ARA arm's exact reach bound (the wrist
points of a standing and a landing foot placement at most the arm's length
apart), against independent enumerations; the members no feasible transition
reaches, named by the coverage check."""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from planners.inspection import InspectionParams, plan_inspection
from planners.inspection.faces import FaceGeom, driving_face, foot_centres
from planners.inspection.inspect_plan import _checks
from planners.inspection.layout import pose_from
from planners.inspection.transitions import nearest_wrists
from planners.switching.jump import arm_length, wrist_distance
from robots import load_robot
from server.kinds.ara_inspect import AraInspectParams, ara_robot_numbers, inspection_params
from tests.inspection._models import structure

ARA: Any = load_robot("ara")


def _brute(s, ns, land, nl, p: InspectionParams) -> float:
    best = math.inf
    for a, b in itertools.product(s, land):
        if ns is None:  # the standing wrist anywhere wrist_standing_m from the point
            d = max(float(np.linalg.norm(b + p.wrist_landing_m * nl - a)) - p.wrist_standing_m, 0)
        else:
            d = float(np.linalg.norm((b + p.wrist_landing_m * nl) - (a + p.wrist_standing_m * ns)))
        best = min(best, d)
    return best


def _unit(v) -> np.ndarray:
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


vec = st.tuples(*[st.floats(-1, 1, allow_nan=False)] * 3).filter(lambda v: np.linalg.norm(v) > 0.1)
pts = st.lists(st.tuples(*[st.floats(-0.8, 0.8, allow_nan=False)] * 3), min_size=1, max_size=12)


@settings(max_examples=80, deadline=None)
@given(s=pts, land=pts, ns=st.none() | vec, nl=vec, off=st.floats(0, 0.2), off2=st.floats(0, 0.2))
def test_nearest_wrists_is_the_brute_force_minimum(s, land, ns, nl, off, off2) -> None:
    p = InspectionParams(wrist_standing_m=off, wrist_landing_m=off2)
    S, L = np.array(s), np.array(land)
    n_s = None if ns is None else _unit(ns)
    d, i, j = nearest_wrists(S, n_s, L, _unit(nl), p)
    assert d == pytest.approx(_brute(S, n_s, L, _unit(nl), p), abs=1e-9)
    assert d == pytest.approx(_brute(S[i : i + 1], n_s, L[j : j + 1], _unit(nl), p), abs=1e-9)


def test_nearest_wrists_of_nothing_is_infinite() -> None:
    d, i, j = nearest_wrists(
        np.zeros((0, 3)), None, np.zeros((2, 3)), np.array([0, 0, 1.0]), InspectionParams()
    )
    assert d == math.inf and (i, j) == (-1, -1)


def test_the_ara_numbers_come_from_its_params_file() -> None:
    ara = ara_robot_numbers()
    arm = ARA.params["arm"]
    assert ara["arm_length_m"] == pytest.approx(arm_length(ARA)) == pytest.approx(0.5)
    assert ara["wrist_standing_m"] == pytest.approx(arm["j1_above_sole_m"] + arm["j2_above_j1_m"])
    assert ara["wrist_landing_m"] == pytest.approx(arm["j6_below_j5_m"] + arm["sole_below_j6_m"])
    p = inspection_params(AraInspectParams())
    assert (p.arm_length_m, p.wrist_standing_m, p.wrist_landing_m) == pytest.approx((0.5, 0.1, 0.1))
    assert InspectionParams().arm_length_m == pytest.approx(0.5)


# ------------------------------------------------------------------ on a joint


def _l_joint(angle_deg: float, roll_deg: float, flange_from: float, depth: float):
    """Member 0 along x to the joint at the origin, member 1 leaving it at
    ``angle_deg`` from −x in the x–z plane, rolled about its axis."""
    a = math.radians(angle_deg)
    far = [-math.cos(a) * 2.0, 0.0, math.sin(a) * 2.0]
    nodes: dict[int, Sequence[float]] = {0: [-2.0, 0.0, 0.0], 1: [0.0, 0.0, 0.0], 2: far}
    return structure(
        nodes,
        [
            ([0, 1], {"depth": depth}),
            ([1, 2], {"roll_deg": roll_deg, "flange_from": flange_from, "depth": depth}),
        ],
    )


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    angle=st.floats(20, 160),
    roll=st.sampled_from([0.0, 90.0, 180.0, 270.0]),
    flange_from=st.floats(0.0, 0.6),
    depth=st.sampled_from([0.2, 0.3, 0.5]),
)
def test_s_hc_is_the_exact_bound_over_every_placement_pair(angle, roll, flange_from, depth):
    """Independent enumeration: every pair of foot placements (the standing face's
    near the joint, the landing face's), each made a 4×4 sole pose, foot 1's
    placed in foot 2's frame and measured with the jump planner's own
    ``wrist_distance`` / ``arm_length``: S_hc holds iff some pair is within the arm."""
    p = InspectionParams(placement_spacing_m=0.05)
    m = _l_joint(angle, roll, flange_from, depth)
    plan = plan_inspection(m, params=p)
    (t,) = plan.transitions
    if t.mode != "inchworm" or not t.availability["area"]:
        return
    v = np.zeros(3)
    # The route may start on either member (the one giving a feasible walk).
    ma, mb = m.members[t.from_member], m.members[t.to_member]
    ga = FaceGeom.of(driving_face(ma, p.foot_width_m))
    gb = FaceGeom.of(driving_face(mb, p.foot_width_m))
    stand = foot_centres(ga, v, ma.direction, p)
    land = foot_centres(gb, v, mb.direction, p)
    assert len(stand) and len(land)
    best = math.inf
    for a in stand:
        S = pose_from(a, ga.x_axis, ga.normal)
        inv = np.linalg.inv(S)
        for b in land:
            best = min(best, wrist_distance(inv @ pose_from(b, gb.x_axis, gb.normal), ARA))
    assert t.availability["wrist_distance_m"] == pytest.approx(best, abs=1e-9)
    assert t.availability["height"] == (best <= arm_length(ARA))
    assert t.feasible == (best <= arm_length(ARA))
    if not t.feasible:
        assert "S_hc" in t.reason and f"{best:.3f} m apart > the 0.50 m arm" in t.reason


def test_a_landing_the_sole_bound_allows_but_the_arm_cannot_reach_is_named():
    """Standing on a top flange stopping 0.3 m before the joint, landing on a
    column's flange starting 0.3 m up: the nearest soles 0.58 m apart (within
    the old 0.7 m bound), the wrist points 0.64 m: beyond the 0.5 m arm."""
    nodes = {0: (0, 0, 0), 1: (1, 0, 0), 2: (1, 0, 1)}
    m = structure(nodes, [([0, 1], {"flange_to": 0.7}), ([1, 2], {"flange_from": 0.3})])
    plan = plan_inspection(m)
    (t,) = plan.transitions
    av = t.availability
    assert av["reach_distance_m"] <= av["reach_limit_m"]  # the sole-to-sole bound passes
    assert av["wrist_distance_m"] == pytest.approx(0.64, abs=0.02)
    assert not av["height"] and not t.feasible
    assert "out of the arm's reach" in t.reason and "S_hc false" in t.reason
    # The only member change fails: member 1 cannot be reached, and the check says so.
    assert plan.unreachable_members == [1]
    assert [(b.from_member, b.to_member) for b in plan.blocked] == [(0, 1)]
    checks = {c.name: c for c in _checks(m, plan)[0]}
    cov = checks["members_covered"]
    assert not cov.passed and "not inspected" in cov.message and "member 1 " in cov.message
    assert "S_hc" in cov.message
    # A longer arm reaches it.
    longer = plan_inspection(m, params=InspectionParams(arm_length_m=0.7))
    assert longer.transitions[0].feasible and longer.unreachable_members == []
