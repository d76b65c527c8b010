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
from scipy.sparse import csr_matrix
from scipy.spatial import cKDTree

#: rows of a neighbour query at a time (× k × 3 floats per chunk)
CHUNK_ROWS = 32_768
#: threads of the stages' batch KD-tree queries (scipy's ``workers``): each
#: query point is answered on its own, so the answers are the same for any
#: count; two is what this project's 2-core target machines have
QUERY_WORKERS = 2


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
    # one int64 key per cell: a 1-D unique sorts ~10× faster than rows
    span = keys.max(axis=0) + 1
    flat = (keys[:, 0] * span[1] + keys[:, 1]) * span[2] + keys[:, 2]
    _, inverse = np.unique(flat, return_inverse=True)
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
    voxels within ``radius`` of each voxel.

    The neighbourhood moments are sparse products: the k-nearest relation is
    a sparse (n × n) matrix with at most k entries a row, and its products
    with the coordinates and their pairwise products give every
    neighbourhood's sums at once (coordinates are relative to the cloud's
    corner, metres, so E[xx] − E[x]² keeps its precision)."""
    n = len(centres)
    tree = cKDTree(centres)
    kk = min(k, n)
    per_row, cols_l = [], []
    for a in range(0, n, CHUNK_ROWS):
        q = centres[a : a + CHUNK_ROWS]
        _, idx = tree.query(q, k=kk, distance_upper_bound=radius, workers=QUERY_WORKERS)
        # a missing neighbour's index is n: sorted, each row's columns come
        # first and ascending, the CSR layout itself (no COO conversion)
        idx = np.sort(np.asarray(idx).reshape(len(q), kk), axis=1)
        ok = idx < n
        per_row.append(ok.sum(axis=1))
        cols_l.append(idx[ok])
    cols = np.concatenate(cols_l)
    indptr = np.concatenate([[0], np.cumsum(np.concatenate(per_row))])
    adj = csr_matrix((np.ones(len(cols)), cols, indptr), shape=(n, n))
    x = centres - centres.mean(axis=0)
    prods = np.column_stack(
        [x, x[:, 0] * x[:, 0], x[:, 0] * x[:, 1], x[:, 0] * x[:, 2],
         x[:, 1] * x[:, 1], x[:, 1] * x[:, 2], x[:, 2] * x[:, 2]]
    )  # fmt: skip
    sums = adj @ prods
    cnt = np.asarray(adj.sum(axis=1)).ravel()
    c = np.maximum(cnt, 1.0)
    mu = sums[:, :3] / c[:, None]
    m2 = sums[:, 3:] / c[:, None]
    cov = np.empty((n, 3, 3))
    ij = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))
    for col, (i, j) in enumerate(ij):
        cov[:, i, j] = cov[:, j, i] = m2[:, col] - mu[:, i] * mu[:, j]
    lin = np.zeros(n)
    dirs = np.zeros((n, 3))
    for a in range(0, n, CHUNK_ROWS):
        ev, evec = np.linalg.eigh(cov[a : a + CHUNK_ROWS])
        l1 = np.maximum(ev[:, 2], 1e-300)
        lin[a : a + len(ev)] = np.where(cnt[a : a + len(ev)] >= 5, (ev[:, 2] - ev[:, 1]) / l1, 0.0)
        dirs[a : a + len(ev)] = evec[:, :, 2]
    mean = mu + centres.mean(axis=0)
    return lin, dirs, mean, cnt.astype(np.int64)


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
