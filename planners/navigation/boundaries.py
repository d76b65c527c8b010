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
  crossings star-shaped about their centre);
* a bar is sliced in its own principal frame (Alg. 1's "planes" are the
  bar's axis and its normal, so every slice cuts straight across the bar or
  along it), and its points are ordered by angle in that frame scaled to a
  square (s / length, t / width).  Ordering a long, thin bar's points by
  their plain angle about the centre interleaves the far end's top-edge,
  bottom-edge and end-cap points (their angles differ by less than the
  noise), which drew spikes deep into the bar — the wheel patch could not
  drive straight along a bar whose boundary crossed its centre line.  A
  linear map with a positive determinant keeps the cyclic order of
  directions about the centre, so the polygon is still star-shaped about the
  centre in plane coordinates and Alg. 6's angular test stays exact.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from planners.errors import InvalidInputError
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


POLYGON_METHODS = ("strips", "stars")


def cluster_geometry(
    uv: np.ndarray,
    labels: np.ndarray,
    kinds: Sequence[str],
    borders: Sequence[Border],
    *,
    sliding_factor_m: float = 0.02,
    polygons: str = "strips",
) -> list[Cluster]:
    """Geometry of every cluster (loops over clusters, vectorised inside).

    ``polygons``: ``"strips"`` (default segmentation) — a bar's boundary is
    its s-monotone slice ring (:func:`_bar_polygon`) over its own points and
    the border points inside its lateral band, a cross area's the convex
    hull of its own points; ``"stars"`` (the seed's GMM blobs) — NCBE points
    of own + border points ordered by angle about the centre.
    """
    if polygons not in POLYGON_METHODS:
        raise InvalidInputError(f"polygons must be one of {POLYGON_METHODS}, got {polygons!r}")
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
        normal = np.array([-axis[1], axis[0]])
        s = (pts - centre) @ axis
        t = (pts - centre) @ normal
        length = float(np.subtract(*np.percentile(s, [98, 2])))
        width = float(np.subtract(*np.percentile(t, [98, 2])))
        idx = np.unique(np.concatenate([own, *extra[k]])) if extra[k] else own
        if polygons == "strips" and kind == "bar" and len(own) >= 3:
            # Border points only inside the bar's own lateral band: the ring
            # reaches into the neighbouring cross area along the strip, never
            # across the notch between two bars that meet there.
            tb = (uv[idx] - centre) @ normal
            band = idx[(tb >= t.min()) & (tb <= t.max())]
            boundary = _bar_polygon(uv[band], centre, axis, sliding_factor_m)
        elif polygons == "strips" and len(own) >= 3:
            boundary = _hull_polygon(pts)
        else:
            bpts = (
                ncbe_boundary(uv[idx], sliding_factor=sliding_factor_m)
                if len(idx) >= 3
                else uv[idx]
            )
            boundary = star_polygon(bpts, centre)
        out.append(
            Cluster(
                id=k,
                kind=kind,
                n_points=len(own),
                centre=centre,
                axis=axis,
                length_m=length,
                width_m=width,
                boundary=boundary,
            )
        )
    return out


def _hull_polygon(pts: np.ndarray) -> np.ndarray:
    """Counter-clockwise convex hull of a cross area's points (the overlap of
    straight strips is convex; for three or more it is star-shaped about the
    joint, and the hull adds only the little between the strips' overlaps)."""
    try:
        return pts[ConvexHull(pts).vertices]
    except QhullError:
        return pts[[int(np.argmin(pts[:, 0])), int(np.argmax(pts[:, 0]))]]


def _bar_polygon(
    pts: np.ndarray,
    centre: np.ndarray,
    axis: np.ndarray,
    sliding_factor_m: float,
    fill_slices: int = 1,
) -> np.ndarray:
    """NCBE (Alg. 1) of a bar sliced across its own axis, as an s-monotone ring.

    Each slice of width αs across the bar contributes its two furthest points
    (Alg. 1 line 11), here the points of largest and smallest ``t`` (offset
    across the axis): the upper chain runs along the bar in ``s``, the lower
    chain back.  Plane coordinates, counter-clockwise.
    """
    normal = np.array([-axis[1], axis[0]])
    s = (pts - centre) @ axis
    t = (pts - centre) @ normal
    sl = np.floor((s - s.min()) / sliding_factor_m).astype(np.int64)
    order = np.lexsort((t, sl))
    first = np.ones(len(order), dtype=bool)
    first[1:] = sl[order][1:] != sl[order][:-1]
    last = np.ones(len(order), dtype=bool)
    last[:-1] = first[1:]
    lower, upper = order[first], order[last]  # per slice, ascending s
    # End caps: the outward side of the end slices' convex hulls, from one
    # chain's end to the other's, counter-clockwise.
    st = np.column_stack([s, t])
    right = _hull_arc(st, np.nonzero(sl == sl.max())[0], lower[-1], upper[-1])
    left = _hull_arc(st, np.nonzero(sl == 0)[0], upper[0], lower[0])
    # A dropout hole at a flange edge leaves one slice whose extreme point
    # lies far inside the flange: a spike narrower than the real steel.  The
    # interior slices take the outermost offset of their neighbours
    # (a ±fill_slices running max / min), which fills holes up to that many
    # slices long and cannot reach past the bar's own widest neighbour.
    t_up, t_lo = t[upper].copy(), t[lower].copy()
    if fill_slices > 0 and len(upper) > 2:
        k = len(upper)
        for d in range(1, fill_slices + 1):
            t_up[d:] = np.maximum(t_up[d:], t[upper][:-d])
            t_up[:-d] = np.maximum(t_up[:-d], t[upper][d:])
            t_lo[d:] = np.minimum(t_lo[d:], t[lower][:-d])
            t_lo[:-d] = np.minimum(t_lo[:-d], t[lower][d:])
        t_up[[0, k - 1]] = t[upper][[0, k - 1]]  # the end caps start from real points
        t_lo[[0, k - 1]] = t[lower][[0, k - 1]]

    def lift(idx: np.ndarray, tt: np.ndarray) -> np.ndarray:
        return centre + np.outer(s[idx], axis) + np.outer(tt, normal)

    poly = np.concatenate(
        [
            lift(lower, t_lo),
            pts[right],
            lift(upper, t_up)[::-1],
            pts[left],
        ]
    )
    keep = np.ones(len(poly), dtype=bool)
    keep[1:] = np.any(np.abs(np.diff(poly, axis=0)) > 1e-12, axis=1)
    return poly[keep]


def _hull_arc(st: np.ndarray, members: np.ndarray, a: int, b: int) -> np.ndarray:
    """Indices strictly between ``a`` and ``b`` on the counter-clockwise convex
    hull of ``st[members]`` (empty when degenerate or when a/b are not on it)."""
    if len(members) < 3:
        return np.zeros(0, dtype=np.int64)
    try:
        hull = members[ConvexHull(st[members]).vertices]  # counter-clockwise
    except QhullError:
        return np.zeros(0, dtype=np.int64)
    ia, ib = np.nonzero(hull == a)[0], np.nonzero(hull == b)[0]
    if len(ia) == 0 or len(ib) == 0:
        return np.zeros(0, dtype=np.int64)
    rolled = np.roll(hull, -int(ia[0]))
    return rolled[1 : int((ib[0] - ia[0]) % len(hull))]


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
