"""Distinct indices (planners.structure.indices) against numpy's own unique."""

from __future__ import annotations

from typing import cast

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from planners.structure.indices import hit_union, sorted_unique


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(-(2**40), 2**40), max_size=200), st.booleans())
def test_sorted_unique_equals_np_unique(values: list[int], narrow: bool) -> None:
    a = np.array(values, dtype=np.int64)
    if narrow:  # many repeats
        a = a % 7
    got = sorted_unique(a)
    assert got.dtype == np.int64
    assert got.tolist() == np.unique(a).tolist()


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 10_000), st.integers(1, 30), st.floats(0.05, 1.0))
def test_hit_union_is_the_union_of_a_ball_query(seed: int, k: int, r: float) -> None:
    rng = np.random.default_rng(seed)
    pts = rng.uniform(0, 3, (500, 3))
    tree = cKDTree(pts)
    centres = rng.uniform(0, 3, (k, 3))
    hits = cast(list[list[int]], tree.query_ball_point(centres, r, return_sorted=False))
    want = sorted({int(i) for h in hits for i in h})
    got = hit_union(hits)
    assert got.dtype == np.int64
    assert got.tolist() == want
    assert hit_union([]).tolist() == []
