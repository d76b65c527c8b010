"""Point Inside Boundary Check (seed Alg. 6, §4.3) and the robot footprint.

A configuration is free when every projected footprint point lies inside one
of the cluster boundaries.  The seed's "centre-closest points" test: a point
P is inside boundary b when its distance d_s to b's centre C is shorter than
the distance to C of the boundary points closest to P; only the ``n``
clusters whose centres are nearest to P are tried.

Two variants, both vectorised over all points of all configurations at once
(the seed loops over points, clusters and neighbours):

``"thesis"`` — as printed: the ``m`` boundary points nearest to P (Euclidean);
inside when d_s < d_j for any of them (Alg. 6 lines 9–13).  On an elongated
bar the nearest boundary points are not on the ray C→P, so points just
outside a long edge read as inside (measured in the tests and the benchmark).

``"angular"`` (default) — the same centre comparison, but against the
boundary *along the ray* C→P: the two boundary vertices bracketing P's angle
about C, and the radius of the edge between them at that angle.  For a
polygon star-shaped about C (vertices ordered by angle by
:func:`planners.navigation.boundaries.star_polygon`, with C inside) this is an
exact point-in-polygon test, with one ``searchsorted`` per cluster instead of
an edge loop per point; any other boundary (a bar's s-monotone ring whose
noisy edge hides part of it from the centre, a bent GMM blob) is tested by
exact ray casting in its own vertex order (:func:`is_star_about` decides).

:func:`point_in_polygon` is an independent exact even–odd ray-casting test
used to cross-check both.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from planners.errors import InvalidInputError

PIBC_METHODS = ("angular", "thesis")

#: Most elements of one (items × per-item) temporary: the point-in-polygon,
#: nearest-centre and footprint arrays are products of two unbounded counts
#: (points × polygon edges, points × clusters, poses × footprint points), so
#: they are built in chunks of at most this many (8 MiB per float64 array).
CHUNK_ELEMENTS = 1 << 20
#: Rings with more edges than this are tested by :func:`point_in_polygon`
#: through a y-band index (about this many edges a band) instead of against
#: every edge.
BAND_MIN_EDGES = 64
#: Most shapely geometries (one footprint rectangle or swept hull per pose)
#: :func:`rectangles_on_steel` and :func:`swept_on_steel` build at once.
SHAPES_PER_CHUNK = 1 << 15


def chunk_slices(n: int, per_item: int, budget: int = CHUNK_ELEMENTS) -> list[slice]:
    """Slices tiling ``range(n)`` so that each chunk × ``per_item`` stays
    within ``budget`` elements (at least one item a chunk)."""
    step = max(1, budget // max(1, per_item))
    return [slice(i, min(i + step, n)) for i in range(0, n, step)]


def point_in_polygon(
    points: np.ndarray, polygon: np.ndarray, *, budget: int = CHUNK_ELEMENTS
) -> np.ndarray:
    """Even–odd ray casting (exact reference): (Q,) bool, vectorised over
    points × edges in chunks of at most ``budget`` point–edge pairs.

    A ring of more than ``BAND_MIN_EDGES`` edges (a big cluster's boundary
    has thousands) is indexed by y: the points, sorted by y, go in bands,
    and each band is tested against the edges whose y-range meets it only.
    An edge outside a point's y cannot cross its ray (the test's first
    condition), so the crossing count, the arithmetic of every counted pair
    and the answer are those of the full points × edges test, without its
    points × all-edges work."""
    p = np.asarray(points, dtype=float).reshape(-1, 2)
    a = np.asarray(polygon, dtype=float).reshape(-1, 2)
    b = np.roll(a, -1, axis=0)
    out = np.zeros(len(p), dtype=bool)
    if len(a) <= BAND_MIN_EDGES or len(p) == 0:
        for sl in chunk_slices(len(p), len(a), budget):
            out[sl] = _crossings_odd(p[sl], a, b)
        return out
    order = np.argsort(p[:, 1], kind="stable")
    ys = p[order, 1]
    e_lo = np.minimum(a[:, 1], b[:, 1])
    e_hi = np.maximum(a[:, 1], b[:, 1])
    per_band = max(1, len(p) * BAND_MIN_EDGES // len(a))  # about edges / 64 bands
    for i0 in range(0, len(p), per_band):
        idx = order[i0 : i0 + per_band]
        y0, y1 = ys[i0], ys[min(i0 + per_band, len(p)) - 1]
        # edges with a point of the band in [min y, max y): the rest have cond False
        near = (e_lo <= y1) & (e_hi > y0)
        if not near.any():
            continue  # no edge spans these y: every crossing count is 0
        ea, eb = a[near], b[near]
        for sl in chunk_slices(len(idx), len(ea), budget):
            out[idx[sl]] = _crossings_odd(p[idx[sl]], ea, eb)
    return out


def _crossings_odd(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Whether each point's rightward ray crosses an odd number of the edges a→b."""
    x, y = p[:, 0:1], p[:, 1:2]
    cond = (a[None, :, 1] > y) != (b[None, :, 1] > y)
    dy = b[:, 1] - a[:, 1]
    dy = np.where(dy == 0, 1.0, dy)
    x_cross = a[None, :, 0] + (y - a[None, :, 1]) * (b[None, :, 0] - a[None, :, 0]) / dy[None]
    return (np.count_nonzero(cond & (x < x_cross), axis=1) % 2).astype(bool)


