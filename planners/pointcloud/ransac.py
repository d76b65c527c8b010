"""RANSAC plane fitting and sequential multi-plane detection.

The seed (§3.1, "Plane availability") extracts the planar point cloud P_cl
with RANSAC [Fischler & Bolles 1981] after pass-through filtering and
down-sampling, and takes its centroid and normal (Eq. 3.2).  Here every
hypothesis batch is scored at once with numpy; the winning plane is refitted
by least squares (SVD of the inliers) and the inliers re-selected.
:func:`detect_planes` repeats this on the remaining points (sequential RANSAC)
so every plane in view is found, not only the largest.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from planners.errors import EmptyInputError, InvalidInputError
from planners.pointcloud._validate import as_points, positive

# Largest hypotheses×points block scored at once (floats); bounds memory.
_BLOCK = 4_000_000


@dataclass
class PlaneFit:
    """A plane ``normal · p + d = 0`` fitted to a cloud.

    ``normal`` is a unit (3,) vector oriented so that ``d >= 0`` (it points
    towards the origin, i.e. towards a sensor at the origin of the cloud's
    frame); ``centroid`` is the mean of the inliers; ``inliers`` is a boolean
    mask over the points given to the fitting function; ``rms_m`` the RMS
    point-to-plane distance of the inliers.
    """

    normal: np.ndarray
    d: float
    centroid: np.ndarray
    inliers: np.ndarray
    rms_m: float

    @property
    def n_inliers(self) -> int:
        return int(np.count_nonzero(self.inliers))

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Signed point-to-plane distances (metres) of (N, 3) ``points``."""
        return np.asarray(points, dtype=float) @ self.normal + self.d


def _orient(normal: np.ndarray, d: float) -> tuple[np.ndarray, float]:
    """Fix the sign ambiguity deterministically: d > 0, else largest |n_i| > 0."""
    if abs(d) > 1e-12:
        s = 1.0 if d > 0 else -1.0
    else:
        # Plane through the origin: orientation by the dominant component.
        s = 1.0 if normal[int(np.argmax(np.abs(normal)))] > 0 else -1.0
        d = 0.0
    return normal * s, float(d * s)


def _lsq_plane(points: np.ndarray) -> tuple[np.ndarray, float, np.ndarray]:
    """Total-least-squares plane through ``points``: (normal, d, centroid)."""
    c = points.mean(axis=0)
    # Smallest right-singular vector of the centred points = plane normal.
    _, _, vt = np.linalg.svd(points - c, full_matrices=False)
    n = vt[-1]
    n = n / np.linalg.norm(n)
    return n, float(-n @ c), c


