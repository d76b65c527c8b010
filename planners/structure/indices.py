"""Distinct indices, as the stages need them: ascending, without duplicates.

``np.unique`` on numpy 2.x hashes before it sorts; on the int64 index
arrays of a KD-tree's ball queries (hundreds to tens of thousands of
entries) a sort and a neighbour compare give the same array 4–7× faster,
and the stages call it thousands of times per scan.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable
from typing import Any

import numpy as np


def sorted_unique(a: np.ndarray) -> np.ndarray:
    """The distinct values of the 1-D integer array ``a``, ascending
    (``np.unique(a)``)."""
    out = np.sort(a)
    if len(out) < 2:
        return out
    keep = np.empty(len(out), bool)
    keep[0] = True
    np.not_equal(out[1:], out[:-1], out=keep[1:])
    return out[keep]


def hit_union(hits: Iterable[Any]) -> np.ndarray:
    """The distinct indices in a ball query's hit lists (sorted or not), ascending, as
    int64; ``hits`` is what ``cKDTree.query_ball_point`` answers for (S, 3) points
    (an object array of S lists, which scipy's stubs type as ``list[int]``)."""
    flat = np.fromiter(itertools.chain.from_iterable(hits), dtype=np.int64)
    return sorted_unique(flat)


def points_by_label(labels: np.ndarray, m: int) -> list[np.ndarray]:
    """The indices of the points labelled 0 … ``m`` − 1, ascending, one
    array a label (one sort rather than a pass over every point a member)."""
    order = np.argsort(labels, kind="stable")
    bounds = np.searchsorted(labels[order], np.arange(m + 1))
    return [order[bounds[k] : bounds[k + 1]] for k in range(m)]
