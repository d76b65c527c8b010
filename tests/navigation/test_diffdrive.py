"""Differential-drive path primitives, the exact footprint-on-steel tests and
the differential-drive RRT-Connect, each against brute force or an
independent construction."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely import affinity

from planners.navigation.pibc import (
    BoundarySet,
    footprint_points,
    poses_valid,
    rectangles_on_steel,
    steel_union,
    swept_on_steel,
)
from planners.navigation.rrt import (
    DiffDrivePlanner,
    corridor_sampler,
    primitive_poses,
    primitive_validator,
    rt_waypoints,
    rtr_cost,
    rtr_waypoints,
    wrap,
)

from ._shared import bar_boundaries

FAST = settings(max_examples=60, deadline=None)

coord = st.floats(-2.0, 2.0, allow_nan=False, allow_infinity=False)
angle = st.floats(-np.pi, np.pi, allow_nan=False, allow_infinity=False, exclude_max=True)
pose = st.tuples(coord, coord, angle).map(np.array)
radius = st.floats(0.0, 0.5, allow_nan=False)


def _is_turn(p: np.ndarray, q: np.ndarray, tol: float = 1e-9) -> bool:
    return bool(np.hypot(*(q[:2] - p[:2])) <= tol)


def _is_straight(p: np.ndarray, q: np.ndarray, tol: float = 1e-9) -> bool:
    """Same yaw and a displacement along that heading (either sign)."""
    d = q[:2] - p[:2]
    sideways = abs(d[0] * np.sin(p[2]) - d[1] * np.cos(p[2]))
    return abs(float(wrap(q[2] - p[2]))) <= tol and sideways <= tol * max(1.0, np.hypot(*d))


def _primitive(p: np.ndarray, q: np.ndarray, tol: float = 1e-9) -> bool:
    return _is_turn(p, q, tol) or _is_straight(p, q, tol)


def _way_cost(way: list[np.ndarray], r: float) -> float:
    """Distance driven + r × |angle turned| summed over the way-points."""
    return float(
        sum(
            np.hypot(*(q[:2] - p[:2])) + r * abs(float(wrap(q[2] - p[2])))
            for p, q in itertools.pairwise(way)
        )
    )


# ------------------------------------------------------------ rtr / rt way-points
@FAST
@given(pose, pose, radius, st.booleans())
def test_rtr_cost_is_the_cheapest_waypoint_list_and_each_step_a_primitive(a, b, r, rev) -> None:
    ways = rtr_waypoints(a, b, allow_reverse=rev)
    assert len(ways) == (2 if rev and np.hypot(*(b[:2] - a[:2])) > 1e-9 else 1)
    costs = [_way_cost(w, r) for w in ways]
    c = float(rtr_cost(a, b, r, rev))
    assert c == pytest.approx(costs[0], abs=1e-9)
    assert all(c <= k + 1e-9 for k in costs)
    for w in ways:
        np.testing.assert_allclose(w[0], a)
        np.testing.assert_allclose(w[-1][:2], b[:2], atol=1e-9)
        assert abs(float(wrap(w[-1][2] - b[2]))) < 1e-9
        for p, q in itertools.pairwise(w):
            assert _primitive(p, q), (p, q)
        # primitive_poses accepts every step (it raises on a sideways slide).
        for p, q in itertools.pairwise(w):
            primitive_poses(p, q, resolution_m=0.01, turn_resolution_rad=0.05)


@FAST
@given(pose, pose, radius)
def test_rtr_cost_against_an_independent_formula(a, b, r) -> None:
    """Independent of the angle wrapping: each turn is the angle between two
    unit vectors (arccos of their dot product); the translation runs along
    a → b forwards or backwards."""
    d = b[:2] - a[:2]
    dist = float(np.hypot(*d))
    ua = np.array([np.cos(a[2]), np.sin(a[2])])
    ub = np.array([np.cos(b[2]), np.sin(b[2])])

    def ang(u: np.ndarray, v: np.ndarray) -> float:
        return float(np.arccos(np.clip(u @ v, -1.0, 1.0)))

    if dist <= 1e-9:
        want = want_fwd = r * ang(ua, ub)
    else:
        h = d / dist
        want_fwd = dist + r * (ang(ua, h) + ang(h, ub))
        want = min(want_fwd, dist + r * (ang(ua, -h) + ang(-h, ub)))
    # arccos near ±1 loses precision (√ε of angle): compare accordingly.
    assert float(rtr_cost(a, b, r)) == pytest.approx(want, abs=1e-6)
    assert float(rtr_cost(a, b, r, False)) == pytest.approx(want_fwd, abs=1e-6)
    # Backwards allowed: never dearer than forwards only, and symmetric.
    assert float(rtr_cost(a, b, r)) <= float(rtr_cost(a, b, r, False)) + 1e-12
    assert float(rtr_cost(a, b, r)) == pytest.approx(float(rtr_cost(b, a, r)), abs=1e-9)


def test_rtr_cost_broadcasts_like_the_scalar_call() -> None:
    rng = np.random.default_rng(3)
    a = np.column_stack([rng.uniform(-1, 1, (50, 2)), rng.uniform(-np.pi, np.pi, 50)])
    b = np.column_stack([rng.uniform(-1, 1, (50, 2)), rng.uniform(-np.pi, np.pi, 50)])
    b[:5, :2] = a[:5, :2]  # pure turns too
    vec = rtr_cost(a, b, 0.04)
    one = [float(rtr_cost(a[i], b[i], 0.04)) for i in range(50)]
    np.testing.assert_allclose(vec, one, atol=1e-12)
    # A tree's nodes against one target (the planner's nearest-neighbour call).
    np.testing.assert_allclose(rtr_cost(a, b[7], 0.04), [rtr_cost(x, b[7], 0.04) for x in a])


@FAST
@given(pose, st.tuples(coord, coord).map(np.array), st.booleans())
def test_rt_waypoints_reach_the_position_by_primitives_smaller_turn_first(a, xy, rev) -> None:
    if np.hypot(*(xy - a[:2])) < 1e-6:
        return
    ways = rt_waypoints(a, xy, allow_reverse=rev)
    assert len(ways) == (2 if rev else 1)
    turns = []
    for w in ways:
        np.testing.assert_allclose(w[0], a)
        np.testing.assert_allclose(w[-1][:2], xy, atol=1e-9)
        for p, q in itertools.pairwise(w):
            assert _primitive(p, q)
        turns.append(abs(float(wrap(w[-1][2] - a[2]))))
    assert turns == sorted(turns)
    assert turns[-1] <= np.pi + 1e-12 and (not rev or turns[0] <= np.pi / 2 + 1e-9)


@FAST
@given(pose, st.floats(-1.0, 1.0), angle, st.booleans())
def test_primitive_poses_steps_and_end(a, dist, dyaw, turn) -> None:
    if turn:
        b = np.array([a[0], a[1], float(wrap(a[2] + dyaw))])
    else:
        b = np.array([a[0] + dist * np.cos(a[2]), a[1] + dist * np.sin(a[2]), a[2]])
    q = primitive_poses(a, b, resolution_m=0.01, turn_resolution_rad=0.05)
    np.testing.assert_allclose(q[-1][:2], b[:2], atol=1e-12)
    assert abs(float(wrap(q[-1][2] - b[2]))) < 1e-12
    full = np.vstack([a, q])
    steps = np.diff(full, axis=0)
    assert np.all(np.hypot(steps[:, 0], steps[:, 1]) <= 0.01 + 1e-12)
    assert np.all(np.abs(wrap(steps[:, 2])) <= 0.05 + 1e-12)
    for p, r in itertools.pairwise(full):
        assert _primitive(p, r, tol=1e-9)


def test_primitive_poses_rejects_a_sideways_slide_and_a_turning_drive() -> None:
    a = np.array([0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="neither a turn in place nor a straight drive"):
        primitive_poses(a, np.array([0.0, 0.01, 0.0]), resolution_m=0.01, turn_resolution_rad=0.05)
    with pytest.raises(ValueError, match="neither"):
        primitive_poses(a, np.array([0.05, 0.0, 0.1]), resolution_m=0.01, turn_resolution_rad=0.05)


# ------------------------------------------------------------ exact on-steel tests
FOOT_L, FOOT_W = 0.08, 0.025


def _l_corridor() -> shapely.Polygon:
    """One L-shaped polygon: 60 mm bars along +x and +y from a corner square."""
    return shapely.Polygon(
        [(-0.03, -0.03), (0.5, -0.03), (0.5, 0.03), (0.03, 0.03), (0.03, 0.5), (-0.03, 0.5)]
    )


def _notched_bar() -> shapely.Polygon:
    """A 100 mm bar with a 3 mm wide, 60 mm deep notch cut in from one side
    at x = 0.2 — narrower than Alg. 6's footprint point spacing."""
    return shapely.Polygon(
        [
            (0.0, -0.05),
            (0.1985, -0.05),
            (0.1985, 0.01),
            (0.2015, 0.01),
            (0.2015, -0.05),
            (0.4, -0.05),
            (0.4, 0.05),
            (0.0, 0.05),
        ]
    )


