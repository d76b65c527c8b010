"""planners.blasting.motion.rrt_connect (OMPL) and the former hand-written
RRT-Connect it replaced (the benchmark baseline): a joint-space ball between
the two poses blocks the straight move; the path must go round it, checked by
fine sampling of every segment (independent of edge_free)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from planners.blasting import motion
from planners.errors import InvalidInputError
from tests.blasting._reference_rrt import rrt_connect_legacy

LIMITS = np.tile([-2.0, 2.0], (6, 1))
W = np.ones(6)  # clearance below is 1-Lipschitz in Σ|Δq| (≥ ‖Δq‖₂): certifiable
QA = np.array([-1.0, 0, 0, 0, 0, 0.3])
QB = np.array([1.0, 0, 0, 0, 0, 0.3])


def clear(Q: np.ndarray) -> np.ndarray:
    """Distance (joint space, J1–J5) outside a ball of radius 0.5 at 0, minus margin 0.01."""
    Q = np.atleast_2d(Q)
    return np.linalg.norm(Q[:, :5], axis=1) - 0.5 - 0.01


def _plan(seed: int, backend: str) -> motion.RRTResult:
    fn = motion.rrt_connect if backend == "ompl" else rrt_connect_legacy
    return fn(QA, QB, clear, LIMITS, W, rng=np.random.default_rng(seed))


@pytest.mark.parametrize("backend", ["legacy", "ompl"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_goes_round_the_ball(seed, backend):
    res = _plan(seed, backend)
    assert res.path is not None
    P = res.path
    assert np.array_equal(P[0], QA) and np.array_equal(P[-1], QB)
    assert np.all(P[:, 5] == QA[5])  # J6 (nozzle roll) never moves
    assert len(P) >= 3  # the straight move is blocked
    for a, b in itertools.pairwise(P):
        t = np.linspace(0, 1, int(np.abs(b - a).sum() / 1e-3) + 2)[:, None]
        assert np.all(np.linalg.norm((a + t * (b - a))[:, :5], axis=1) > 0.5)
    assert res.nodes >= 2 and res.iterations >= 1


def test_ompl_backend_is_deterministic():
    a, b = _plan(4, "ompl"), _plan(4, "ompl")
    assert np.array_equal(a.path, b.path)


def test_blocked_goal_and_bad_input():
    inside = np.zeros(6)
    res = motion.rrt_connect(QA, inside, clear, LIMITS, W, rng=np.random.default_rng(0))
    assert res.path is None
    with pytest.raises(InvalidInputError, match="non-finite"):
        motion.rrt_connect(QA, QB * np.nan, clear, LIMITS, W, rng=np.random.default_rng(0))