def is_star_about(polygon: np.ndarray, centre: np.ndarray) -> bool:
    """Whether the ring ``polygon`` (in its vertex order) winds once around
    ``centre`` with every vertex at a larger angle than the one before (each
    step turning by less than π one way): then every ray from the centre
    crosses it exactly once and the angular test is exact."""
    poly = np.asarray(polygon, dtype=float).reshape(-1, 2)
    if len(poly) < 3:
        return False
    d = poly - np.asarray(centre, dtype=float)
    ang = np.arctan2(d[:, 1], d[:, 0])
    step = np.diff(np.append(ang, ang[:1]))
    step = (step + np.pi) % (2 * np.pi) - np.pi
    if np.all(step > 0):
        return bool(abs(step.sum() - 2 * np.pi) < 1e-6)
    if np.all(step < 0):  # clockwise ring: the same polygon
        return bool(abs(step.sum() + 2 * np.pi) < 1e-6)
    return False


@dataclass
class _Star:
    centre: np.ndarray
    ang: np.ndarray  # sorted vertex angles about the centre
    pts: np.ndarray  # vertices in that order
    tree: cKDTree
    star: bool  # star-shaped about the centre (:func:`is_star_about`): the ray test is exact
    lo: np.ndarray  # bounding box of the boundary
    hi: np.ndarray