def _rect_points(spacing: float = 0.0005) -> np.ndarray:
    """Points on the footprint rectangle's outline every ``spacing`` metres
    (the test polygons have no holes, so a rectangle is inside one exactly
    when its outline is)."""
    hx, hy = FOOT_L / 2, FOOT_W / 2
    nx_, ny_ = int(np.ceil(FOOT_L / spacing)), int(np.ceil(FOOT_W / spacing))
    xs, ys = np.linspace(-hx, hx, nx_ + 1), np.linspace(-hy, hy, ny_ + 1)
    return np.vstack(
        [
            np.column_stack([xs, np.full_like(xs, -hy)]),
            np.column_stack([xs, np.full_like(xs, hy)]),
            np.column_stack([np.full_like(ys, -hx), ys]),
            np.column_stack([np.full_like(ys, hx), ys]),
        ]
    )


def _brute_on(poly: shapely.Geometry, a: np.ndarray, b: np.ndarray, n_t: int) -> bool:
    """Footprint outline points at ``n_t`` poses interpolated a → b (yaw the
    short way round) all within 1e-7 m of ``poly`` (a polygon without holes)."""
    t = np.linspace(0.0, 1.0, n_t)[:, None]
    d = np.array([b[0] - a[0], b[1] - a[1], float(wrap(b[2] - a[2]))])
    q = a + t * d
    fp = _rect_points()
    c, s = np.cos(q[:, 2]), np.sin(q[:, 2])
    x = q[:, :1] + c[:, None] * fp[None, :, 0] - s[:, None] * fp[None, :, 1]
    y = q[:, 1:2] + s[:, None] * fp[None, :, 0] + c[:, None] * fp[None, :, 1]
    x, y = x.ravel(), y.ravel()
    inside = shapely.contains_xy(poly, x, y)
    if inside.all():
        return True
    out = ~inside
    return bool(np.all(shapely.distance(poly, shapely.points(x[out], y[out])) <= 1e-7))


