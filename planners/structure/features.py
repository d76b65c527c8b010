"""Multi-scale line features of a cloud (the first stage of the structure model).

A steel member seen from a distance larger than its section is a line: the
covariance of the surface points within a radius r that exceeds the section
has one dominant eigenvalue, λ1 ≫ λ2 (the linearity (λ1 − λ2)/λ1 of
Demantké et al. 2011 dimensionality features), with its eigenvector along
the member.  Sections range from 5 cm angles to 1 m girders, so the
analysis runs at several radii and each voxel keeps the scale at which it
looks most linear.

Bounded memory: at radius r the cloud is voxelised at r/4, so every
neighbourhood holds a bounded number of voxels whatever the point spacing,
and the k-nearest queries run in row chunks.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

#: rows of a neighbour query at a time (× k × 3 floats per chunk)
CHUNK_ROWS = 32_768


@dataclass
class VoxelGrid:
    """Centroids of the occupied cells of edge ``size`` and, per input row,
    the cell it falls in."""

    size: float
    centres: np.ndarray  # (V, 3)
    counts: np.ndarray  # (V,)
    inverse: np.ndarray  # (N,) cell index of each input row


def voxelise(points: np.ndarray, size: float, weights: np.ndarray | None = None) -> VoxelGrid:
    """Weighted centroid per occupied voxel; cells anchored at the cloud's minimum
    corner so coordinates far from the origin (survey frames) keep precision."""
    lo = points.min(axis=0)
    keys = np.floor((points - lo) / size).astype(np.int64)
    _, inverse = np.unique(keys, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    w = np.ones(len(points)) if weights is None else np.asarray(weights, float)
    wsum = np.bincount(inverse, weights=w)
    centres = np.column_stack(
        [np.bincount(inverse, weights=w * points[:, i]) / wsum for i in range(3)]
    )
    return VoxelGrid(size, centres, np.bincount(inverse, weights=w), inverse)


@dataclass
class LineFeatures:
    """Per voxel of the finest grid: the scale (radius, m) at which its
    neighbourhood is most linear, that linearity, the principal direction
    and the neighbourhood mean (which lies near the member's axis)."""

    grid: VoxelGrid
    radius: np.ndarray  # (V,)
    linearity: np.ndarray  # (V,)
    direction: np.ndarray  # (V, 3) unit
    mean: np.ndarray  # (V, 3)
    neighbours: np.ndarray  # (V,) voxels in the chosen neighbourhood


def _local_pca(
    centres: np.ndarray, radius: float, k: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Linearity, principal direction, mean and neighbour count of the ≤ k
    voxels within ``radius`` of each voxel."""
    n = len(centres)
    tree = cKDTree(centres)
    lin = np.zeros(n)
    dirs = np.zeros((n, 3))
    mean = centres.copy()
    cnt = np.zeros(n, dtype=np.int64)
    padded = np.vstack([centres, np.zeros((1, 3))])
    kk = min(k, n)
    for a in range(0, n, CHUNK_ROWS):
        q = centres[a : a + CHUNK_ROWS]
        d, idx = tree.query(q, k=kk, distance_upper_bound=radius)
        idx = np.asarray(idx).reshape(len(q), kk)
        valid = np.isfinite(np.asarray(d).reshape(len(q), kk))
        nb = padded[idx] - q[:, None, :]  # relative coordinates keep precision
        w = valid.astype(float)
        c = w.sum(axis=1)
        mu = (nb * w[..., None]).sum(axis=1) / c[:, None]
        r = (nb - mu[:, None, :]) * w[..., None]
        cov = np.einsum("nki,nkj->nij", r, r) / c[:, None, None]
        ev, evec = np.linalg.eigh(cov)
        l1 = np.maximum(ev[:, 2], 1e-300)
        lin[a : a + len(q)] = np.where(c >= 5, (ev[:, 2] - ev[:, 1]) / l1, 0.0)
        dirs[a : a + len(q)] = evec[:, :, 2]
        mean[a : a + len(q)] = q + mu
        cnt[a : a + len(q)] = c.astype(np.int64)
    return lin, dirs, mean, cnt


def line_features(
    points: np.ndarray, spacing: float, scales: tuple[float, ...], k: int, max_voxels: int
) -> LineFeatures:
    """Multi-scale linearity on a voxel pyramid (finest cell max(s, r0/4),
    enlarged until at most ``max_voxels`` cells)."""
    size = max(spacing, scales[0] / 4.0)
    fine = voxelise(points, size)
    while len(fine.centres) > max_voxels:
        size *= 1.25
        fine = voxelise(points, size)
    v = len(fine.centres)
    best_lin = np.full(v, -1.0)
    best_dir = np.zeros((v, 3))
    best_mean = fine.centres.copy()
    best_r = np.zeros(v)
    best_n = np.zeros(v, dtype=np.int64)
    for r in scales:
        cell = max(size, r / 4.0)
        if cell == size:
            centres, parent = fine.centres, np.arange(v)
        else:
            coarse = voxelise(fine.centres, cell, fine.counts)
            centres, parent = coarse.centres, coarse.inverse
        lin, dirs, mean, cnt = _local_pca(centres, r, k)
        lin_f, dir_f, mean_f, cnt_f = lin[parent], dirs[parent], mean[parent], cnt[parent]
        # larger scales win only when clearly more linear: the smallest scale
        # that sees a line localises it best
        better = lin_f > best_lin + 0.05
        best_lin[better] = lin_f[better]
        best_dir[better] = dir_f[better]
        best_mean[better] = mean_f[better]
        best_r[better] = r
        best_n[better] = cnt_f[better]
    return LineFeatures(fine, best_r, best_lin, best_dir, best_mean, best_n)
