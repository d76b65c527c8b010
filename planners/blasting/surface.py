"""Planar blasting surface: a polygon (with optional holes) on a plane in 3D.

DESIGN §5: ``Surface(origin, normal, boundary, x_axis=None)``; ``boundary`` is a
(K,2) polygon in metres in the plane frame, whose x axis is ``x_axis``
projected onto the plane, or the world x axis projected onto the plane (world
y when the normal is parallel to x), and y = normal × x.  The seed (§3.1)
takes the surface as already extracted from the point cloud; ``from_points``
does that extraction for a cloud of one plane (least-squares plane + concave
hull of the projected points).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import shapely
from shapely.geometry import GeometryCollection, MultiPoint, Polygon

from planners.errors import EmptyInputError, InvalidInputError

# |normal · x| above this counts as "normal parallel to world x" (DESIGN §5).
_PARALLEL = 1.0 - 1e-9


def _finite(name: str, a: np.ndarray) -> None:
    if not np.all(np.isfinite(a)):
        raise InvalidInputError(f"{name} has non-finite values")


def _ring(name: str, ring: np.ndarray) -> np.ndarray:
    ring = np.asarray(ring, dtype=float)
    if ring.ndim != 2 or ring.shape[1] != 2:
        raise InvalidInputError(
            f"{name} must be a (K,2) array of plane coordinates in metres, got shape {ring.shape}"
        )
    _finite(name, ring)
    if len(ring) > 1 and np.allclose(ring[0], ring[-1]):
        ring = ring[:-1]
    if len(ring) < 3:
        raise EmptyInputError(f"{name} needs at least 3 distinct vertices, got {len(ring)}")
    return ring


@dataclass
class Surface:
    """A planar surface to blast (seed §3.2): polygon ``boundary`` (K,2, metres)
    in the plane through ``origin`` with unit ``normal``; optional ``holes``
    (list of (M,2) rings) are not blasted.  The nozzle stands on the side the
    robot base is on (see :func:`planners.blasting.plan_blasting`)."""

    origin: np.ndarray
    normal: np.ndarray
    boundary: np.ndarray
    x_axis: np.ndarray | None = None
    holes: Sequence[np.ndarray] = field(default_factory=tuple)

    def __post_init__(self) -> None:
        self.origin = np.asarray(self.origin, dtype=float).reshape(-1)
        self.normal = np.asarray(self.normal, dtype=float).reshape(-1)
        if self.origin.shape != (3,):
            raise InvalidInputError(
                f"origin must be a 3-vector in metres, got shape {self.origin.shape}"
            )
        if self.normal.shape != (3,):
            raise InvalidInputError(f"normal must be a 3-vector, got shape {self.normal.shape}")
        _finite("origin", self.origin)
        _finite("normal", self.normal)
        nn = np.linalg.norm(self.normal)
        if nn < 1e-12:
            raise InvalidInputError("normal must be a non-zero vector")
        self.normal = self.normal / nn
        if self.x_axis is None:
            ref = np.array([1.0, 0.0, 0.0])
            if abs(self.normal @ ref) > _PARALLEL:
                ref = np.array([0.0, 1.0, 0.0])
        else:
            ref = np.asarray(self.x_axis, dtype=float).reshape(-1)
            if ref.shape != (3,):
                raise InvalidInputError(f"x_axis must be a 3-vector, got shape {ref.shape}")
            _finite("x_axis", ref)
        x = ref - (ref @ self.normal) * self.normal
        if np.linalg.norm(x) < 1e-9:
            raise InvalidInputError("x_axis is parallel to the normal; give an axis in the plane")
        self.x_axis = x / np.linalg.norm(x)
        self.y_axis = np.cross(self.normal, self.x_axis)
        self.boundary = _ring("boundary", self.boundary)
        self.holes = tuple(_ring(f"holes[{i}]", h) for i, h in enumerate(self.holes))
        poly = shapely.make_valid(Polygon(self.boundary, [h for h in self.holes]))
        if isinstance(poly, GeometryCollection):
            poly = shapely.union_all([g for g in poly.geoms if g.area > 0])
        if poly.is_empty or poly.area <= 0.0:
            raise EmptyInputError("boundary encloses no area")
        self.polygon = poly

    @property
    def area(self) -> float:
        """Area in m² (holes excluded)."""
        return float(self.polygon.area)

    @property
    def rotation(self) -> np.ndarray:
        """3×3 with columns x, y, normal (plane frame in the world)."""
        assert self.x_axis is not None  # __post_init__ sets the unit in-plane x axis
        return np.stack([self.x_axis, self.y_axis, self.normal], axis=1)

    def to_plane(self, points3d: np.ndarray) -> np.ndarray:
        """World points (N,3) → plane coordinates (N,2) (orthogonal projection)."""
        p = np.asarray(points3d, dtype=float).reshape(-1, 3) - self.origin
        return np.stack([p @ self.x_axis, p @ self.y_axis], axis=1)

    def to_world(self, points2d: np.ndarray) -> np.ndarray:
        """Plane coordinates (N,2) → world points (N,3) on the plane."""
        uv = np.asarray(points2d, dtype=float).reshape(-1, 2)
        return self.origin + uv[:, :1] * self.x_axis + uv[:, 1:2] * self.y_axis

    @classmethod
    def from_points(
        cls,
        points: np.ndarray,
        *,
        concavity: float = 0.3,
        toward: np.ndarray | None = None,
        x_axis: np.ndarray | None = None,
    ) -> Surface:
        """Fit a surface to the points of one plane (N,3): least-squares plane
        (SVD), origin at the centroid, boundary = concave hull of the
        projected points (shapely, ``concavity`` 0 = tightest … 1 = convex).
        The normal points toward ``toward`` when given."""
        pts = np.asarray(points, dtype=float)
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise InvalidInputError(f"points must be (N,3), got shape {pts.shape}")
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        if len(pts) < 3:
            raise EmptyInputError(f"points needs at least 3 finite points, got {len(pts)}")
        c = pts.mean(axis=0)
        _, s, vt = np.linalg.svd(pts - c, full_matrices=False)
        if s[1] < 1e-9 * max(s[0], 1e-12):
            raise InvalidInputError("points are collinear; no plane can be fitted")
        n = vt[2]
        if toward is not None and (np.asarray(toward, dtype=float) - c) @ n < 0:
            n = -n
        tmp = cls(c, n, np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]), x_axis=x_axis)
        uv = tmp.to_plane(pts)
        hull = shapely.concave_hull(MultiPoint(uv), ratio=float(np.clip(concavity, 0.0, 1.0)))
        if not isinstance(hull, Polygon):
            hull = MultiPoint(uv).convex_hull
        if not isinstance(hull, Polygon) or hull.area <= 0:
            raise EmptyInputError("the points span no area on their plane")
        ring = np.asarray(hull.exterior.coords)[:-1]
        holes = [np.asarray(h.coords)[:-1] for h in hull.interiors]
        return cls(c, n, ring, x_axis=x_axis, holes=holes)