def _n_t(a: np.ndarray, b: np.ndarray) -> int:
    """Interpolation samples a → b: every 0.5 mm of travel and 0.005 rad of turn."""
    turn = abs(float(wrap(b[2] - a[2]))) / 0.005
    return 2 + int(np.ceil(max(turn, np.hypot(*(b[:2] - a[:2])) / 0.0005)))


def _random_motions(rng: np.random.Generator, box: tuple[float, float, float, float], n: int):
    """Pose pairs near ``box``: a third turns in place, a third straight
    drives, a third general small (x, y, yaw) motions."""
    x0, y0, x1, y1 = box
    a = np.column_stack(
        [rng.uniform(x0, x1, n), rng.uniform(y0, y1, n), rng.uniform(-np.pi, np.pi, n)]
    )
    kind = rng.integers(0, 3, n)
    b = a.copy()
    turn = kind == 0
    b[turn, 2] = wrap(a[turn, 2] + rng.uniform(-np.pi, np.pi, turn.sum()))
    drive = kind == 1
    s = rng.uniform(-0.05, 0.05, drive.sum())
    b[drive, 0] += s * np.cos(a[drive, 2])
    b[drive, 1] += s * np.sin(a[drive, 2])
    gen = kind == 2
    b[gen, :2] += rng.uniform(-0.02, 0.02, (gen.sum(), 2))
    b[gen, 2] = wrap(a[gen, 2] + rng.uniform(-0.6, 0.6, gen.sum()))
    return a, b


