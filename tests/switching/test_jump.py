"""Inch-worm jump (seed §3.2, §5.2.2): every returned trajectory passes its
checks, verified independently of the planner's own bookkeeping."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import robots
from planners.errors import UnreachableError
from planners.motion import interpolate
from planners.switching import decide_mode
from planners.switching.jump import (
    JumpParams,
    JumpRobot,
    _time_parameterise,
    plan_inchworm_jump,
    plan_path,
)
from planners.switching.scenes import make_scene
from tests.switching._reference_rrt import rrt_connect, shortcut

# Tens of seconds (planning on the seed scenes): `make test` runs it, not `make test-fast`.
pytestmark = pytest.mark.slow

ARA = robots.load_robot("ara")
ROB = JumpRobot.from_model(ARA)


@pytest.fixture(scope="module")
def step_down():
    sc = make_scene("step_down_7cm", 0)
    d = decide_mode(sc.points, camera_to_base=sc.camera_to_base, base_height=0.0, foot=(0.18, 0.12))
    c = d.chosen
    plan = plan_inchworm_jump(
        ARA,
        d.foothold_candidates,
        obstacles=d.points,
        surface=(c.frame.origin, c.frame.x_axis, c.frame.y_axis, c.area.hull),
    )
    return sc, d, plan


def test_phase_sequence_and_magnets(step_down):
    _, _, plan = step_down
    assert [p.name for p in plan.phases] == ["A", "B", "C", "D", "E", "F"]
    assert [(m["foot"], m["state"]) for m in plan.magnet_commands] == [
        ("foot2", "touched"),  # A: magnet 2 touched
        ("foot1", "touched"),  # D: swap
        ("foot2", "untouched"),
        ("foot1", "untouched"),  # F: mobile, both untouched
    ]
    t = [m["t_s"] for m in plan.magnet_commands]
    assert t == sorted(t)
    # Anchor: foot 2 until the swap, then foot 1.
    d = next(p for p in plan.phases if p.name == "D")
    assert (plan.anchor[: d.start] == 0).all() and (plan.anchor[d.start :] == 1).all()


def test_trajectory_respects_limits_and_speeds(step_down):
    _, _, plan = step_down
    Q, t = plan.joint_trajectory, plan.times
    lo, hi = ARA.joint_limits[:, 0], ARA.joint_limits[:, 1]
    assert np.all(lo - 1e-9 <= Q) and np.all(hi + 1e-9 >= Q)
    assert np.all(np.diff(t) > 0)
    speed = np.abs(np.diff(Q, axis=0)) / np.diff(t)[:, None]
    assert np.all(speed <= ARA.max_speed * (1 + 1e-6))
    np.testing.assert_allclose(Q[0], ARA.q_mobile)


def test_feet_reach_their_targets(step_down):
    _, _, plan = step_down
    Q = plan.joint_trajectory
    c = next(p for p in plan.phases if p.name == "C")
    # End of C: foot 1 (chain end) at the foothold, in the base frame.
    np.testing.assert_allclose(ARA.fk(Q[c.stop - 1]), plan.foot1_target, atol=1e-6)
    assert plan.foot1_target[2, 3] == pytest.approx(-0.07, abs=0.005)  # on the lower slab
    # End: foot 2 at its target = foot 1 pose · FK(q)^-1.
    W2 = plan.foot1_target @ np.linalg.inv(ARA.fk(Q[-1]))
    np.testing.assert_allclose(W2, plan.foot2_target, atol=1e-5)
    assert plan.foot2_target[2, 3] == pytest.approx(-0.07, abs=0.005)


def test_clearance_matches_brute_force(step_down):
    """Recompute scene clearance of the moving parts by brute force (all
    sphere-point distances, no KD-tree) on free-motion samples."""
    _, d, plan = step_down
    margin = 0.01
    pts = np.vstack([d.points, _standing_patch()])
    cov = ROB.cover
    frames = plan.link_frames(ROB)
    # Free-motion samples: the moving foot is away from both of its contacts
    # (lift-off within 4 cm of the start, landing within 4 cm of the target
    # may touch the surface under the footprint by design).
    start1 = ARA.fk(ARA.q_mobile)
    moving = np.where(plan.anchor == 0, len(ROB.link_names) - 1, 0)
    pos = frames[np.arange(len(frames)), moving, :3, 3]
    starts = np.where(plan.anchor[:, None] == 0, start1[:3, 3], np.zeros(3))
    ends = np.where(plan.anchor[:, None] == 0, plan.foot1_target[:3, 3], plan.foot2_target[:3, 3])
    away = (np.linalg.norm(pos - starts, axis=1) > 0.041) & (
        np.linalg.norm(pos - ends, axis=1) > 0.041
    )
    free = np.nonzero(away)[0][::8]
    assert len(free) > 40
    for k in free:
        anchored = (
            (0,) if plan.anchor[k] == 0 else (len(ROB.link_names) - 2, len(ROB.link_names) - 1)
        )
        mask = ~np.isin(cov.link, anchored)
        C = cov.world(frames[k])[mask]
        dist = np.linalg.norm(C[:, None, :] - pts[None], axis=2).min(axis=1) - cov.radius[mask]
        brute = float(dist.min())
        assert brute >= margin - 1e-9
        # Never clearer than it is; exact (below the 0.1 m culling cap) unless
        # the coarse-then-fine re-check left the sample out, which it only does
        # above max(margin, the motion's minimum).
        assert plan.clearance[k] <= min(brute, 0.1) + 1e-9
        exact = plan.clearance[k] == pytest.approx(min(brute, 0.1), abs=1e-9)
        assert exact or plan.clearance[k] > max(margin, plan.clearance.min())
    assert plan.clearance.min() >= margin - 1e-9
    assert plan.self_clearance.min() >= 0.0


def _standing_patch() -> np.ndarray:
    """The planner's default known patch of the standing surface (z = 0)."""
    gx, gy = np.meshgrid(np.arange(-0.75, 0.13 + 1e-9, 0.01), np.arange(-0.2, 0.2 + 1e-9, 0.01))
    return np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])


