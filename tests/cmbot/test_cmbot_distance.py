"""Sphere–cuboid distances (seed §3.2, Fig. 13): the closed form against the
former GJK (now a test reference, ``_reference_gjk``) and brute force."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from planners.cmbot.distance import Cuboid, sphere_box_bruteforce, sphere_box_exact
from tests.cmbot._reference_gjk import gjk_distance, sphere_box_gjk, support_tuple

coord = st.floats(-2.0, 2.0, allow_nan=False)
half = st.floats(0.02, 1.0, allow_nan=False)


@st.composite
def boxes(draw):
    c = np.array([draw(coord), draw(coord), draw(coord)])
    h = np.array([draw(half), draw(half), draw(half)])
    R = Rotation.from_rotvec(np.array([draw(coord), draw(coord), draw(coord)])).as_matrix()
    return Cuboid(c, h, R)


@settings(max_examples=300, deadline=None)
@given(box=boxes(), x=coord, y=coord, z=coord, r=st.floats(0.0, 0.3))
def test_gjk_matches_closed_form_and_brute_force(box, x, y, z, r):
    c = np.array([x, y, z])
    d, u = sphere_box_gjk(c, r, box)
    de, ue = sphere_box_exact(c[None], np.array([r]), [box])
    assert abs(d - de[0, 0]) < 1e-9
    assert abs(np.linalg.norm(u) - 1.0) < 1e-9
    assert np.allclose(u, ue[0, 0], atol=1e-6) or d < 0  # inside: nearest face (ties may differ)
    # brute force: dense surface sampling overestimates |distance to the surface|
    db = sphere_box_bruteforce(c, r, box, n=41)
    grid = 2.0 * float(box.half.max()) / 40 * np.sqrt(2)
    inside = np.all(np.abs(box.rotation.T @ (c - box.center)) <= box.half)
    if inside:
        assert db <= d + 1e-9 and d - db <= grid
    else:
        assert d <= db + 1e-9 and db - d <= grid
    if d > 1e-9:
        # u points from the box's closest point to the centre: moving along u increases d
        d2, _ = sphere_box_gjk(c + 1e-4 * u, r, box)
        assert d2 > d


@settings(max_examples=100, deadline=None)
@given(a=boxes(), b=boxes())
def test_gjk_box_box_against_vertex_face_brute_force(a, b):
    """Generic GJK (two support functions) vs dense sampling of both surfaces."""
    res = gjk_distance(
        lambda d: support_tuple(a, d), lambda d: support_tuple(b, d), a.center - b.center
    )
    g = np.linspace(-1, 1, 13)
    pts = []
    for box in (a, b):
        P = []
        for axis in range(3):
            o = [i for i in range(3) if i != axis]
            A, B = np.meshgrid(g, g, indexing="ij")
            for s in (-1.0, 1.0):
                Q = np.zeros((A.size, 3))
                Q[:, axis] = s
                Q[:, o[0]] = A.ravel()
                Q[:, o[1]] = B.ravel()
                P.append(Q)
        pts.append(box.center + (np.concatenate(P) * box.half) @ box.rotation.T)
    brute = np.linalg.norm(pts[0][:, None] - pts[1][None], axis=-1).min()
    if res.intersect:
        # the boxes overlap: some point of one lies inside the other (or they touch)
        d_in, _ = sphere_box_exact(pts[0], np.zeros(len(pts[0])), [b])
        d_in2, _ = sphere_box_exact(pts[1], np.zeros(len(pts[1])), [a])
        assert min(d_in.min(), d_in2.min()) <= 0.05 * max(a.half.max(), b.half.max())
    else:
        assert res.distance <= brute + 1e-9
        assert np.isclose(np.linalg.norm(res.point_a - res.point_b), res.distance)
        # the closest points lie on (or in) their boxes
        for p, box in ((res.point_a, a), (res.point_b, b)):
            local = box.rotation.T @ (p - box.center)
            assert np.all(np.abs(local) <= box.half + 1e-9)


def test_penetration_gets_negative_distance_and_face_normal():
    box = Cuboid.from_bounds([0, 0, 0], [1, 2, 3])
    d, u = sphere_box_gjk(np.array([0.1, 1.0, 1.5]), 0.05, box)
    assert np.isclose(d, -0.1 - 0.05) and np.allclose(u, [-1, 0, 0])


def test_batched_boxes_over_time():
    """Box arrays with a time axis give the same as per-step calls."""
    rng = np.random.default_rng(0)
    T = 5
    bc = rng.normal(size=(T, 3, 3))
    bh = rng.uniform(0.1, 0.5, (3, 3))
    bR = Rotation.random(T * 3, random_state=1).as_matrix().reshape(T, 3, 3, 3)
    C = rng.normal(size=(T, 4, 3))
    r = rng.uniform(0, 0.1, 4)
    d, _ = sphere_box_exact(C, r, (bc, bh, bR))
    for t in range(T):
        dt_, _ = sphere_box_exact(C[t], r, (bc[t], bh, bR[t]))
        assert np.allclose(d[t], dt_)


@settings(max_examples=30, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**31 - 1), moving=st.booleans())
def test_distance_only_path_equals_the_full_closed_form(seed, moving):
    """The distance-only path (one array per component) gives exactly the
    floats of the path with directions, outside and inside the boxes, with
    the boxes broadcast over time or carrying it."""
    from planners.cmbot.distance import point_box_closed_form

    rng = np.random.default_rng(seed)
    T, P = 7, 40
    rel = rng.normal(size=(T, P, 3)) * rng.uniform(0.05, 0.6)
    half = rng.uniform(0.02, 0.4, (P, 3))
    R = Rotation.random(T * P if moving else P, random_state=seed % 997).as_matrix()
    R = R.reshape((T, P, 3, 3) if moving else (P, 3, 3))
    fast, none = point_box_closed_form(rel, half, R, directions=False)
    full, _ = point_box_closed_form(rel, half, R, directions=True)
    assert none is None
    assert np.array_equal(fast, full)
