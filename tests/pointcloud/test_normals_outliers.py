"""Local-PCA normals, the facing filter, and statistical outlier removal."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from planners.errors import InvalidInputError
from planners.pointcloud.filters import statistical_outliers
from planners.pointcloud.normals import estimate_normals, facing_mask


def _frame(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a = np.array([1.0, 0, 0]) if abs(n[0]) < 0.9 else np.array([0, 1.0, 0])
    u = np.cross(n, a)
    u /= np.linalg.norm(u)
    return u, np.cross(n, u)


@settings(max_examples=30, deadline=None)
@given(
    st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1), st.integers(0, 2**31 - 1)
)  # fmt: skip
def test_normals_of_a_noisy_plane_match_its_normal(a, b, c, seed):
    n = np.array([a, b, c])
    if np.linalg.norm(n) < 1e-3:
        n = np.array([0, 0, 1.0])
    n /= np.linalg.norm(n)
    rng = np.random.default_rng(seed)
    u, v = _frame(n)
    uv = rng.uniform(-0.5, 0.5, (400, 2))
    pts = uv[:, :1] * u + uv[:, 1:] * v + rng.normal(scale=1e-4, size=(400, 1)) * n
    est = estimate_normals(pts, k=10)
    np.testing.assert_allclose(np.linalg.norm(est, axis=1), 1.0, atol=1e-9)
    assert np.abs(est @ n).min() > np.cos(np.deg2rad(2.0))


def test_facing_mask_drops_the_strip_of_a_crossing_face():
    # a dense vertical patch (x = 0) and a horizontal face crossing it at z = 0.3
    g = np.linspace(0, 0.3, 31)
    yy, zz = np.meshgrid(g, g)
    patch = np.c_[np.zeros(yy.size), yy.ravel(), zz.ravel() - 0.35]
    xx, yy = np.meshgrid(np.linspace(-0.1, 0.1, 21), g)
    face = np.c_[xx.ravel(), yy.ravel(), np.zeros(xx.size)]
    pts = np.r_[patch, face]
    keep = facing_mask(pts, [1.0, 0, 0], 30.0)
    assert keep[: len(patch)].mean() > 0.95
    assert not keep[len(patch) :].any()
    with pytest.raises(InvalidInputError, match="normal"):
        facing_mask(pts, [0, 0, 0], 30.0)
    with pytest.raises(InvalidInputError, match="max_angle_deg"):
        facing_mask(pts, [1, 0, 0], 0.0)
    with pytest.raises(InvalidInputError, match="k"):
        estimate_normals(pts, k=2)


def test_statistical_outliers_against_brute_force():
    rng = np.random.default_rng(1)
    pts = np.r_[rng.uniform(0, 1, (300, 3)), [[5, 5, 5], [-4, 0, 0]]]
    out = statistical_outliers(pts, k=6, std_ratio=3.0)
    d = np.linalg.norm(pts[:, None] - pts[None], axis=-1)
    md = np.sort(d, axis=1)[:, 1:7].mean(axis=1)
    np.testing.assert_array_equal(out, md > md.mean() + 3.0 * md.std())
    assert out[-2:].all() and out[:-2].sum() == 0
    assert not statistical_outliers(pts[:5], k=8).any()  # too few points to judge
    with pytest.raises(InvalidInputError):
        statistical_outliers(pts, std_ratio=0.0)