class BoundarySet:
    """Cluster boundaries prepared for Alg. 6 queries (plane coordinates, metres)."""

    def __init__(self, centres: Sequence[np.ndarray], polygons: Sequence[np.ndarray]):
        if len(centres) != len(polygons):
            raise InvalidInputError("BoundarySet needs one centre per polygon")
        self.stars: list[_Star] = []
        for c, poly in zip(centres, polygons, strict=True):
            c = np.asarray(c, dtype=float)
            poly = np.asarray(poly, dtype=float).reshape(-1, 2)
            star = is_star_about(poly, c)
            d = poly - c
            ang = np.arctan2(d[:, 1], d[:, 0])
            # A polygon star-shaped about c is the same polygon in angle order;
            # any other keeps its own vertex order (tested by ray casting).
            order = np.argsort(ang, kind="stable") if star else np.arange(len(poly))
            self.stars.append(
                _Star(
                    c,
                    ang[order],
                    poly[order],
                    cKDTree(poly) if len(poly) else cKDTree(c[None]),
                    star,
                    poly.min(axis=0) if len(poly) else c,
                    poly.max(axis=0) if len(poly) else c,
                )
            )
        self.centres = np.array([s.centre for s in self.stars]) if self.stars else np.zeros((0, 2))

    def __len__(self) -> int:
        return len(self.stars)

    def subset(self, ids: Sequence[int]) -> BoundarySet:
        """The boundaries ``ids`` only (per-edge planning looks at nearby clusters)."""
        out = BoundarySet.__new__(BoundarySet)
        out.stars = [self.stars[i] for i in ids]
        out.centres = self.centres[list(ids)] if len(ids) else np.zeros((0, 2))
        return out

    def _inside_angular(self, s: _Star, p: np.ndarray, budget: int) -> np.ndarray:
        k = len(s.pts)
        if k < 3:
            return np.zeros(len(p), dtype=bool)
        if not s.star:
            # Not star-shaped about its centre (a bar's s-monotone ring, a bent
            # GMM blob): no single ray crossing to compare with; use the exact
            # crossing count instead.
            return point_in_polygon(p, s.pts, budget=budget)
        d = p - s.centre
        phi = np.arctan2(d[:, 1], d[:, 0])
        # Bracketing vertices (cyclic): ang[i-1] <= phi < ang[i].
        i = np.searchsorted(s.ang, phi, side="right") % k
        a = s.pts[i - 1]
        b = s.pts[i]
        # Ray C + r·u (u unit along phi) meets edge a→b where cross(a + t(b-a) - C, u) = 0.
        u = d / np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-300)[:, None]
        ea, eb = a - s.centre, b - s.centre
        ca = ea[:, 0] * u[:, 1] - ea[:, 1] * u[:, 0]
        cb = eb[:, 0] * u[:, 1] - eb[:, 1] * u[:, 0]
        den = ca - cb
        t = np.where(np.abs(den) > 1e-15, ca / np.where(np.abs(den) > 1e-15, den, 1.0), 0.5)
        hit = ea + np.clip(t, 0.0, 1.0)[:, None] * (eb - ea)
        radius = hit[:, 0] * u[:, 0] + hit[:, 1] * u[:, 1]
        ds = np.hypot(d[:, 0], d[:, 1])
        return (ds < radius) | (ds == 0.0)  # the centre itself is inside a star

    def _inside_thesis(self, s: _Star, p: np.ndarray, m: int) -> np.ndarray:
        if len(s.pts) == 0:
            return np.zeros(len(p), dtype=bool)
        mm = min(m, len(s.pts))
        _, idx = s.tree.query(p, k=mm)
        idx = idx.reshape(len(p), mm)
        dn = np.linalg.norm(s.tree.data[idx] - s.centre, axis=2)  # d_n of the m closest
        ds = np.linalg.norm(p - s.centre, axis=1)
        return np.any(ds[:, None] < dn, axis=1)  # Alg. 6 l. 12–13

    def contains(
        self,
        points: np.ndarray,
        *,
        method: str = "angular",
        n_centres: int = 3,
        m_closest: int = 3,
        budget: int = CHUNK_ELEMENTS,
    ) -> np.ndarray:
        """(Q,) bool: inside any of the ``n_centres`` nearest boundaries (Alg. 6
        l. 5–17), in chunks of points whose point × cluster (and point × edge)
        temporaries stay within ``budget`` elements."""
        if method not in PIBC_METHODS:
            raise InvalidInputError(f"PIBC method must be one of {PIBC_METHODS}, got {method!r}")
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        out = np.zeros(len(p), dtype=bool)
        if len(self.stars) == 0 or len(p) == 0:
            return out
        # d2 holds 2 floats per (point, cluster) pair; the per-cluster tests hold
        # at most n_centres candidates per point.
        for sl in chunk_slices(len(p), 2 * max(len(self.stars), n_centres), budget):
            out[sl] = self._contains_chunk(p[sl], method, n_centres, m_closest, budget)
        return out

    def _contains_chunk(
        self, p: np.ndarray, method: str, n_centres: int, m_closest: int, budget: int
    ) -> np.ndarray:
        out = np.zeros(len(p), dtype=bool)
        n = min(int(n_centres), len(self.stars))
        if n < len(self.stars):
            d2 = ((p[:, None, :] - self.centres[None]) ** 2).sum(axis=2)  # Alg. 6 l. 6
            near = np.argpartition(d2, n - 1, axis=1)[:, :n].ravel()  # l. 7
            # Group the (point, cluster) candidates by cluster in one sort.
            order = np.argsort(near, kind="stable")
            owner = np.repeat(np.arange(len(p)), n)[order]
            bounds = np.searchsorted(near[order], np.arange(len(self.stars) + 1))
        for k, s in enumerate(self.stars):  # per cluster, all its points at once
            sel = owner[bounds[k] : bounds[k + 1]] if n < len(self.stars) else np.arange(len(p))
            sel = sel[~out[sel]]
            if method == "angular":
                # Exact test: only points inside the boundary's bounding box can
                # be inside it, so skip the rest before the ray computation.
                q = p[sel]
                box = np.all((q >= s.lo) & (q <= s.hi), axis=1)
                sel = sel[box]
            if len(sel) == 0:
                continue
            if method == "angular":
                out[sel] |= self._inside_angular(s, p[sel], budget)
            else:
                out[sel] |= self._inside_thesis(s, p[sel], m_closest)
        return out