def test_unreachable_foothold():
    far = np.eye(4)
    far[:3, 3] = [1.5, 0.0, 0.0]
    with pytest.raises(UnreachableError):
        plan_inchworm_jump(ARA, far, obstacles=np.zeros((0, 3)))


def _wall_with_gap(Q: np.ndarray) -> np.ndarray:
    """2-D toy: a wall at x = 0 with a gap at |y| < 0.1."""
    Q = np.atleast_2d(Q)
    return ~((np.abs(Q[:, 0]) < 0.05) & (np.abs(Q[:, 1]) > 0.1))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_plan_path_goes_through_the_gap_in_a_wall(seed):
    """The jump's OMPL planner (and its simplifier): every segment is checked
    here, finely and independently of OMPL's motion validator."""
    lo, hi = np.array([-1.0, -1.0]), np.array([1.0, 1.0])
    a, b = np.array([-0.8, 0.8]), np.array([[0.8, 0.8]])  # the wall stands between
    params = JumpParams(step_rad=0.2, resolution_rad=0.01)
    path = plan_path(a, b, _wall_with_gap, lower=lo, upper=hi,
                     rng=np.random.default_rng(seed), params=params)  # fmt: skip
    assert path is not None and len(path) >= 3  # the straight segment is blocked
    assert np.array_equal(path[0], a) and np.array_equal(path[-1], b[0])
    for p, q in itertools.pairwise(path):
        assert _wall_with_gap(interpolate(p, q, 0.002)).all()
    again = plan_path(a, b, _wall_with_gap, lower=lo, upper=hi,
                      rng=np.random.default_rng(seed), params=params)  # fmt: skip
    assert again is not None and np.array_equal(path, again)  # deterministic for a seed


def test_reference_rrt_connect_and_shortcut_on_a_wall_with_a_gap():
    """The former hand-written planner, kept as the benchmark baseline."""
    rng = np.random.default_rng(0)
    lo, hi = np.array([-1.0, -1.0]), np.array([1.0, 1.0])
    path = rrt_connect(
        np.array([-0.8, 0.8]),
        np.array([[0.8, -0.8]]),
        _wall_with_gap,
        lower=lo,
        upper=hi,
        rng=rng,
        step=0.2,
        resolution=0.01,
    )
    assert path is not None
    np.testing.assert_allclose(path[0], [-0.8, 0.8])
    np.testing.assert_allclose(path[-1], [0.8, -0.8])
    short = shortcut(path, _wall_with_gap, rng=rng, iterations=200, resolution=0.01)
    for P in (path, short):
        for a, b in itertools.pairwise(P):
            assert _wall_with_gap(interpolate(a, b, 0.01)).all()
    assert (
        np.linalg.norm(np.diff(short, axis=0), axis=1).sum()
        <= np.linalg.norm(np.diff(path, axis=0), axis=1).sum() + 1e-12
    )


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 10_000), st.integers(2, 6))
def test_time_parameterisation_limits(seed, n):
    rng = np.random.default_rng(seed)
    wp = rng.uniform(-2, 2, (n, 6))
    vmax = rng.uniform(0.3, 1.5, 6)
    t, q = _time_parameterise(wp, vmax, 2.0, 0.01)
    assert np.all(np.diff(t) > 0)
    v = np.abs(np.diff(q, axis=0)) / np.diff(t)[:, None]
    assert np.all(v <= vmax * (1 + 1e-6))
    a = np.abs(np.diff(v, axis=0)) / np.diff(t)[1:, None]
    assert np.all(a <= 2.0 * 1.5 + 1e-6)  # sampled accelerations (dt-quantised) stay near the bound
    # Passes through every waypoint, in order.
    for w in wp:
        assert np.min(np.abs(q - w).max(axis=1)) < 1e-9
