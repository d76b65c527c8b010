"""Per-point surface normals by local PCA (the k nearest neighbours'
covariance; the normal is the eigenvector of its smallest eigenvalue), as
PCL's NormalEstimation does it.  Used to keep only the points of a RANSAC
plane whose own surface faces the same way: a distance threshold alone also
takes the strip where a perpendicular face (a flange) crosses the plane.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from planners.errors import InvalidInputError
from planners.pointcloud._validate import as_points


def estimate_normals(points: np.ndarray, k: int = 12) -> np.ndarray:
    """Unit normals (N,3), sign arbitrary, from the ``k`` nearest neighbours
    (the point included) of each point.  Batched: one KD-tree query and one
    batched symmetric eigendecomposition."""
    pts = as_points(points, "points", dims=3)
    k = int(k)
    if k < 3:
        raise InvalidInputError(f"k must be >= 3 neighbours, got {k}")
    if len(pts) < k:
        raise InvalidInputError(f"need at least k={k} points for normals, got {len(pts)}")
    _, idx = cKDTree(pts).query(pts, k=k)
    nb = pts[idx]  # (N,k,3)
    d = nb - nb.mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", d, d)
    _, vec = np.linalg.eigh(cov)  # ascending eigenvalues
    return vec[:, :, 0]


def facing_mask(
    points: np.ndarray, normal: np.ndarray, max_angle_deg: float, k: int = 12
) -> np.ndarray:
    """Points whose local normal is within ``max_angle_deg`` of ±``normal``."""
    n = np.asarray(normal, dtype=float)
    if n.shape != (3,) or not np.all(np.isfinite(n)) or np.linalg.norm(n) == 0:
        raise InvalidInputError(f"normal must be a finite non-zero 3-vector, got {normal!r}")
    if not 0.0 < float(max_angle_deg) <= 90.0:
        raise InvalidInputError(f"max_angle_deg must be in (0, 90], got {max_angle_deg!r}")
    cosang = np.abs(estimate_normals(points, k) @ (n / np.linalg.norm(n)))
    return cosang >= np.cos(np.deg2rad(float(max_angle_deg)))
