"""The three availability checks of the ARA switching control (seed §3.1).

* plane availability S_pa (Eq. 3.2): pass-through, voxel down-sampling and
  sequential RANSAC find *every* planar surface in view, with centroid and
  normal;
* area availability S_am: NCBE boundary (Alg. 1) and Area Checking and Pose
  Estimation (Alg. 2) with n = 5, m = 3, t = 0.02, keeping every candidate
  rectangle with its verdict, cross-checked against an exact test (rectangle
  inside the plane's alpha-shape concave hull);
* height availability S_hc (Eq. 3.3–3.4): centroid in the base frame compared
  with the base height within a tolerance.

Reading of Alg. 2 where the printed pseudo-code is ambiguous (each choice is
the only one under which the algorithm does what the prose says):
  - ``e_y = e_z × e_x`` (printed ``e_x × e_y``, which is circular);
  - the rectangle is w wide along e_y and l long along e_x, i.e. its corners
    are ``N_i ± (w/2)·ê_y`` and those minus ``l·ê_x`` (the prose: "a rectangle
    of width w and length l"); it extends from the boundary point *towards*
    the centroid — extending outwards puts it outside the plane by
    construction, and no rectangle could ever pass line 18;
  - the four "middle points" are the edge midpoints of the rectangle;
  - ``d_Q`` is the mean distance of the m nearest boundary points to C;
  - the pose is placed at the rectangle centre (the seed's −l/4 shift on y is
    the offset of the original robot's foot frame; ours is the sole centre).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import shapely
from scipy.spatial import cKDTree
from shapely.geometry.base import BaseGeometry

from planners.pointcloud import alpha_shape, ncbe_boundary_indices


@dataclass
class RectangleCandidate:
    """One foot rectangle tried by Alg. 2 (all coordinates in the base frame)."""

    index: int
    boundary_point: np.ndarray  # N_i (3,)
    corners: np.ndarray  # (4, 3), polygon order
    test_points: np.ndarray  # (8, 3): 4 corners then 4 edge midpoints
    d_r: np.ndarray  # (8,) distance of each test point to the centroid
    d_q: np.ndarray  # (8,) mean distance of its m nearest boundary points
    point_passed: np.ndarray  # (8,) S_i of Alg. 2 line 18
    passed: bool  # Alg. 2 verdict
    reason: str
    exact_passed: bool  # rectangle inside the plane's concave hull
    exact_margin_m: float  # signed: + inside by that much, − outside by that much
    pose: np.ndarray  # 4×4: axes (e_x, e_y, e_z), origin the rectangle centre

    @property
    def agrees(self) -> bool:
        return self.passed == self.exact_passed


@dataclass
class PlaneFrame:
    """In-plane 2D frame: origin, x axis, y axis, normal (DESIGN §5 Surface)."""

    origin: np.ndarray
    x_axis: np.ndarray
    y_axis: np.ndarray
    normal: np.ndarray

    @staticmethod
    def from_normal(origin: np.ndarray, normal: np.ndarray) -> PlaneFrame:
        n = normal / np.linalg.norm(normal)
        ref = np.array([1.0, 0.0, 0.0])
        x = ref - (ref @ n) * n
        if np.linalg.norm(x) < 1e-6:  # normal ∥ world x: use world y
            ref = np.array([0.0, 1.0, 0.0])
            x = ref - (ref @ n) * n
        x /= np.linalg.norm(x)
        return PlaneFrame(np.asarray(origin, float), x, np.cross(n, x), n)

    def to_plane(self, points: np.ndarray) -> np.ndarray:
        rel = np.asarray(points, float) - self.origin
        return np.stack([rel @ self.x_axis, rel @ self.y_axis], axis=-1)

    def to_world(self, points2d: np.ndarray) -> np.ndarray:
        p = np.asarray(points2d, float)
        return self.origin + p[..., :1] * self.x_axis + p[..., 1:2] * self.y_axis


@dataclass
class AreaResult:
    """Outcome of Alg. 1 + Alg. 2 on one plane."""

    boundary2d: np.ndarray
    hull: BaseGeometry
    rectangles: list[RectangleCandidate] = field(default_factory=list)

    @property
    def available(self) -> bool:
        return any(r.passed for r in self.rectangles)

    @property
    def chosen(self) -> RectangleCandidate | None:
        """First passing rectangle in closeness order (Alg. 2 returns it)."""
        return next((r for r in self.rectangles if r.passed), None)


def area_check(
    points2d: np.ndarray,
    frame: PlaneFrame,
    *,
    foot: tuple[float, float],
    n_closest: int = 5,
    m_neighbours: int = 3,
    tolerance: float = 0.02,
    sliding_factor: float = 0.02,
    alpha_m: float = 0.03,
    exact_tolerance_m: float = 0.01,
) -> AreaResult:
    """Alg. 1 (NCBE) then Alg. 2 (area checking and pose estimation) on a plane.

    ``points2d`` are the plane's inliers in ``frame`` coordinates, ``foot`` =
    (length l, width w) in metres.  Every one of the ``n_closest`` rectangles
    is evaluated (the seed stops at the first pass; the operator wants all),
    and each is also tested exactly against the alpha shape of the points
    (grown by ``exact_tolerance_m``: two corners sit on boundary points).
    """
    length, width = float(foot[0]), float(foot[1])
    bidx = ncbe_boundary_indices(points2d, sliding_factor=sliding_factor)
    B = points2d[bidx]
    hull = alpha_shape(points2d, alpha_m)
    C = points2d.mean(axis=0)  # C_Pcl (the frame origin is the 3D centroid)
    out = AreaResult(boundary2d=B, hull=hull)
    if len(B) < 2:
        return out
    dist = np.linalg.norm(B - C, axis=1)
    order = np.argsort(dist, kind="stable")[: int(n_closest)]
    N = B[order]  # (n, 2) — Alg. 2 line 2
    ex = N - C
    norm = np.linalg.norm(ex, axis=1, keepdims=True)
    exh = ex / np.maximum(norm, 1e-12)
    eyh = np.stack([-exh[:, 1], exh[:, 0]], axis=1)  # e_z × e_x in the plane
    half_w = 0.5 * width * eyh
    c1, c2 = N + half_w, N - half_w  # line 9
    c3, c4 = c2 - length * exh, c1 - length * exh  # line 11, towards C
    corners = np.stack([c1, c2, c3, c4], axis=1)  # (n, 4, 2)
    mids = 0.5 * (corners + np.roll(corners, -1, axis=1))  # line 12
    R = np.concatenate([corners, mids], axis=1)  # (n, 8, 2)
    tree = cKDTree(B)
    k = min(int(m_neighbours), len(B))
    _, qi = tree.query(R.reshape(-1, 2), k=k)  # line 16
    qi = np.asarray(qi).reshape(len(N), 8, k)
    d_r = np.linalg.norm(R - C, axis=2)  # line 17
    d_q = np.linalg.norm(B[qi] - C, axis=3).mean(axis=2)
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(d_r > 0, (d_r - d_q) / d_r, -np.inf)
    S = (d_r < d_q) | (rel < float(tolerance))  # line 18
    # vectorised shapely calls on arrays return arrays (asarray narrows the stub unions)
    polys = np.asarray(shapely.polygons(np.concatenate([corners, corners[:, :1]], axis=1)))
    grown = hull.buffer(exact_tolerance_m) if not hull.is_empty else hull
    inside = (
        np.asarray(shapely.covers(grown, polys)) if not hull.is_empty else np.zeros(len(N), bool)
    )
    boundary = hull.boundary
    for i in range(len(N)):  # n = 5 rectangles: bookkeeping only
        fails = np.nonzero(~S[i])[0]
        if len(fails) == 0:
            reason = "all 8 test points inside (Alg. 2 line 18)"
        else:
            j = int(fails[np.argmax(rel[i, fails])])
            what = f"corner {j + 1}" if j < 4 else f"edge midpoint {j - 3}"
            reason = (
                f"{len(fails)} of 8 test points outside; worst {what}: d_r={d_r[i, j]:.3f} m > "
                f"d_Q={d_q[i, j]:.3f} m by {100 * rel[i, j]:.1f}% (t={100 * tolerance:.0f}%)"
            )
        margin = _signed_margin(hull, boundary, polys[i], bool(inside[i]))
        pose = np.eye(4)
        pose[:3, 0] = exh[i, 0] * frame.x_axis + exh[i, 1] * frame.y_axis
        pose[:3, 2] = frame.normal
        pose[:3, 1] = np.cross(pose[:3, 2], pose[:3, 0])
        pose[:3, 3] = frame.to_world(R[i, :4].mean(axis=0))  # line 23, rectangle centre
        out.rectangles.append(
            RectangleCandidate(
                index=i,
                boundary_point=frame.to_world(N[i]),
                corners=frame.to_world(corners[i]),
                test_points=frame.to_world(R[i]),
                d_r=d_r[i],
                d_q=d_q[i],
                point_passed=S[i],
                passed=bool(S[i].all()),
                reason=reason,
                exact_passed=bool(inside[i]),
                exact_margin_m=margin,
                pose=pose,
            )
        )
    return out


def _signed_margin(
    hull: BaseGeometry, boundary: BaseGeometry, rect: BaseGeometry, inside: bool
) -> float:
    """+ distance from the rectangle to the hull outline when inside; −(how
    far the rectangle's outside part reaches beyond the hull) otherwise."""
    if hull.is_empty:
        return -np.inf
    if inside:
        return float(shapely.distance(boundary, rect))
    outside = shapely.difference(rect, hull)
    pts = np.asarray(shapely.points(shapely.get_coordinates(outside)))  # (k, 2) in: an array
    return -float(np.max(shapely.distance(hull, pts))) if len(pts) else 0.0


def height_check(
    centroid_base: np.ndarray,
    normal_base: np.ndarray,
    *,
    base_height: float,
    tolerance_m: float = 0.005,
    parallel_tolerance_deg: float = 5.0,
) -> tuple[bool, float, float]:
    """Eq. 3.4: S_hc = (|z_frb − z_base| ≤ tolerance) — and, our addition,
    the plane is parallel to the standing surface (normal within
    ``parallel_tolerance_deg`` of base z), else a wall whose centroid happens
    to sit at base height would pass.  Returns (S_hc, Δz, normal angle °)."""
    dz = float(centroid_base[2] - base_height)
    angle = float(np.degrees(np.arccos(np.clip(abs(normal_base[2]), 0.0, 1.0))))
    return (abs(dz) <= tolerance_m and angle <= parallel_tolerance_deg), dz, angle


def exact_foot_placements(
    hull: BaseGeometry,
    foot: tuple[float, float],
    *,
    spacing_m: float = 0.02,
    n_angles: int = 12,
    tolerance_m: float = 0.0,
) -> tuple[int, np.ndarray | None]:
    """Brute-force, independent of Alg. 2: how many foot rectangles (l × w),
    centred on a ``spacing_m`` grid over the hull's bounds and turned through
    ``n_angles`` headings in [0, π), lie inside ``hull`` (grown by
    ``tolerance_m``).  Returns (count, (x, y, heading) of the placement
    deepest inside, or None).  All rectangles are tested in one vectorised
    shapely call."""
    if hull.is_empty:
        return 0, None
    x0, y0, x1, y1 = hull.bounds
    xs = np.arange(x0, x1 + 1e-9, spacing_m)
    ys = np.arange(y0, y1 + 1e-9, spacing_m)
    gx, gy = np.meshgrid(xs, ys)
    centres = np.column_stack([gx.ravel(), gy.ravel()])
    centres = centres[shapely.contains_xy(hull, centres[:, 0], centres[:, 1])]
    if len(centres) == 0:
        return 0, None
    ang = np.arange(n_angles) * np.pi / n_angles
    hl, hw = foot[0] / 2, foot[1] / 2
    local = np.array([[hl, hw], [-hl, hw], [-hl, -hw], [hl, -hw], [hl, hw]])
    c, s = np.cos(ang), np.sin(ang)
    rot = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)  # (A,2,2)
    corners = np.einsum("aij,kj->aki", rot, local)  # (A,5,2)
    rings = centres[:, None, None, :] + corners[None]  # (C,A,5,2)
    polys = shapely.polygons(rings.reshape(-1, 5, 2))
    region = hull.buffer(tolerance_m) if tolerance_m > 0 else hull
    shapely.prepare(region)
    ok = np.asarray(shapely.covers(region, polys))  # one flag per rectangle
    if not ok.any():
        return 0, None
    idx = np.nonzero(ok)[0]
    depth = shapely.distance(region.boundary, polys[idx])
    best = int(idx[int(np.argmax(depth))])
    ci, ai = divmod(best, n_angles)
    return int(ok.sum()), np.array([centres[ci, 0], centres[ci, 1], ang[ai]])