def footprint_points(
    length_m: float,
    width_m: float,
    *,
    center_x_m: float = 0.0,
    center_y_m: float = 0.0,
    spacing_m: float = 0.04,
) -> np.ndarray:
    """(F, 2) points sampling the footprint rectangle (edges and interior) in
    the robot frame: x forward along ``length_m``, y left along ``width_m``."""
    if not (np.isfinite(length_m) and np.isfinite(width_m)) or length_m <= 0 or width_m <= 0:
        raise InvalidInputError(
            f"footprint length_m and width_m must be positive, got {length_m}, {width_m}"
        )
    nx_ = max(2, int(np.ceil(length_m / spacing_m)) + 1)
    ny_ = max(2, int(np.ceil(width_m / spacing_m)) + 1)
    xs = np.linspace(-length_m / 2, length_m / 2, nx_) + center_x_m
    ys = np.linspace(-width_m / 2, width_m / 2, ny_) + center_y_m
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    return np.column_stack([gx.ravel(), gy.ravel()])


def project_footprint(poses: np.ndarray, footprint: np.ndarray) -> np.ndarray:
    """(P, F, 2) footprint points of poses (P, 3) = (x, y, yaw) in plane coordinates."""
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    fx, fy = footprint[:, 0], footprint[:, 1]
    x = poses[:, 0:1] + c[:, None] * fx[None] - s[:, None] * fy[None]
    y = poses[:, 1:2] + s[:, None] * fx[None] + c[:, None] * fy[None]
    return np.stack([x, y], axis=2)


def poses_valid(
    poses: np.ndarray,
    footprint: np.ndarray,
    boundaries: BoundarySet,
    *,
    method: str = "angular",
    n_centres: int = 3,
    m_closest: int = 3,
) -> np.ndarray:
    """(P,) bool: every footprint point of each pose lies on steel (Alg. 6 l.
    18–22), in chunks of poses whose projected footprints stay within
    ``CHUNK_ELEMENTS`` points."""
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    fp = np.asarray(footprint, dtype=float).reshape(-1, 2)
    out = np.zeros(len(poses), dtype=bool)
    for sl in chunk_slices(len(poses), len(fp)):
        pts = project_footprint(poses[sl], fp)
        inside = boundaries.contains(
            pts.reshape(-1, 2), method=method, n_centres=n_centres, m_closest=m_closest
        )
        out[sl] = inside.reshape(pts.shape[:2]).all(axis=1)
    return out


def footprint_corners(
    poses: np.ndarray,
    length_m: float,
    width_m: float,
    *,
    center_x_m: float = 0.0,
    center_y_m: float = 0.0,
) -> np.ndarray:
    """(P, 4, 2) corners of the footprint rectangle at each pose, counter-clockwise."""
    hx, hy = 0.5 * length_m, 0.5 * width_m
    rect = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]]) + [center_x_m, center_y_m]
    return project_footprint(poses, rect)


#: Gaps narrower than twice this between boundary polygons are closed (below
#: the 1 cm voxel grid, a seam between two clusters' rings is not a gap in
#: the steel).
STEEL_CLOSING_M = 0.003


