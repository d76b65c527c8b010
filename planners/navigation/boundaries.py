"""Cluster geometry: centre, principal axis, NCBE boundary polygon (seed Alg. 1, Alg. 3 l. 5–7).

Every cluster's boundary points come from the shared NCBE implementation
(:func:`planners.pointcloud.ncbe_boundary`, seed Alg. 1) with the sliding
factor αs.  Two choices beyond the seed, both for the boundary check (Alg. 6):

* the NCBE input of a cluster includes the border points its neighbours
  share with it, so adjacent boundaries overlap by the border width instead
  of leaving a sliver between them that a footprint point could fall into;
* the boundary points are ordered by angle about the cluster centre into a
  polygon.  The polygon is then star-shaped about the centre by construction,
  which is what the centre-based test of Alg. 6 assumes (bars are convex,
  crossings star-shaped about their centre).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from planners.navigation.segmentation import Border
from planners.pointcloud import ncbe_boundary


@dataclass
class Cluster:
    """One segment of the structure (seed §4.1): a bar or a cross area."""

    id: int
    kind: str  # "bar" | "cross"
    n_points: int
    centre: np.ndarray  # (2,) plane coordinates, metres
    axis: np.ndarray  # (2,) unit principal direction
    length_m: float  # extent along the axis (2–98 % quantiles)
    width_m: float  # extent across the axis (2–98 % quantiles)
    boundary: np.ndarray  # (K, 2) polygon, counter-clockwise about the centre

    def as_dict(self) -> dict[str, object]:
        return {
            "id": self.id,
            "kind": self.kind,
            "n_points": self.n_points,
            "centre": self.centre.tolist(),
            "axis": self.axis.tolist(),
            "length_m": self.length_m,
            "width_m": self.width_m,
            "boundary": self.boundary.tolist(),
        }


def star_polygon(points: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """Order ``points`` by angle about ``centre`` (ties: nearer first); drop duplicates."""
    d = points - centre
    ang = np.arctan2(d[:, 1], d[:, 0])
    rad = np.hypot(d[:, 0], d[:, 1])
    order = np.lexsort((rad, ang))
    poly = points[order]
    keep = np.ones(len(poly), dtype=bool)
    keep[1:] = np.any(np.abs(np.diff(poly, axis=0)) > 1e-12, axis=1)
    return poly[keep]


def cluster_geometry(
    uv: np.ndarray,
    labels: np.ndarray,
    kinds: Sequence[str],
    borders: Sequence[Border],
    *,
    sliding_factor_m: float = 0.02,
) -> list[Cluster]:
    """Geometry of every cluster (loops over clusters, vectorised inside)."""
    extra: dict[int, list[np.ndarray]] = {k: [] for k in range(len(kinds))}
    for br in borders:
        extra[br.a].append(br.points)
        extra[br.b].append(br.points)
    out: list[Cluster] = []
    for k, kind in enumerate(kinds):
        own = np.nonzero(labels == k)[0]
        pts = uv[own]
        centre = pts.mean(axis=0)
        if len(pts) >= 2:
            _, _, vt = np.linalg.svd(pts - centre, full_matrices=False)
            axis = vt[0]
        else:
            axis = np.array([1.0, 0.0])
        # A deterministic sign for the axis: first non-zero component positive.
        if axis[0] < 0 or (axis[0] == 0 and axis[1] < 0):
            axis = -axis
        s = (pts - centre) @ axis
        t = (pts - centre) @ np.array([-axis[1], axis[0]])
        length = float(np.subtract(*np.percentile(s, [98, 2])))
        width = float(np.subtract(*np.percentile(t, [98, 2])))
        idx = np.unique(np.concatenate([own, *extra[k]])) if extra[k] else own
        bpts = ncbe_boundary(uv[idx], sliding_factor=sliding_factor_m) if len(idx) >= 3 else uv[idx]
        out.append(
            Cluster(
                id=k,
                kind=kind,
                n_points=len(own),
                centre=centre,
                axis=axis,
                length_m=length,
                width_m=width,
                boundary=star_polygon(bpts, centre),
            )
        )
    return out


def line_polygon_hits(
    centre: np.ndarray, direction: np.ndarray, polygon: np.ndarray
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Farthest intersections of the line ``centre + s·direction`` with the
    polygon's edges on the + and − side (seed Alg. 4 line 10: feature line ∩ boundary)."""
    a = polygon
    b = np.roll(polygon, -1, axis=0)
    e = b - a
    # Solve centre + s·d = a + u·e for (s, u), vectorised over edges.
    den = direction[0] * (-e[:, 1]) - direction[1] * (-e[:, 0])
    rhs = a - centre
    ok = np.abs(den) > 1e-12
    den_safe = np.where(ok, den, 1.0)
    s = (rhs[:, 0] * (-e[:, 1]) - rhs[:, 1] * (-e[:, 0])) / den_safe
    u = (direction[0] * rhs[:, 1] - direction[1] * rhs[:, 0]) / den_safe
    hit = ok & (u >= 0) & (u <= 1)
    plus = hit & (s > 0)
    minus = hit & (s < 0)
    p = centre + s[plus].max() * direction if np.any(plus) else None
    m = centre + s[minus].min() * direction if np.any(minus) else None
    return p, m