def fit_plane_ransac(
    points: np.ndarray,
    *,
    threshold_m: float = 0.01,
    iterations: int = 500,
    seed: int = 0,
    refine: bool = True,
) -> PlaneFit:
    """Fit one plane by RANSAC (most inliers within ``threshold_m``).

    ``iterations`` random 3-point hypotheses are drawn with
    ``np.random.default_rng(seed)`` and scored in blocks; ties go to the lower
    inlier RMS.  With ``refine`` the plane is refitted by least squares on its
    inliers and the inliers re-selected with the refitted plane.
    Raises :class:`EmptyInputError` for fewer than 3 points and
    :class:`InvalidInputError` when all points are collinear.
    """
    pts = as_points(points, "points", dims=3)
    thr = positive(threshold_m, "threshold_m")
    if int(iterations) < 1:
        raise InvalidInputError(f"iterations must be >= 1, got {iterations!r}")
    n_pts = len(pts)
    if n_pts < 3:
        raise EmptyInputError(f"points has {n_pts} point(s); a plane needs at least 3")
    rng = np.random.default_rng(seed)
    # Centre the cloud first: float cancellation in the cross products is
    # smaller and far-from-origin clouds (real scans at 20 m) fit as well.
    origin = pts.mean(axis=0)
    local = pts - origin
    idx = rng.integers(0, n_pts, size=(int(iterations), 3))
    a, b, c = local[idx[:, 0]], local[idx[:, 1]], local[idx[:, 2]]
    normals = np.cross(b - a, c - a)
    norms = np.linalg.norm(normals, axis=1)
    scale = max(float(np.ptp(local, axis=0).max()), 1e-12)
    good = norms > 1e-9 * scale**2  # drop degenerate (collinear / repeated) triples
    if not np.any(good):
        # Retry with fresh triples before declaring the cloud collinear.
        extra = rng.integers(0, n_pts, size=(max(int(iterations), 200), 3))
        a, b, c = local[extra[:, 0]], local[extra[:, 1]], local[extra[:, 2]]
        normals = np.cross(b - a, c - a)
        norms = np.linalg.norm(normals, axis=1)
        good = norms > 1e-9 * scale**2
        if not np.any(good):
            raise InvalidInputError("points are collinear or repeated; no plane can be fitted")
    normals = normals[good] / norms[good, None]
    ds = -np.einsum("ij,ij->i", normals, a[good])
    best_count, best_sq, best_k = -1, np.inf, 0
    block = max(1, _BLOCK // n_pts)
    for s in range(0, len(normals), block):
        dist = np.abs(local @ normals[s : s + block].T + ds[s : s + block])  # (N, B)
        inl = dist <= thr
        counts = inl.sum(axis=0)
        sq = np.where(inl, dist**2, 0.0).sum(axis=0)
        # Lexicographic best: more inliers, then smaller summed squared residual.
        order = np.lexsort((sq, -counts))
        k = int(order[0])
        if counts[k] > best_count or (counts[k] == best_count and sq[k] < best_sq):
            best_count, best_sq, best_k = int(counts[k]), float(sq[k]), s + k
    n, d = normals[best_k], float(ds[best_k])
    inliers = np.abs(local @ n + d) <= thr
    if refine and np.count_nonzero(inliers) >= 3:
        for _ in range(2):  # refit, re-select; two rounds settle in practice
            n_new, d_new, _ = _lsq_plane(local[inliers])
            new_inl = np.abs(local @ n_new + d_new) <= thr
            if np.count_nonzero(new_inl) < 3:
                break
            n, d, inliers = n_new, d_new, new_inl
    # Back to the caller's frame: n·(p - o) + d = 0  ⇒  n·p + (d - n·o) = 0.
    d_world = d - float(n @ origin)
    n, d_world = _orient(n, d_world)
    resid = pts[inliers] @ n + d_world
    return PlaneFit(
        normal=n,
        d=d_world,
        centroid=pts[inliers].mean(axis=0),
        inliers=inliers,
        rms_m=float(np.sqrt(np.mean(resid**2))) if len(resid) else 0.0,
    )


def connected_parts(points: np.ndarray, radius_m: float) -> np.ndarray:
    """Connected-component label per point of the graph linking points closer
    than ``radius_m`` (Euclidean clustering, as PCL's EuclideanClusterExtraction)."""
    pts = as_points(points, "points", dims=(2, 3))
    r = positive(radius_m, "radius_m")
    if len(pts) == 0:
        return np.zeros(0, dtype=np.int64)
    pairs = cKDTree(pts).query_pairs(r, output_type="ndarray")
    graph = coo_matrix(
        (np.ones(len(pairs), dtype=np.int8), (pairs[:, 0], pairs[:, 1])),
        shape=(len(pts), len(pts)),
    )
    _, labels = connected_components(graph, directed=False)
    return labels.astype(np.int64)


def _fit_from_mask(pts: np.ndarray, mask: np.ndarray) -> PlaneFit:
    n, d, c = _lsq_plane(pts[mask])
    n, d = _orient(n, d)
    resid = pts[mask] @ n + d
    return PlaneFit(
        normal=n, d=d, centroid=c, inliers=mask, rms_m=float(np.sqrt(np.mean(resid**2)))
    )


def detect_planes(
    points: np.ndarray,
    *,
    threshold_m: float = 0.01,
    min_points: int = 200,
    max_planes: int = 10,
    iterations: int = 500,
    seed: int = 0,
    cluster_radius_m: float | None = None,
) -> list[PlaneFit]:
    """Sequential RANSAC: fit the plane with most inliers, remove its inliers,
    repeat on the rest until fewer than ``min_points`` inliers or ``max_planes``.

    With ``cluster_radius_m`` each plane's inliers are split into spatially
    connected components (points within that radius are connected), so two
    coplanar but separate slabs come out as two planes; each component with
    ≥ ``min_points`` points is refitted by least squares.  Returned planes are
    in discovery order (components largest first); every ``inliers`` mask is
    over the input ``points``.  Attempt ``k`` uses seed ``seed + k``.
    """
    pts = as_points(points, "points", dims=3)
    if int(min_points) < 3:
        raise InvalidInputError(f"min_points must be >= 3, got {min_points!r}")
    if int(max_planes) < 1:
        raise InvalidInputError(f"max_planes must be >= 1, got {max_planes!r}")
    if cluster_radius_m is not None:
        positive(cluster_radius_m, "cluster_radius_m")
    remaining = np.arange(len(pts))
    planes: list[PlaneFit] = []
    attempt = 0
    while len(planes) < int(max_planes) and len(remaining) >= int(min_points):
        try:
            fit = fit_plane_ransac(
                pts[remaining],
                threshold_m=threshold_m,
                iterations=iterations,
                seed=seed + attempt,
            )
        except InvalidInputError:
            break  # what is left is collinear: no more planes
        attempt += 1
        if fit.n_inliers < int(min_points):
            break
        sub = remaining[fit.inliers]
        if cluster_radius_m is None:
            mask = np.zeros(len(pts), dtype=bool)
            mask[sub] = True
            planes.append(PlaneFit(fit.normal, fit.d, fit.centroid, mask, fit.rms_m))
        else:
            labels = connected_parts(pts[sub], cluster_radius_m)
            sizes = np.bincount(labels)
            for lab in np.argsort(-sizes, kind="stable"):
                if sizes[lab] < int(min_points) or len(planes) >= int(max_planes):
                    break
                mask = np.zeros(len(pts), dtype=bool)
                mask[sub[labels == lab]] = True
                planes.append(_fit_from_mask(pts, mask))
        # All inliers leave the pool (also small components) so the loop ends.
        remaining = remaining[~fit.inliers]
    return planes
