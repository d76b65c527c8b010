"""Concave hull (alpha shape) of a planar cloud, as an exact region.

Not from the seed: used as the independent reference the seed's Alg. 2
verdict is cross-checked against (a foot rectangle must lie inside the
plane's concave hull).  The alpha shape keeps the Delaunay triangles whose
circumradius is below ``alpha_m`` and unions them, so concavities and holes
larger than about 2·alpha_m survive [Edelsbrunner et al. 1983].
"""

from __future__ import annotations

import numpy as np
import shapely
from scipy.spatial import Delaunay, QhullError
from shapely.geometry.base import BaseGeometry

from planners.errors import InvalidInputError
from planners.pointcloud._validate import as_points, positive


def alpha_shape(points2d: np.ndarray, alpha_m: float) -> BaseGeometry:
    """Union of the Delaunay triangles of ``points2d`` with circumradius < ``alpha_m``.

    Returns a shapely ``Polygon``/``MultiPolygon`` (possibly with holes), or an
    empty polygon when no triangle qualifies.  Choose ``alpha_m`` ≈ 2–3 × the
    point spacing: smaller breaks the region apart, larger bridges gaps.
    """
    pts = as_points(points2d, "points2d", dims=2, allow_empty=False)
    alpha = positive(alpha_m, "alpha_m")
    if len(pts) < 3:
        return shapely.Polygon()
    try:
        tri = Delaunay(pts)
    except QhullError as exc:
        raise InvalidInputError(f"points2d are degenerate (collinear?): {exc}") from exc
    corners = pts[tri.simplices]  # (T, 3, 2)
    a = np.linalg.norm(corners[:, 1] - corners[:, 2], axis=1)
    b = np.linalg.norm(corners[:, 0] - corners[:, 2], axis=1)
    c = np.linalg.norm(corners[:, 0] - corners[:, 1], axis=1)
    e1, e2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    area2 = np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])  # twice the area
    with np.errstate(divide="ignore", invalid="ignore"):
        circum_r = a * b * c / (2.0 * area2)
    keep = np.isfinite(circum_r) & (circum_r < alpha)
    if not np.any(keep):
        return shapely.Polygon()
    rings = np.concatenate([corners[keep], corners[keep][:, :1]], axis=1)  # closed
    polys = shapely.polygons(rings)
    # Delaunay triangles never overlap and share whole edges: a polygonal
    # coverage, which coverage_union_all dissolves ~30x faster than union_all.
    return shapely.coverage_union_all(polys)
