"""Non-Convex Boundary Estimation (NCBE), the seed's Algorithm 1.

For every coordinate axis p the cloud is cut into slices of width αs (the
"sliding factor") centred at ``sl_p,i = d_min,p + i·αs`` for i = 1, 2, …
while the previous centre is below ``d_max,p`` (Alg. 1 lines 7–9); the two
points of each slice that are furthest apart (line 11) are boundary points
(line 12).  Slicing along x finds the lower/upper edges, slicing along y the
left/right ones, so a non-convex outline (an L, a notch) is followed where a
convex hull would bridge it, and small holes inside are ignored.

Literal reading kept on purpose: slice i covers ``[sl - αs/2, sl + αs/2)``
(half-open so that every point is in at most one slice per axis), and, as
in the pseudo-code, the first centre is ``d_min + αs``, so points closer than
αs/2 to ``d_min`` on that axis are only reached by the other axes' slices.

:func:`order_boundary` chains boundary points into a polygon ring (greedy
nearest neighbour) when a caller needs an ordered outline.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, QhullError, cKDTree

from planners.errors import InternalError, InvalidInputError
from planners.pointcloud._validate import as_points, positive


def _diameter_pair(p: np.ndarray) -> tuple[int, int]:
    """Indices of the two points of ``p`` furthest apart (exact).

    The furthest pair lies on the convex hull, so only hull vertices are
    compared; degenerate (collinear) sets use the extremes along their
    principal direction, which is exact for collinear points.
    """
    k = len(p)
    if k == 1:
        return 0, 0
    cand: np.ndarray  # candidate indices into p
    if k <= 64:
        cand = np.arange(k)
    else:
        try:
            cand = ConvexHull(p).vertices
        except QhullError:
            centred = p - p.mean(axis=0)
            _, _, vt = np.linalg.svd(centred, full_matrices=False)
            t = centred @ vt[0]
            return int(np.argmin(t)), int(np.argmax(t))
    q = p[cand]
    d2 = ((q[:, None, :] - q[None, :, :]) ** 2).sum(axis=-1)
    i, j = np.unravel_index(int(np.argmax(d2)), d2.shape)
    return int(cand[min(i, j)]), int(cand[max(i, j)])


def ncbe_boundary_indices(points: np.ndarray, *, sliding_factor: float = 0.02) -> np.ndarray:
    """Indices (into ``points``) of the NCBE boundary points (Alg. 1).

    ``points`` is (N, 2) or (N, 3) (three axes are sliced for 3D input, as
    the seed's ``Planes = {xy, yz, zx}``); ``sliding_factor`` αs in metres.
    Returns sorted unique indices (Alg. 1's B_s is a set).
    """
    pts = as_points(points, "points2d", dims=(2, 3), allow_empty=False)
    alpha = positive(sliding_factor, "sliding_factor")
    chosen: list[np.ndarray] = []
    for axis in range(pts.shape[1]):
        c = pts[:, axis]
        dmin, dmax = float(c.min()), float(c.max())
        # Number of slice centres dmin + i·αs (i ≥ 1) visited by the while loop:
        # it runs while the previous centre is < dmax, so the last centre is the
        # first one ≥ dmax (at least one slice).
        n_slices = max(1, int(np.ceil((dmax - dmin) / alpha - 1e-12)))
        if n_slices > 1_000_000:
            raise InvalidInputError(
                f"sliding_factor={alpha} m gives {n_slices} slices on axis {axis}; "
                "use a larger sliding factor"
            )
        # Slice index of each point: i with sl_i - αs/2 <= c < sl_i + αs/2.
        idx = np.floor((c - dmin) / alpha + 0.5).astype(np.int64)
        inside = (idx >= 1) & (idx <= n_slices)
        members = np.nonzero(inside)[0]
        order = members[np.argsort(idx[members], kind="stable")]
        slice_ids, starts = np.unique(idx[order], return_index=True)
        bounds = np.append(starts, len(order))
        for s in range(len(slice_ids)):  # one iteration per slice, not per point
            group = order[bounds[s] : bounds[s + 1]]
            a, b = _diameter_pair(pts[group])
            chosen.append(group[[a, b]])
    if not chosen:
        return np.zeros(0, dtype=np.int64)
    return np.unique(np.concatenate(chosen))


def ncbe_boundary(points2d: np.ndarray, *, sliding_factor: float = 0.02) -> np.ndarray:
    """Boundary points (K, D) of a planar cloud by NCBE (seed Alg. 1).

    ``points2d`` are the plane's points in plane coordinates (N, 2) — or
    (N, 3) to slice along x, y and z as the seed does with raw 3D points;
    ``sliding_factor`` αs is the slice width in metres (the seed chose it
    "experimentally based on the point cloud size"; 2 cm suits a cloud
    down-sampled to ~5 mm).
    """
    pts = as_points(points2d, "points2d", dims=(2, 3), allow_empty=False)
    return pts[ncbe_boundary_indices(pts, sliding_factor=sliding_factor)]


def order_boundary(points2d: np.ndarray) -> np.ndarray:
    """Order boundary points into a ring by greedy nearest-neighbour chaining.

    Starts at the lowest-x (then lowest-y) point and repeatedly walks to the
    nearest unvisited point; returns the permutation (K,) of row indices.
    This is a helper for display and polygon building, not part of the seed:
    it assumes one outer outline (points of a hole's rim get spliced into the
    ring), and a ring through sparse corners may cut a concave corner.
    Use :func:`planners.pointcloud.hull.alpha_shape` for an exact region.
    """
    pts = as_points(points2d, "points2d", dims=(2, 3), allow_empty=False)
    k = len(pts)
    tree = cKDTree(pts)
    start = int(np.lexsort(pts.T[::-1])[0])
    visited = np.zeros(k, dtype=bool)
    ring = [start]
    visited[start] = True
    cur = start
    # O(K log K) expected: query growing neighbourhoods until an unvisited one.
    for _ in range(k - 1):
        kq = 8
        while True:
            _, nn = tree.query(pts[cur], k=min(kq, k))
            nn = np.atleast_1d(nn)
            free = nn[~visited[nn]]
            if len(free):
                cur = int(free[0])
                break
            if kq >= k:
                raise InternalError("unreachable: unvisited point missing")  # pragma: no cover
            kq *= 4
        visited[cur] = True
        ring.append(cur)
    return np.asarray(ring, dtype=np.int64)