@pytest.mark.parametrize(
    ("name", "box", "yaw_bias"),
    [("l", (-0.03, -0.03, 0.15, 0.15), None), ("notch", (0.12, -0.04, 0.28, 0.04), 0.0)],
)
def test_swept_on_steel_never_passes_a_motion_that_brute_force_sees_leave_the_steel(
    name, box, yaw_bias
) -> None:
    poly = _l_corridor() if name == "l" else _notched_bar()
    rng = np.random.default_rng(11)
    a, b = _random_motions(rng, box, 3000)
    if yaw_bias is not None:  # along the bar, so many poses fit at all
        a[:, 2] = wrap(yaw_bias + rng.normal(0, 0.15, len(a)) + np.pi * rng.integers(0, 2, len(a)))
        b[:, 2] = wrap(a[:, 2] + 0.5 * wrap(b[:, 2] - a[:, 2]) * (rng.random(len(a)) < 0.5))
    pair = np.array(
        [swept_on_steel(np.stack([a[i], b[i]]), poly, FOOT_L, FOOT_W) for i in range(len(a))]
    )
    pair_ok = pair.all(axis=1)
    # One call over a sequence answers pose k with the sweep from pose k-1,
    # as the per-pair calls do (pose 0 alone).
    seq = np.stack([a, b], axis=1).reshape(-1, 3)
    claimed = swept_on_steel(seq, poly, FOOT_L, FOOT_W)
    np.testing.assert_array_equal(claimed[1::2], pair[:, 1])
    np.testing.assert_array_equal(claimed[0], pair[0, 0])
    idx = np.nonzero(pair_ok)[0]
    assert len(idx) >= 30, f"too few on-steel motions to test ({len(idx)})"
    for i in idx[:150]:
        assert _brute_on(poly, a[i], b[i], _n_t(a[i], b[i])), (name, a[i], b[i])
    # Not vacuous the other way either: most motions brute force keeps on the
    # steel are accepted (the sagitta-grown hull over-covers only a little).
    ends_on = rectangles_on_steel(a, poly, FOOT_L, FOOT_W) & rectangles_on_steel(
        b, poly, FOOT_L, FOOT_W
    )
    sub = np.nonzero(ends_on)[0][:300]
    brute = np.array([_brute_on(poly, a[i], b[i], 25) for i in sub])
    assert brute.sum() >= 30
    assert pair_ok[sub][brute].mean() >= 0.6, pair_ok[sub][brute].mean()


def _exact_rect(p: np.ndarray, cx: float, cy: float) -> shapely.Polygon:
    """The footprint rectangle at pose ``p``, built independently with shapely."""
    r = shapely.box(-FOOT_L / 2 + cx, -FOOT_W / 2 + cy, FOOT_L / 2 + cx, FOOT_W / 2 + cy)
    r = affinity.rotate(r, float(p[2]), origin=(0, 0), use_radians=True)
    return affinity.translate(r, float(p[0]), float(p[1]))


@pytest.mark.parametrize("name", ["l", "notch"])
@pytest.mark.parametrize("centre", [(0.0, 0.0), (-0.02, 0.005)])
def test_rectangles_on_steel_matches_an_independent_exact_test_and_sampling(name, centre) -> None:
    poly = _l_corridor() if name == "l" else _notched_bar()
    rng = np.random.default_rng(5)
    box = (-0.03, -0.03, 0.2, 0.2) if name == "l" else (0.1, -0.05, 0.3, 0.05)
    q = np.column_stack(
        [
            rng.uniform(box[0], box[2], 1500),
            rng.uniform(box[1], box[3], 1500),
            wrap(np.pi / 2 * rng.integers(0, 4, 1500) + rng.normal(0, 0.2, 1500)),
        ]
    )
    got = rectangles_on_steel(q, poly, FOOT_L, FOOT_W, center_x_m=centre[0], center_y_m=centre[1])
    want = np.array([poly.contains(_exact_rect(p, *centre)) for p in q])
    np.testing.assert_array_equal(got, want)
    assert 50 <= got.sum() <= len(q) - 50  # both answers occur
    # Sampling 1 mm: any rectangle accepted has every sample on the steel.
    fp = _rect_points() + np.asarray(centre)
    for p in q[got][:200]:
        c, s = np.cos(p[2]), np.sin(p[2])
        x = p[0] + c * fp[:, 0] - s * fp[:, 1]
        y = p[1] + s * fp[:, 0] + c * fp[:, 1]
        assert np.all(shapely.distance(poly, shapely.points(x, y)) <= 1e-9)
    if name == "notch":
        # Alg. 6's 1 cm footprint points straddle the 3 mm notch (all of them
        # on steel); the exact test does not: the rectangle is refused.
        across = np.array([[0.2025, 0.0, 0.0]])
        pts = footprint_points(FOOT_L, FOOT_W, spacing_m=0.01) + across[0, :2]
        assert shapely.contains_xy(poly, pts[:, 0], pts[:, 1]).all()
        assert not rectangles_on_steel(across, poly, FOOT_L, FOOT_W)[0]
        assert not swept_on_steel(across, poly, FOOT_L, FOOT_W)[0]


def test_steel_union_closes_seams_but_not_gaps() -> None:
    """Two bars split at x = 0.2: a seam (touching, or 1 mm apart: below the
    3 mm closing) is steel, a 10 mm gap is not."""

    def bars(gap: float) -> list[np.ndarray]:
        return [
            np.array([[0.0, -0.03], [0.2, -0.03], [0.2, 0.03], [0.0, 0.03]]),
            np.array([[0.2 + gap, -0.03], [0.4, -0.03], [0.4, 0.03], [0.2 + gap, 0.03]]),
        ]

    across = np.array([[0.2, 0.0, 0.0]])
    for gap, ok in ((0.0, True), (0.001, True), (0.01, False)):
        steel = steel_union(bars(gap))
        assert rectangles_on_steel(across, steel, FOOT_L, FOOT_W)[0] == ok, gap
    # The closing does not grow the outline: a rectangle over the outer edge
    # stays refused.
    steel = steel_union(bars(0.0))
    assert not rectangles_on_steel(np.array([[0.1, 0.018, 0.0]]), steel, FOOT_L, FOOT_W)[0]
    assert rectangles_on_steel(np.array([[0.1, 0.017, 0.0]]), steel, FOOT_L, FOOT_W)[0]


# ------------------------------------------------------------ the planner
def _shape(rects: list[tuple[tuple[float, float], tuple[float, float]]]):
    """Boundary polygons of axis-aligned bars overlapping by 1 mm (as the
    pipeline's boundaries overlap across borders), the PIBC set, the exact
    steel and an independent shapely union."""
    centres, polys = bar_boundaries(rects)
    union = shapely.union_all(
        [shapely.box(x0 - 1e-3, y0 - 1e-3, x1 + 1e-3, y1 + 1e-3) for (x0, y0), (x1, y1) in rects]
    )
    return BoundarySet(centres, polys), steel_union(polys), union


