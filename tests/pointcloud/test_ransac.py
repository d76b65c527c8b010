"""RANSAC plane fitting recovers known planes; sequential detection."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from planners.errors import EmptyInputError, InvalidInputError
from planners.pointcloud import detect_planes, fit_plane_ransac


def _plane_frame(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.array([1.0, 0, 0]) if abs(normal[0]) < 0.9 else np.array([0, 1.0, 0])
    u = np.cross(normal, helper)
    u /= np.linalg.norm(u)
    return u, np.cross(normal, u)


def _slab(rng, normal, offset, n, size=(1.0, 0.6), noise=0.002, centre=(0, 0)):
    u, v = _plane_frame(normal)
    s = rng.uniform(-0.5, 0.5, (n, 2)) * size + centre
    return -offset * normal + s[:, :1] * u + s[:, 1:] * v + rng.normal(0, noise, (n, 3))


@settings(max_examples=25, deadline=None)
@given(
    st.integers(0, 10_000),
    st.floats(-3.0, 3.0),
    st.floats(0.0, 0.4),
    st.floats(0.0, 0.003),
)
def test_ransac_recovers_known_plane(seed, offset, outlier_frac, noise):
    rng = np.random.default_rng(seed)
    normal = rng.normal(size=3)
    normal /= np.linalg.norm(normal)
    n_in = 1500
    inl = _slab(rng, normal, offset, n_in, noise=noise)
    n_out = int(outlier_frac / (1 - outlier_frac) * n_in)
    centre = -offset * normal
    out = centre + rng.uniform(-1, 1, (n_out, 3))
    out = out[np.abs((out - centre) @ normal) > 0.05]  # true outliers only
    pts = np.vstack([inl, out])
    fit = fit_plane_ransac(pts, threshold_m=0.01, seed=seed)
    assert abs(abs(fit.normal @ normal) - 1) < 1 - np.cos(np.radians(1.0))
    # Same plane: the true centre lies on the fitted plane (within mm).
    assert abs(fit.distance(centre[None])[0]) < 0.003
    recall = fit.inliers[:n_in].mean()
    assert recall > 0.97
    assert not fit.inliers[n_in:].any()
    assert np.isclose(np.linalg.norm(fit.normal), 1.0)
    assert fit.d >= 0  # oriented towards the origin


def test_ransac_far_from_origin_and_deterministic():
    rng = np.random.default_rng(1)
    pts = _slab(rng, np.array([0.0, 0.0, 1.0]), -7.0, 2000) + np.array([4.0, 20.0, 0.0])
    a = fit_plane_ransac(pts, seed=5)
    b = fit_plane_ransac(pts, seed=5)
    np.testing.assert_array_equal(a.inliers, b.inliers)
    assert abs(abs(a.normal[2]) - 1) < 1e-4
    assert abs(a.centroid[2] - 7.0) < 1e-3


def test_detect_planes_finds_perpendicular_slabs():
    rng = np.random.default_rng(2)
    floor = _slab(rng, np.array([0, 0, 1.0]), 0.0, 3000, size=(1.0, 1.0), centre=(0.0, 0.0))
    wall = _slab(rng, np.array([1.0, 0, 0]), -0.7, 2000, size=(0.5, 0.5), centre=(0.3, 0.0))
    planes = detect_planes(np.vstack([floor, wall]), min_points=300)
    assert len(planes) == 2
    normals = sorted(tuple(np.round(np.abs(p.normal))) for p in planes)
    assert normals == [(0.0, 0.0, 1.0), (1.0, 0.0, 0.0)]
    assert not (planes[0].inliers & planes[1].inliers).any()


def test_detect_planes_splits_coplanar_components():
    rng = np.random.default_rng(4)
    n = np.array([0, 0, 1.0])
    a = _slab(rng, n, 0.0, 1500, size=(0.4, 0.4), centre=(-0.5, 0.0))
    b = _slab(rng, n, 0.0, 1000, size=(0.4, 0.4), centre=(0.5, 0.0))
    pts = np.vstack([a, b])
    assert len(detect_planes(pts, min_points=200)) == 1
    split = detect_planes(pts, min_points=200, cluster_radius_m=0.05)
    assert [p.n_inliers for p in split] == [1500, 1000]
    assert split[0].inliers[:1500].all() and split[1].inliers[1500:].all()


def test_detect_planes_on_pure_noise_finds_nothing_big():
    rng = np.random.default_rng(5)
    assert detect_planes(rng.uniform(-1, 1, (3000, 3)), min_points=300) == []


def test_fit_errors():
    with pytest.raises(EmptyInputError):
        fit_plane_ransac(np.zeros((2, 3)))
    with pytest.raises(InvalidInputError):
        fit_plane_ransac(np.c_[np.arange(10.0), np.zeros(10), np.zeros(10)])
    with pytest.raises(InvalidInputError):
        fit_plane_ransac(np.array([[0, 0, 0], [1, 0, 0], [0, np.nan, 1.0]]))
    with pytest.raises(InvalidInputError):
        detect_planes(np.zeros((10, 3)), min_points=1)
