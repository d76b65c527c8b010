"""coal spheroid–box distances against the former hand-written
alternating-projection kernel (kept in ``_reference_collision``) and against
analytic penetration depths."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from planners.blasting.collision import Box, Spheroids, spheroid_box_distance, spheroid_frames
from tests.blasting import _reference_collision as ref


def _pair(seed: int) -> tuple[Spheroids, Box]:
    rng = np.random.default_rng(seed)
    f1 = rng.normal(size=(1, 3)) * 0.3
    f2 = f1 + rng.normal(size=(1, 3)) * 0.3
    cf = np.linalg.norm(f2 - f1, axis=1) * rng.uniform(1.03, 1.3)
    box = Box(
        rng.normal(size=3) * 0.4,
        rng.uniform(0.02, 0.3, 3),
        Rotation.random(random_state=seed).as_matrix(),
    )
    return Spheroids(f1, f2, cf), box


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 2**31 - 1))
def test_coal_agrees_with_the_converged_reference(seed):
    S, box = _pair(seed)
    d = spheroid_box_distance(S, box)[0]
    with np.errstate(all="ignore"):
        # converged far past the production tolerance: the exact distance
        # (a lower bound within 1e-12) while separated, the probe depth inside
        dr = ref.spheroid_box_distance(S, box, tol=1e-12, max_iter=20_000)[0]
    if dr > 1e-6:
        assert d == pytest.approx(dr, abs=1e-8)
    elif dr < -1e-6:
        # overlap: coal's EPA depth is the true penetration depth, which is at
        # least the depth of any box point inside the spheroid (a translation
        # that separates them must carry that point out), up to EPA's tolerance
        assert d < 0.0
        assert d <= dr + 2e-6


def test_sphere_box_penetration_depth_is_analytic():
    """Coincident foci: a sphere of radius r.  Centre outside the box above
    the middle of its top face at height h < r: depth r − h; centre inside
    the box at depth s below the top face (the nearest face): depth r + s."""
    box = Box.from_bounds([-1.0, -1.0, -1.0], [1.0, 1.0, 1.0])
    r = 0.25
    for z, want in ((1.1, -(r - 0.1)), (1.0 + r + 0.2, 0.2), (0.9, -(r + 0.1))):
        c = np.array([[0.1, -0.2, z]])
        d = spheroid_box_distance(Spheroids(c, c, np.array([2 * r])), box)[0]
        assert d == pytest.approx(want, abs=1e-6)


@pytest.mark.parametrize("tilt", [0.0, 0.3, 0.7, 1.2])
def test_spheroid_tip_depth_is_true_not_probe_depth(tilt):
    """A prolate spheroid (axis tilted by ``tilt`` from the normal) dipping
    into a wide slab whose top face is z = 0: its lowest point is
    c_z − √(a²u_z² + b²(1 − u_z²)) (support function), and the shortest
    separating translation is that depth δ along the face normal.  For a
    tilted spheroid the former probe depth (box corners, centre, closest
    point) understated it."""
    box = Box.from_bounds([-2.0, -2.0, -1.0], [2.0, 2.0, 0.0])
    a, L, delta = 0.3, 0.5, 0.04
    u = np.array([np.sin(tilt), 0.0, np.cos(tilt)])
    b = np.sqrt(a * a - (L / 2) ** 2)
    c = np.array([0.1, 0.2, np.sqrt(a * a * u[2] ** 2 + b * b * (1 - u[2] ** 2)) - delta])
    S = Spheroids((c - L / 2 * u)[None], (c + L / 2 * u)[None], np.array([2 * a]))
    d = spheroid_box_distance(S, box)[0]
    assert d == pytest.approx(-delta, abs=1e-6)
    with np.errstate(all="ignore"):
        d_probe = ref.spheroid_box_distance(S, box)[0]
    assert d_probe < 0.0
    if tilt > 0.0:
        assert d_probe > -delta + 1e-3


def test_spheroid_frames_put_the_major_axis_first():
    rng = np.random.default_rng(3)
    f1 = rng.normal(size=(50, 3))
    f2 = f1 + rng.normal(size=(50, 3))
    S = Spheroids(f1, f2, np.linalg.norm(f2 - f1, axis=1) * 1.1)
    R = spheroid_frames(S)
    np.testing.assert_allclose(R[:, :, 0], S.axis, atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    np.testing.assert_allclose(
        R.transpose(0, 2, 1) @ R, np.broadcast_to(np.eye(3), R.shape), atol=1e-12
    )