def steel_union(polygons: Sequence[np.ndarray], *, closing_m: float = STEEL_CLOSING_M) -> Any:
    """The steel the footprint must stay on: the union of the boundary
    polygons, morphologically closed by ``closing_m`` (slivers and holes
    narrower than 2·closing_m filled; convex outlines unchanged), as a
    prepared shapely geometry."""
    import shapely

    parts = [shapely.Polygon(p).buffer(0) for p in polygons if len(p) >= 3]
    steel = shapely.union_all(parts) if parts else shapely.Polygon()
    if closing_m > 0 and not steel.is_empty:
        steel = steel.buffer(closing_m, quad_segs=8).buffer(-closing_m, quad_segs=8)
    shapely.prepare(steel)
    return steel


def rectangles_on_steel(
    poses: np.ndarray,
    steel: Any,
    length_m: float,
    width_m: float,
    *,
    center_x_m: float = 0.0,
    center_y_m: float = 0.0,
) -> np.ndarray:
    """(P,) bool: the whole footprint rectangle at each pose lies inside
    ``steel`` (a geometry from :func:`steel_union`) — exact, unlike a test of
    sampled footprint points, which a narrow gap between two boundaries can
    pass between."""
    import shapely

    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    out = np.zeros(len(poses), dtype=bool)
    # One shapely polygon per pose (a GEOS object of a few hundred bytes):
    # built and tested a bounded batch at a time.
    for sl in chunk_slices(len(poses), 1, SHAPES_PER_CHUNK):
        corners = footprint_corners(
            poses[sl], length_m, width_m, center_x_m=center_x_m, center_y_m=center_y_m
        )
        out[sl] = np.asarray(shapely.contains(steel, shapely.polygons(corners)), dtype=bool)
    return out


def swept_on_steel(
    poses: np.ndarray,
    steel: Any,
    length_m: float,
    width_m: float,
    *,
    center_x_m: float = 0.0,
    center_y_m: float = 0.0,
) -> np.ndarray:
    """(P,) bool: the footprint rectangle at pose k, and the area it sweeps
    moving from pose k-1 to pose k, lie inside ``steel`` (a shapely geometry
    from :func:`steel_union`, or the boundary polygons themselves) — an exact
    geometric test, independent of Alg. 6's sampled footprint points.

    The swept area between consecutive poses is the convex hull of the two
    rectangles, grown by the sagitta of the arc the farthest corner draws
    when the yaw changes (every footprint point moves along a chord of the
    hull, or an arc within that sagitta of it); a straight drive sweeps
    exactly the hull.  Pose 0 is tested alone.
    """
    import shapely

    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    if len(poses) == 0:
        return np.zeros(0, dtype=bool)
    if not isinstance(steel, shapely.Geometry):
        steel = steel_union(steel)
    corners = footprint_corners(
        poses, length_m, width_m, center_x_m=center_x_m, center_y_m=center_y_m
    )
    reach = float(np.max(np.hypot(*(corners[0] - poses[0, :2]).T)))
    prev_of = np.maximum(np.arange(len(poses)) - 1, 0)  # pose 0 is its own predecessor
    dyaw = np.abs(wrap_angle(np.diff(poses[:, 2], prepend=poses[0, 2])))
    sagitta = reach * (1.0 - np.cos(np.minimum(dyaw, np.pi) / 2.0))
    out = np.zeros(len(poses), dtype=bool)
    # One hull per pose (GEOS objects): built and tested a bounded batch at a time.
    for sl in chunk_slices(len(poses), 1, SHAPES_PER_CHUNK):
        both = np.concatenate([corners[prev_of[sl]], corners[sl]], axis=1)
        # an object array (asarray narrows the scalar-or-array stub type)
        hulls = np.asarray(shapely.convex_hull(shapely.multipoints(both)))
        sag = sagitta[sl]
        turned = sag > 1e-12
        if turned.any():
            hulls[turned] = shapely.buffer(hulls[turned], sag[turned], quad_segs=2)
        out[sl] = np.asarray(shapely.contains(steel, hulls), dtype=bool)
    return out


def wrap_angle(a: np.ndarray | float) -> np.ndarray:
    """Angle(s) wrapped into [-π, π)."""
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi
