"""Arm motion (seed §3.4.1, Eq. 3.9–3.13) and the whole plan_blasting chain
on the seed's under-deck scenes."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from planners.blasting import (
    FOCI,
    _family_groups,
    _family_mask,
    _join_tours,
    _via_polylines,
    plan_blasting,
    scenes,
)
from planners.blasting import arm as A
from planners.blasting.collision import Obstacles
from planners.errors import CancelledError, InvalidInputError, StreamLengthError
from robots import load_robot

# Tens of seconds (planning on the seed scenes): `make test` runs it, not `make test-fast`.
pytestmark = pytest.mark.slow

ROBOT = load_robot("denso_vm6083").with_base(scenes.robot_base())


def test_eq_3_12_3_13_time_stretching():
    q = np.deg2rad(np.array([[0, 0], [3, 0], [3, 60], [3, 61]], dtype=float))
    t = A.time_stamps(q, np.array([1.0, 1.0, 1.0]), np.deg2rad(30))
    np.testing.assert_allclose(np.diff(t), [1.0, 2.0, 1.0])  # only the 60° step is stretched
    v = np.abs(np.diff(q, axis=0)).max(axis=1) / np.diff(t)
    assert v.max() <= np.deg2rad(30) + 1e-12


def test_branch_dp_matches_brute_force():
    rng = np.random.default_rng(1)
    for _ in range(5):
        Q = rng.normal(size=(4, 8, 6))
        ok = rng.random((4, 8)) < 0.6
        ok[:, 0] = True
        q0 = rng.normal(size=6)
        got = A.choose_branches(Q, ok, q0)

        def cost(seq, Q=Q, q0=q0):
            c = A._change(Q[0, seq[0]], q0)
            return c + sum(A._change(Q[i, seq[i]], Q[i - 1, seq[i - 1]]) for i in range(1, 4))

        best = min(
            (
                s
                for s in itertools.product(range(8), repeat=4)
                if all(ok[i, s[i]] for i in range(4))
            ),
            key=cost,
        )
        assert cost(got) == pytest.approx(cost(best))


def test_approximate_ik_exact_when_reachable_and_beats_the_seed_ga():
    q = np.deg2rad([20, -10, 100, 15, 40, 0])
    T = ROBOT.fk(q)
    p, a = T[:3, 3], T[:3, 2]
    q_ref = np.deg2rad([0, -75, 160, 0, 30, 0])
    ap = A.approximate_ik(ROBOT, p, a, q_ref)
    assert ap.pos_err_m < 1e-7 and ap.axis_err_deg < 1e-5
    # out of reach: the residual is at least the distance beyond the reach
    far = ROBOT.base[:3, 3] + np.array([1.2, 0.0, 0.6])
    ap = A.approximate_ik(ROBOT, far, np.array([1.0, 0, 0]), q_ref)
    shoulder = ROBOT.frames(np.zeros(6))[1, :3, 3]
    reach = 0.385 + np.hypot(0.1, 0.445) + 0.09
    assert ap.pos_err_m >= np.linalg.norm(far - shoulder) - reach - 1e-3
    ga = A.ga_ik(ROBOT, far, np.array([1.0, 0, 0]), q_ref, seed=0)
    assert ap.objective <= ga.objective + 1e-9
    assert ROBOT.within_limits(ap.q) and ROBOT.within_limits(ga.q)


def _raster_coverage(surface, plan, discs, h: float = 0.001) -> tuple[float, float]:
    """Coverage and overspray of the footprints ``discs`` on ``surface``,
    computed here on a 1 mm grid in the surface plane, independently of
    :mod:`planners.blasting.coverage`: a point is blasted when it lies in some
    ellipse ((s/a)² + (t/b)² ≤ 1, s along ``major_dir_2d``); coverage is the
    blasted share of the points inside the polygon (holes excluded), overspray
    the blasted area outside it over the surface area."""
    poly = shapely.Polygon(surface.boundary, [np.asarray(r) for r in surface.holes])
    c, ab, u = plan.centers_2d[discs], plan.semi_axes[discs], plan.major_dir_2d[discs]
    lo = np.minimum(np.array(poly.bounds[:2]), (c - ab[:, :1]).min(axis=0)) - h
    hi = np.maximum(np.array(poly.bounds[2:]), (c + ab[:, :1]).max(axis=0)) + h
    xs, ys = np.arange(lo[0], hi[0], h) + h / 2, np.arange(lo[1], hi[1], h) + h / 2
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    inside = shapely.contains_xy(poly, X, Y)
    hit = np.zeros(X.shape, dtype=bool)
    for (cx, cy), (a, b), (ux, uy) in zip(c, ab, u, strict=True):
        i0, i1 = np.searchsorted(xs, [cx - a, cx + a])
        j0, j1 = np.searchsorted(ys, [cy - a, cy + a])
        dx, dy = X[i0:i1, j0:j1] - cx, Y[i0:i1, j0:j1] - cy
        s_, t_ = dx * ux + dy * uy, dy * ux - dx * uy
        hit[i0:i1, j0:j1] |= (s_ / a) ** 2 + (t_ / b) ** 2 <= 1.0
    return float((hit & inside).sum() / inside.sum()), float(
        (hit & ~inside).sum() * h * h / poly.area
    )


@pytest.fixture(scope="module")
def s1_plan():
    return plan_blasting(
        scenes.bridge_surface(1),
        disc_radius_m=scenes.DISC_RADIUS_M,
        robot=ROBOT,
        obstacles=scenes.bridge_obstacles(),
        joint_planner="rrt",
    )


def test_surface_1_plan_passes_every_check(s1_plan):
    p = s1_plan
    failed = [c["message"] for c in p.checks() if not c["passed"]]
    assert not failed, failed
    # graded independently of the plan's own metrics: coverage and overspray
    # rasterised here, joint limits from the robot model, speeds from q(t)
    cov, over = _raster_coverage(scenes.bridge_surface(1), p, p.order)
    assert cov >= 0.99 and over <= 0.005, (cov, over)
    assert p.coverage == pytest.approx(cov, abs=2e-3) and p.overspray == pytest.approx(
        over, abs=5e-4
    )
    q, t = p.joint_trajectory, p.times
    lim = np.asarray(ROBOT.joint_limits)
    assert (q >= lim[:, 0] - 1e-12).all() and (q <= lim[:, 1] + 1e-12).all()
    assert (np.diff(t) > 0).all()
    speed = np.abs(np.diff(q, axis=0)).max(axis=1) / np.diff(t)
    assert speed.max() <= np.deg2rad(30) * (1 + 1e-9)
    assert p.max_joint_speed_rad_s == pytest.approx(speed.max())
    assert p.min_clearance_m > 0 and np.isfinite(p.clearance).all()
    assert np.all(np.diff(p.times) >= 0)
    assert sorted(np.r_[p.order, p.skipped]) == list(range(len(p.centers)))


def test_trajectory_structure_and_nozzle_on_the_spots(s1_plan):
    p = s1_plan
    q = p.joint_trajectory
    # start pose, then exactly 100 approach way-points (§4.2.4; here a
    # certified via-point move, its corner among them) ending on the first spot
    np.testing.assert_allclose(np.degrees(q[0]), [0, -75, 160, 0, 30, 0])
    assert p.motion["via_moves"] >= 1 and p.motion["rrt_calls"] == 0
    assert (p.segment[1:101] == 1).all() and p.segment[101] != 1
    assert (p.waypoint_spot[1:100] == -1).all() and p.waypoint_spot[100] == p.order[0]
    # every move was certified free, so the sampled clearance is positive too
    assert p.min_clearance_m > 0 and not len(p.unreached)
    assert (q[:, 5] == 0).all()  # the free roll: J6 never moves
    # at every spot the nozzle axis (flange z) passes through the disc centre
    # with the tip one stream length away (300 mm, or 100 mm for the small
    # fill discs) — independent FK check
    at = np.nonzero(p.waypoint_spot >= 0)[0]
    spots = p.waypoint_spot[at]
    assert set(spots) == set(p.order)
    F = ROBOT.frames(q[at])[:, -1]
    tip = F[:, :3, 3] + 0.1 * F[:, :3, 2]
    target = tip + (p.stream_mm[spots] / 1000.0)[:, None] * F[:, :3, 2]
    # the axis meets the surface at the aim point; the exact cone–plane
    # footprint's centre lies beyond it along the tilt (footprint.py)
    np.testing.assert_allclose(target, p.aim_points[spots], atol=1e-6)
    shift = p.centers_2d - p.aim_points_2d
    cross = shift[:, 0] * p.major_dir_2d[:, 1] - shift[:, 1] * p.major_dir_2d[:, 0]
    np.testing.assert_allclose(cross, 0.0, atol=1e-9)  # along the footprint's major axis
    assert np.all(np.einsum("ij,ij->i", shift, p.major_dir_2d) >= 0)
    # tilt stays within the seed's 45–90° to the surface
    n_in = -np.sign((ROBOT.base[:3, 3] - scenes.bridge_surface(1).origin) @ [0, 0, -1]) * np.array(
        [0, 0, -1.0]
    )
    ang = np.degrees(np.arccos(np.clip(F[:, :3, 2] @ n_in, -1, 1)))
    assert ang.max() <= 45 + 1e-6
    np.testing.assert_allclose(ang, p.tilt_deg[spots], atol=1e-6)
    assert (p.ik_residual_mm == 0).all()


def test_plan_is_deterministic_and_ga_option_works():
    s = scenes.bridge_surface(3)
    a = plan_blasting(s, disc_radius_m=0.04, robot=ROBOT, seed=3)
    b = plan_blasting(s, disc_radius_m=0.04, robot=ROBOT, seed=3)
    np.testing.assert_array_equal(a.order, b.order)
    np.testing.assert_array_equal(a.joint_trajectory, b.joint_trajectory)
    # without a robot there is no tilt, so compare on the same (untilted) discs
    d = plan_blasting(s, disc_radius_m=0.04, seed=3)
    g = plan_blasting(s, disc_radius_m=0.04, sequencer="ga", seed=3)
    assert g.joint_trajectory is None and sorted(g.order) == sorted(d.order)
    np.testing.assert_array_equal(g.centers, d.centers)
    assert d.objective < g.objective


def test_colliding_spots_are_rejected_not_planned_through():
    # a box hanging just under part of Surface 2 blocks the arm there
    blocker = scenes.Box.from_bounds([0.12, 0.30, 1.30], [0.40, 0.52, 1.48], "blocker")
    p = plan_blasting(
        scenes.bridge_surface(2),
        disc_radius_m=0.04,
        robot=ROBOT,
        obstacles=(*scenes.bridge_obstacles(), blocker),
    )
    at = p.waypoint_spot >= 0
    assert (p.clearance[at] > 0).all()  # no spot is blasted from a penetrating pose
    # the box costs both remedies: some spots are re-tilted beyond the global
    # tilt to reach past it, and some (today 3) are reached by no free pose
    assert len(p.skipped) > 0
    assert (p.tilt_deg > p.params["tilt_deg"] + 1e-9).any()
    # the skipped discs are not in the sequence and coverage says so: it is
    # the coverage of the visited footprints alone (rasterised here), less
    # than all footprints would give
    assert not set(p.skipped) & set(p.order)
    assert sorted(np.r_[p.order, p.skipped]) == list(range(len(p.centers)))
    cov_visited, _ = _raster_coverage(scenes.bridge_surface(2), p, p.order)
    cov_all, _ = _raster_coverage(scenes.bridge_surface(2), p, np.arange(len(p.centers)))
    assert p.coverage == pytest.approx(cov_visited, abs=2e-3)
    assert cov_visited < cov_all
    # the box leaves some spots to one arm family only: spots are grouped by
    # family, so the shoulder swings (J1 > 150° between consecutive spots)
    # happen only between groups (7 swings without the grouping)
    at = np.nonzero(p.waypoint_spot >= 0)[0]
    swings = int((np.abs(np.diff(p.joint_trajectory[at, 0])) > np.deg2rad(150)).sum())
    assert p.motion["family_groups"] > 1 and swings <= p.motion["family_groups"] - 1


def test_inputs_are_validated():
    s = scenes.bridge_surface(1)
    with pytest.raises(StreamLengthError):
        plan_blasting(s, stream_length_mm=600)
    with pytest.raises(InvalidInputError, match="sequencer"):
        plan_blasting(s, sequencer="tsp")
    with pytest.raises(InvalidInputError, match="kp"):
        plan_blasting(s, kp=(1.0, 1.1, 1.1))

    def cancel(f, stage):
        if stage == "sequencing":
            raise CancelledError("stop")

    with pytest.raises(CancelledError):
        plan_blasting(s, progress=cancel)
    # default disc radius comes from Eq. 3.1 (medium nozzle, 300 mm)
    assert plan_blasting(s).radius == pytest.approx(0.015875)


def test_hanger_rod_scene_plans_clear_with_a_retract_approach():
    """Fig. 4.27-style point obstacle (a hanger rod at Surface 1's edge) with
    the channel and deck: the direct approach from the start pose drives the
    nozzle into the deck (the regression of the footprint rewrite), so the
    approach must come in along the nozzle axis through a backed-off pose."""
    p = plan_blasting(
        scenes.bridge_surface(1),
        disc_radius_m=scenes.DISC_RADIUS_M,
        robot=ROBOT,
        obstacles=(*scenes.bridge_obstacles(), scenes.obstacle_points()),
    )
    failed = [c["message"] for c in p.checks() if not c["passed"]]
    assert not failed, failed
    assert p.motion["via_moves"] >= 1 and not len(p.unreached) and not len(p.skipped)
    assert (p.segment[1:101] == 1).all() and p.waypoint_spot[100] == p.order[0]
    # independent of the planner's certification: sample every move between
    # way-points 8 times and measure the exact clearance there
    q = p.joint_trajectory
    t = np.linspace(0.0, 1.0, 9)[1:-1, None, None]
    dense = (q[:-1][None] + t * (q[1:] - q[:-1])[None]).reshape(-1, 6)
    obst = Obstacles.coerce((*scenes.bridge_obstacles(), scenes.obstacle_points()))
    c = A.waypoint_clearance(ROBOT, dense, obst, 0.1, (1.05, 1.10, 1.10), FOCI)
    assert c.min() > 0, f"penetration {c.min() * 1000:.2f} mm between way-points"


def test_via_polylines_start_end_and_order():
    rng = np.random.default_rng(4)
    q0, q1, home = rng.uniform(-2, 2, (3, 6))
    r0 = list(rng.uniform(-2, 2, (2, 6)))
    r1 = list(rng.uniform(-2, 2, (1, 6)))
    polys = _via_polylines(q0, q1, r0, r1, home)
    # direct, two via moves, each with/without a retract at either end (3·2·3)
    # and through home for every retract choice (3·2)
    assert len(polys) == 3 * 2 * 3 + 3 * 2
    length = [np.abs(np.diff(p, axis=0)).max(axis=1).sum() for p in polys]
    assert np.all(np.diff(length) >= 0)
    for p in polys:
        np.testing.assert_array_equal(p[0], q0)
        np.testing.assert_array_equal(p[-1], q1)
    assert any(len(p) == 2 for p in polys)
    assert sum(any((c == home).all() for c in p) for p in polys) == 6


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(1, 12))
def test_family_groups_cover_every_spot_in_a_free_family(seed, n):
    rng = np.random.default_rng(seed)
    free = rng.random((n, 8)) < 0.35
    free[np.arange(n), rng.integers(0, 8, n)] = True  # every spot reachable somehow
    groups = _family_groups(free)
    fam = free[:, :4] | free[:, 4:]
    if fam.all(axis=0).any():
        assert groups is None  # one family reaches every spot: no split
        return
    assert groups is not None
    seen = np.concatenate([g for g, _ in groups])
    assert sorted(seen) == list(range(n))  # a partition
    for g, f in groups:
        assert fam[g, f].all()
    # greedy set cover: never more groups than spots, and no family used twice
    assert len({f for _, f in groups}) == len(groups) <= n
    # optimal cover size by brute force; greedy is within the H(n) bound
    best = min(
        k
        for k in range(1, 5)
        for fs in itertools.combinations(range(4), k)
        if fam[:, list(fs)].any(axis=1).all()
    )
    assert len(groups) <= best * sum(1 / i for i in range(1, n + 1)) + 1e-9
    np.testing.assert_array_equal(
        _family_mask(np.array([0, 3])),
        [[1, 0, 0, 0, 1, 0, 0, 0], [0, 0, 0, 1, 0, 0, 0, 1]],
    )


def test_join_tours_turns_each_tour_to_start_near_the_last_end():
    pts = np.array([[0.0, 0], [1, 0], [5, 0], [2, 0]])
    out = _join_tours([np.array([0, 1]), np.array([2, 3])], pts)
    np.testing.assert_array_equal(out, [0, 1, 3, 2])
