"""Filters vs brute-force Python references."""

from __future__ import annotations

import math
from collections import defaultdict

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from planners.errors import InvalidInputError
from planners.pointcloud import drop_nonfinite, passthrough, voxel_downsample

coords = st.floats(-2.0, 2.0, allow_nan=False, width=64)
small_clouds = arrays(np.float64, st.tuples(st.integers(0, 40), st.just(3)), elements=coords)


@settings(max_examples=60, deadline=None)
@given(small_clouds, st.sampled_from([0.05, 0.1, 0.37, 1.0]))
def test_voxel_downsample_matches_brute_force(points, voxel):
    got = voxel_downsample(points, voxel)
    groups: dict[tuple[int, ...], list[np.ndarray]] = defaultdict(list)
    for p in points:  # reference: one Python dict entry per voxel
        groups[tuple(math.floor(v / voxel) for v in p)].append(p)
    want = np.array([np.mean(groups[k], axis=0) for k in sorted(groups)]).reshape(-1, 3)
    assert got.shape == want.shape
    np.testing.assert_allclose(got, want, atol=1e-12)


@settings(max_examples=60, deadline=None)
@given(
    small_clouds,
    st.one_of(st.none(), st.tuples(coords, coords).map(sorted).map(tuple)),
    st.one_of(st.none(), st.tuples(coords, coords).map(sorted).map(tuple)),
)
def test_passthrough_matches_brute_force(points, xlim, zlim):
    mask = passthrough(points, x=xlim, z=zlim)
    for p, m in zip(points, mask, strict=True):
        ok = (xlim is None or xlim[0] <= p[0] <= xlim[1]) and (
            zlim is None or zlim[0] <= p[2] <= zlim[1]
        )
        assert m == ok


def test_voxel_output_is_deterministic_and_order_independent():
    rng = np.random.default_rng(3)
    pts = rng.uniform(-1, 1, (5000, 3))
    a = voxel_downsample(pts, 0.1)
    b = voxel_downsample(pts[rng.permutation(len(pts))], 0.1)
    np.testing.assert_allclose(a, b, atol=1e-12)


def test_drop_nonfinite_counts_rows():
    pts = np.array([[0, 0, 0], [np.nan, 1, 1], [1, np.inf, 0], [2, 2, 2.0]])
    clean, dropped = drop_nonfinite(pts)
    assert dropped == 2
    np.testing.assert_array_equal(clean, [[0, 0, 0], [2, 2, 2]])


@pytest.mark.parametrize(
    "call",
    [
        lambda: passthrough(np.zeros((3, 2))),
        lambda: passthrough(np.zeros((3, 3)), x=(1.0, 0.0)),
        lambda: passthrough(np.zeros((3, 3)), y="a"),
        lambda: voxel_downsample(np.zeros((3, 3)), 0.0),
        lambda: voxel_downsample(np.array([[np.nan, 0, 0]]), 0.1),
        lambda: voxel_downsample(np.zeros(3), 0.1),
    ],
)
def test_bad_input_raises(call):
    with pytest.raises(InvalidInputError):
        call()