W = 0.06  # the narrowest synthetic flange
L_SHAPE = [
    ((0.0, -W / 2), (0.6, W / 2)),
    ((-W / 2, W / 2), (W / 2, 0.6)),
    ((-W / 2, -W / 2), (W / 2, W / 2)),
]
T_SHAPE = [
    ((-0.6, -W / 2), (-W / 2, W / 2)),
    ((W / 2, -W / 2), (0.6, W / 2)),
    ((-W / 2, W / 2), (W / 2, 0.6)),
    ((-W / 2, -W / 2), (W / 2, W / 2)),
]


def _planner(bset, steel, seed: int = 0, margin: float = 0.001, **kw):
    foot = footprint_points(FOOT_L + 2 * margin, FOOT_W + 2 * margin, spacing_m=0.01)

    def valid(p: np.ndarray) -> np.ndarray:
        ok = poses_valid(p, foot, bset)
        if ok.any():
            ok[ok] = rectangles_on_steel(p[ok], steel, FOOT_L + 2 * margin, FOOT_W + 2 * margin)
        return ok

    return DiffDrivePlanner(valid, yaw_radius_m=FOOT_L / 2, **kw), valid


def _check_path(dense: np.ndarray, union: shapely.Geometry) -> None:
    """Independently of the planner: every step a primitive, every pose's
    rectangle (shapely-built) inside the union, and 1 mm / 0.01 rad samples
    between consecutive poses on it too."""
    for p, q in itertools.pairwise(dense):
        assert _primitive(p, q, tol=1e-9), (p, q)
    for p in dense:
        assert union.contains(_exact_rect(p, 0.0, 0.0)), p
    for p, q in itertools.pairwise(dense):
        assert _brute_on(union, p, q, _n_t(p, q)), (p, q)


@pytest.mark.parametrize(
    ("shape", "start", "goal"),
    [
        ("l", (0.5, 0.0, np.pi), (0.0, 0.5, np.pi / 2)),
        ("l", (0.5, 0.0, 0.0), (0.0, 0.5, -np.pi / 2)),  # facing away: drive backwards
        ("t", (-0.5, 0.0, 0.0), (0.0, 0.5, np.pi / 2)),
        ("t", (0.5, 0.0, np.pi), (-0.5, 0.0, np.pi)),  # straight through the crossing
    ],
)
def test_diffdrive_planner_turns_corners_of_60mm_bars(shape, start, goal) -> None:
    rects = L_SHAPE if shape == "l" else T_SHAPE
    bset, steel, union = _shape(rects)
    planner, valid = _planner(bset, steel, max_iterations=800)
    start, goal = np.array(start), np.array(goal)
    assert valid(np.stack([start, goal])).all()
    sampler = corridor_sampler(
        start[:2], goal[:2], np.random.default_rng(0), lateral_sigma_m=0.03, margin_m=0.04
    )
    path, _ = planner.plan(start, goal, sampler, turn_centre=np.zeros(2), turn_radius_m=0.06)
    assert path is not None
    dense = planner.densify(planner.shortcut(path, np.random.default_rng(1)))
    np.testing.assert_allclose(dense[0], start, atol=1e-12)
    np.testing.assert_allclose(dense[-1][:2], goal[:2], atol=1e-9)
    assert abs(float(wrap(dense[-1][2] - goal[2]))) < 1e-9
    assert valid(dense).all()
    _check_path(dense, union)
    assert swept_on_steel(dense, union, FOOT_L, FOOT_W).all()


def test_diffdrive_rrt_alone_finds_a_multi_point_turn() -> None:
    """Without the turn-point shortcut (no turn centre): RRT-Connect with
    rotate–translate steering still gets round the 60 mm L corner."""
    bset, steel, union = _shape(L_SHAPE)
    planner, valid = _planner(bset, steel, max_iterations=1500)
    start, goal = np.array([0.5, 0.0, np.pi]), np.array([0.0, 0.5, np.pi / 2])
    sampler = corridor_sampler(
        np.array([0.5, 0.0]),
        np.zeros(2),
        np.random.default_rng(2),
        lateral_sigma_m=0.02,
        margin_m=0.06,
    )
    path, iters = planner.plan(start, goal, sampler)
    assert path is not None and iters > 0
    dense = planner.densify(path)
    assert valid(dense).all()
    _check_path(dense, union)
    # Shortcutting never makes the path dearer.
    short = planner.shortcut(path, np.random.default_rng(3))
    assert planner.path_cost(short) <= planner.path_cost(path) + 1e-9


