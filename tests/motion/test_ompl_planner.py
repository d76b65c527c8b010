"""planners.motion: the OMPL wrapper on a 2-D wall with a gap, checked independently."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from planners.errors import InvalidInputError
from planners.motion import interpolate, plan_motion, segment_validator, wrap_angle

GAP = (0.45, 0.55)  # the wall x ∈ (0.45, 0.55) is open only for y in this band
START, GOAL = np.array([0.1, 0.1]), np.array([0.9, 0.1])


def wall_valid(Q: np.ndarray) -> np.ndarray:
    Q = np.atleast_2d(Q)
    x, y = Q[:, 0], Q[:, 1]
    return ~((x > 0.45) & (x < 0.55) & ~((y > GAP[0]) & (y < GAP[1])))


def closed_valid(Q: np.ndarray) -> np.ndarray:
    Q = np.atleast_2d(Q)
    return ~((Q[:, 0] > 0.45) & (Q[:, 0] < 0.55))


def _plan(seed: int = 3, valid=wall_valid, **kw):
    return plan_motion(
        START, GOAL[None], valid, lower=[0, 0], upper=[1, 1], seed=seed,
        resolution=0.004, range_=0.2, **kw,
    )  # fmt: skip


def _independently_free(path: np.ndarray) -> bool:
    """Every way-point and every segment sampled at 0.5 mm lies off the wall
    (a geometric test, not the planner's validator)."""
    for a, b in itertools.pairwise(path):
        t = np.linspace(0.0, 1.0, int(np.ceil(np.linalg.norm(b - a) / 5e-4)) + 2)[:, None]
        P = a + t * (b - a)
        in_wall = (P[:, 0] > 0.45) & (P[:, 0] < 0.55)
        if np.any(in_wall & ~((P[:, 1] > GAP[0]) & (P[:, 1] < GAP[1]))):
            return False
    return True


@pytest.mark.parametrize("seed", [0, 1, 2, 3, 4])
def test_path_through_the_gap(seed):
    r = _plan(seed)
    assert r.success and r.status == "exact"
    assert np.array_equal(r.path[0], START) and np.array_equal(r.path[-1], GOAL)
    assert _independently_free(r.path)
    # the straight line is blocked, so the path must cross x = 0.5 inside the gap
    assert len(r.path) >= 3
    assert r.checks > 0 and r.iterations > 0


def test_same_seed_same_path_other_seed_differs():
    a, b, c = _plan(7), _plan(7), _plan(8)
    assert np.array_equal(a.path, b.path) and a.checks == b.checks
    assert a.path.shape != c.path.shape or not np.allclose(a.path, c.path)


def test_simplification_shortens():
    raw, simp = _plan(5, simplify=False), _plan(5)
    L = [float(np.linalg.norm(np.diff(r.path, axis=0), axis=1).sum()) for r in (raw, simp)]
    assert L[1] <= L[0] + 1e-12 and len(simp.path) <= len(raw.path)


def test_direct_segment_when_free():
    r = plan_motion(START, [[0.3, 0.8]], wall_valid, lower=[0, 0], upper=[1, 1], seed=0)
    assert r.success and len(r.path) == 2 and r.iterations == 0


def test_several_goals_reports_the_reached_one():
    goals = np.array([[0.5, 0.9], GOAL])  # the first lies in the wall: invalid
    r = plan_motion(START, goals, wall_valid, lower=[0, 0], upper=[1, 1], seed=1, range_=0.2)
    assert r.success and r.goal_index == 1 and np.array_equal(r.path[-1], GOAL)


def test_impossible_problem_fails_cleanly():
    r = _plan(1, valid=closed_valid, max_iterations=300)
    assert r.path is None and not r.success and r.status == "timeout"
    assert r.iterations == 300
    r = _plan(1, valid=closed_valid, max_time_s=0.2)
    assert r.path is None and r.status == "timeout" and r.planning_time_s >= 0.2
    bad_start = plan_motion([0.5, 0.1], GOAL[None], wall_valid, lower=[0, 0], upper=[1, 1], seed=0)
    assert bad_start.status == "invalid_start" and bad_start.path is None
    bad_goal = plan_motion(START, [[0.5, 0.9]], wall_valid, lower=[0, 0], upper=[1, 1], seed=0)
    assert bad_goal.status == "invalid_goal"


def test_weighted_metric_still_exact_and_free():
    r = _plan(2, weights=[4.0, 1.0])
    assert r.success and np.array_equal(r.path[-1], GOAL) and _independently_free(r.path)


@pytest.mark.parametrize(
    "kw",
    [
        {"start": [0.1]},
        {"start": [np.nan, 0.1]},
        {"goals": np.zeros((0, 2))},
        {"goals": [[1.5, 0.1]]},
        {"lower": [1, 0]},
        {"planner": "prm_unknown"},
        {"max_time_s": 0.0},
        {"max_iterations": 0},
        {"resolution": -1.0},
        {"weights": [1.0, 0.0]},
    ],
)
def test_bad_input_raises(kw):
    args = {"start": START, "goals": GOAL[None], "lower": [0, 0], "upper": [1, 1]}
    args.update(kw)
    extra = {k: v for k, v in args.items() if k not in ("start", "goals", "lower", "upper")}
    with pytest.raises(InvalidInputError):
        plan_motion(
            args["start"], args["goals"], wall_valid,
            lower=args["lower"], upper=args["upper"], seed=0, **extra,
        )  # fmt: skip


# --- periodic (SO2) dimensions: (x, θ) with the band |θ| < 1 forbidden, so a
# path from θ = 2.5 to θ = −2.5 must turn the short way, through ±π.


def band_valid(Q: np.ndarray) -> np.ndarray:
    Q = np.atleast_2d(Q)
    return np.abs(wrap_angle(Q[:, 1])) >= 1.0


def test_periodic_dimension_turns_the_short_way_through_pi():
    start, goal = np.array([0.1, 2.5]), np.array([0.9, -2.5])
    # without the wrap the straight segment crosses the forbidden band ...
    assert not segment_validator(band_valid, 0.01)(start, goal)
    # ... with it, it does not, and the planner takes it directly
    assert segment_validator(band_valid, 0.01, periodic=[1])(start, goal)
    r = plan_motion(start, goal[None], band_valid, lower=[0, 0], upper=[1, 0], seed=0, periodic=[1])
    assert r.success and r.iterations == 0 and len(r.path) == 2
    assert np.array_equal(r.path[0], start) and np.array_equal(r.path[-1], goal)


def test_periodic_search_exact_ends_free_and_deterministic():
    # a wall in x open only at θ ∈ (2.8, π) ∪ [−π, −2.8): the search must go there
    def valid(Q: np.ndarray) -> np.ndarray:
        Q = np.atleast_2d(Q)
        th = wrap_angle(Q[:, 1])
        wall = (Q[:, 0] > 0.45) & (Q[:, 0] < 0.55) & (np.abs(th) < 2.8)
        return band_valid(Q) & ~wall

    start, goal = np.array([0.1, 1.5 + 2 * np.pi]), np.array([0.9, -1.5])  # any angle in
    kw = dict(lower=[0, -9], upper=[1, 9], seed=4, periodic=[1], weights=[1.0, 0.2], range_=0.2)
    r = plan_motion(start, goal[None], valid, **kw)
    again = plan_motion(start, goal[None], valid, **kw)
    assert r.success and r.iterations > 0
    assert np.array_equal(r.path, again.path)
    assert np.array_equal(r.path[0], start) and np.array_equal(r.path[-1], goal)
    assert np.all(np.abs(r.path[1:-1, 1]) <= np.pi)  # inner states on the circle
    # independently: every segment, sampled finely the short way round, is free
    for a, b in itertools.pairwise(r.path):
        assert valid(interpolate(a, b, 1e-3, periodic=[1])).all()
    assert start[1] == 1.5 + 2 * np.pi  # the caller's array is untouched


@settings(max_examples=60, deadline=None)
@given(
    st.tuples(st.floats(-3, 3), st.floats(-10, 10)),
    st.tuples(st.floats(-3, 3), st.floats(-10, 10)),
    st.floats(0.01, 0.5),
)
def test_interpolate_periodic_steps_the_short_way(a, b, res):
    a, b = np.array(a), np.array(b)
    P = interpolate(a, b, res, periodic=[1])
    assert np.all(np.abs(P[:, 1]) <= np.pi)
    assert np.isclose(P[-1, 0], b[0]) and abs(wrap_angle(P[-1, 1] - b[1])) < 1e-9
    steps = np.vstack([a, P])
    dth = np.abs(wrap_angle(np.diff(steps[:, 1])))
    assert np.all(np.abs(np.diff(steps[:, 0])) <= res + 1e-9) and np.all(dth <= res + 1e-9)
    # total turn = the short way, never more than π
    assert dth.sum() == pytest.approx(abs(float(wrap_angle(b[1] - a[1]))), abs=1e-9)


def test_bad_periodic_raises():
    with pytest.raises(InvalidInputError, match="periodic"):
        plan_motion(START, GOAL[None], wall_valid, lower=[0, 0], upper=[1, 1], seed=0, periodic=[2])
