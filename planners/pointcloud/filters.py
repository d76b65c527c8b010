"""Point-cloud pre-processing: pass-through filter, voxel-grid down-sampling,
non-finite removal (the seed's §3.1 "pass-through filtering, downsampling"
before RANSAC plane detection, as PCL's PassThrough / VoxelGrid do it).
"""

from __future__ import annotations

import numpy as np

from planners.errors import InvalidInputError
from planners.pointcloud._validate import as_points, positive

Limit = tuple[float, float] | None


def _check_limit(limit: Limit, axis: str) -> tuple[float, float] | None:
    if limit is None:
        return None
    try:
        lo, hi = (float(v) for v in limit)
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(
            f"pass-through limit {axis} must be a (lo, hi) pair in metres or None, got {limit!r}"
        ) from exc
    if np.isnan(lo) or np.isnan(hi) or lo > hi:
        raise InvalidInputError(f"pass-through limit {axis}={limit!r} needs lo <= hi (metres)")
    return lo, hi


def passthrough(
    points: np.ndarray, *, x: Limit = None, y: Limit = None, z: Limit = None
) -> np.ndarray:
    """Boolean mask of the points with ``lo <= coord <= hi`` on every given axis.

    ``points`` is (N, 3); an axis whose limit is ``None`` is not filtered.  Rows
    with NaN in a filtered coordinate are excluded (a NaN compares false).
    """
    pts = as_points(points, "points", dims=3, finite=False)
    mask = np.ones(len(pts), dtype=bool)
    for col, (axis, limit) in enumerate((("x", x), ("y", y), ("z", z))):
        lim = _check_limit(limit, axis)
        if lim is not None:
            c = pts[:, col]
            mask &= (c >= lim[0]) & (c <= lim[1])
    return mask


def voxel_downsample(points: np.ndarray, voxel_m: float) -> np.ndarray:
    """Centroid of the points in every occupied cubic voxel of edge ``voxel_m``.

    Voxels are the cells ``floor(p / voxel_m)`` of a grid anchored at the
    origin (so results do not depend on the cloud's extent); the output rows
    are sorted by voxel index (lexicographic), hence deterministic.  Works
    for any column count D ≥ 1; non-finite rows are rejected.
    """
    pts = as_points(points, "points", dims=tuple(range(1, 8)))
    voxel = positive(voxel_m, "voxel_m")
    if len(pts) == 0:
        return pts.copy()
    keys = np.floor(pts / voxel).astype(np.int64)
    # np.unique over rows sorts lexicographically: deterministic output order.
    _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    # bincount per column is a vectorised group-sum (much faster than add.at).
    sums = np.stack(
        [
            np.bincount(inverse, weights=pts[:, j], minlength=len(counts))
            for j in range(pts.shape[1])
        ],
        axis=1,
    )
    return sums / counts[:, None]


def drop_nonfinite(points: np.ndarray) -> tuple[np.ndarray, int]:
    """Remove rows holding NaN or ±inf; returns ``(clean, n_dropped)``."""
    pts = as_points(points, "points", dims=tuple(range(1, 8)), finite=False)
    keep = np.all(np.isfinite(pts), axis=1)
    return pts[keep], int(len(pts) - np.count_nonzero(keep))


def statistical_outliers(points: np.ndarray, k: int = 8, std_ratio: float = 3.0) -> np.ndarray:
    """Mask of outliers as PCL's StatisticalOutlierRemoval finds them: a point
    whose mean distance to its ``k`` nearest neighbours exceeds the mean of
    that statistic over the cloud by more than ``std_ratio`` standard
    deviations."""
    from scipy.spatial import cKDTree

    pts = as_points(points, "points", dims=3)
    k = int(k)
    if k < 1:
        raise InvalidInputError(f"k must be >= 1, got {k}")
    positive(std_ratio, "std_ratio")
    if len(pts) <= k:
        return np.zeros(len(pts), dtype=bool)
    d = np.asarray(cKDTree(pts).query(pts, k=k + 1)[0])  # k + 1 ≥ 2: an array
    mean_d = d[:, 1:].mean(axis=1)
    return mean_d > mean_d.mean() + float(std_ratio) * mean_d.std()