def test_diffdrive_planner_reports_failure_across_a_gap() -> None:
    """Two collinear bars 20 mm apart: no on-steel path exists, and the
    planner says so instead of returning one."""
    bset, steel, _ = _shape([((0.0, -W / 2), (0.3, W / 2)), ((0.32, -W / 2), (0.6, W / 2))])
    planner, valid = _planner(bset, steel, max_iterations=150)
    start, goal = np.array([0.1, 0.0, 0.0]), np.array([0.5, 0.0, 0.0])
    assert valid(np.stack([start, goal])).all()
    sampler = corridor_sampler(
        start[:2], goal[:2], np.random.default_rng(0), lateral_sigma_m=0.02, margin_m=0.04
    )
    path, iters = planner.plan(
        start, goal, sampler, turn_centre=np.array([0.31, 0.0]), turn_radius_m=0.06
    )
    assert path is None and iters == 150
    assert planner.connect_poses(start, goal) is None


def test_turn_point_finds_an_in_place_turn_on_steel() -> None:
    bset, steel, union = _shape(L_SHAPE)
    planner, valid = _planner(bset, steel)
    start, goal = np.array([0.5, 0.0, np.pi]), np.array([0.0, 0.5, np.pi / 2])
    way = planner.turn_point(start, goal, np.zeros(2), radius_m=0.06)
    assert way is not None
    dense = planner.densify(np.array(way))
    assert valid(dense).all()
    _check_path(dense, union)
    # Drive in, turn in place, drive out: at most two straight drives.
    drives = [(p, q) for p, q in itertools.pairwise(way) if not _is_turn(p, q)]
    assert 1 <= len(drives) <= 2


def test_injected_motion_validator_is_used_and_matches_the_default() -> None:
    """The planner takes planners.motion's validity shape: an injected
    motion validator decides every primitive (counted here), and injecting
    the default one (:func:`primitive_validator`) gives the very path of the
    default planner, whose batched way check is only an optimisation."""
    bset, steel, union = _shape(L_SHAPE)
    default, valid = _planner(bset, steel, max_iterations=1500)
    calls = 0
    base = primitive_validator(valid, resolution_m=0.01, turn_resolution_rad=0.05)

    def counted(a: np.ndarray, b: np.ndarray) -> bool:
        nonlocal calls
        calls += 1
        assert _primitive(a, b, tol=1e-7), (a, b)  # only primitives reach it
        return base(a, b)

    injected = DiffDrivePlanner(valid, yaw_radius_m=FOOT_L / 2, max_iterations=1500,
                                motion_valid=counted)  # fmt: skip
    start, goal = np.array([0.5, 0.0, np.pi]), np.array([0.0, 0.5, np.pi / 2])
    paths = []
    for planner in (default, injected):
        rng = np.random.default_rng(2)
        sampler = corridor_sampler(start[:2], np.zeros(2), rng, lateral_sigma_m=0.02, margin_m=0.06)
        path, _ = planner.plan(start, goal, sampler)
        assert path is not None
        paths.append(planner.shortcut(path, rng))
    assert calls > 0 and np.array_equal(paths[0], paths[1])
    _check_path(injected.densify(paths[1]), union)
    # a validator that refuses every turn in place leaves only straight drives
    no_turns = DiffDrivePlanner(valid, yaw_radius_m=FOOT_L / 2, max_iterations=50,
                                motion_valid=lambda a, b: not _is_turn(a, b) and base(a, b))  # fmt: skip
    sampler = corridor_sampler(
        start[:2], np.zeros(2), np.random.default_rng(0), lateral_sigma_m=0.02, margin_m=0.06
    )
    path, iters = no_turns.plan(start, goal, sampler)
    assert path is None and iters == 50
