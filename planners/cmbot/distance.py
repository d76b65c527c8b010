"""Sphere–cuboid distances for the arm's obstacle avoidance (seed §3.2, Fig. 12–13).

The arm is covered by spheres C_i, the guardrail, brackets and climbing
mechanism are cuboids D_j.  :func:`gjk_distance` is the Gilbert–Johnson–
Keerthi algorithm (Gilbert, Johnson & Keerthi 1988; closest point of each
simplex by Johnson's sub-algorithm, here by enumerating the simplex's faces)
on support functions; a sphere is its centre point grown by its radius.  It
gives d_ij and the unit direction u_ij from the closest point of D_j to the
closest point of C_i used by Eq. 15.

:func:`sphere_box_exact` is the closed form for spheres against oriented
boxes (clamp the centre into the box), vectorised over all pairs: it is the
reference the GJK tests compare with, and the fast path for bulk clearance
screening in the simulation gate.  Penetration (a centre inside a box) gets a
negative distance and the direction of the nearest face, which GJK alone
cannot provide (it only reports "intersecting").
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from planners.errors import InvalidInputError


@dataclass(frozen=True)
class Cuboid:
    """Oriented box: ``center`` (3,), ``half`` extents (3,), ``rotation`` (3,3)
    whose columns are the box axes in the parent frame."""

    center: np.ndarray
    half: np.ndarray
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    name: str = ""
    group: str = "env"

    def __post_init__(self) -> None:
        c = np.asarray(self.center, dtype=float)
        h = np.asarray(self.half, dtype=float)
        R = np.asarray(self.rotation, dtype=float)
        if c.shape != (3,) or h.shape != (3,) or R.shape != (3, 3):
            raise InvalidInputError(f"cuboid {self.name!r}: center (3,), half (3,), rotation (3,3)")
        if not (np.all(np.isfinite(c)) and np.all(np.isfinite(h)) and np.all(h > 0)):
            raise InvalidInputError(
                f"cuboid {self.name!r}: finite centre and positive half extents"
            )
        object.__setattr__(self, "center", c)
        object.__setattr__(self, "half", h)
        object.__setattr__(self, "rotation", R)

    @staticmethod
    def from_bounds(
        lo: Sequence[float], hi: Sequence[float], name: str = "", group: str = "env"
    ) -> Cuboid:
        """Axis-aligned box between two corners."""
        lo_, hi_ = np.asarray(lo, float), np.asarray(hi, float)
        return Cuboid((lo_ + hi_) / 2, (hi_ - lo_) / 2, np.eye(3), name, group)

    def support(self, d: np.ndarray) -> np.ndarray:
        """Farthest point of the box in direction ``d``."""
        R = self.rotation
        s = np.where(R.T @ d >= 0.0, self.half, -self.half)
        return self.center + R @ s

    def support_tuple(self, d: tuple[float, float, float]) -> tuple[float, float, float]:
        """:meth:`support` on plain floats (GJK's inner loop)."""
        cache = self.__dict__.get("_py")
        if cache is None:
            cache = (
                tuple(self.center.tolist()),
                tuple(map(tuple, self.rotation.T.tolist())),
                tuple(self.half.tolist()),
            )
            object.__setattr__(self, "_py", cache)
        c, rows, h = cache  # rows: box axes
        x, y, z = c
        for axis, hk in zip(rows, h, strict=True):
            sk = hk if axis[0] * d[0] + axis[1] * d[1] + axis[2] * d[2] >= 0.0 else -hk
            x += sk * axis[0]
            y += sk * axis[1]
            z += sk * axis[2]
        return (x, y, z)

    def vertices(self) -> np.ndarray:
        """The 8 corners (8,3)."""
        signs = np.array(list(itertools.product((-1.0, 1.0), repeat=3)))
        return self.center + (signs * self.half) @ self.rotation.T

    def transformed(self, T: np.ndarray) -> Cuboid:
        """The same box expressed in another frame: ``T`` maps parent → new frame."""
        T = np.asarray(T, dtype=float)
        return Cuboid(
            T[:3, :3] @ self.center + T[:3, 3],
            self.half,
            T[:3, :3] @ self.rotation,
            self.name,
            self.group,
        )

    @property
    def circumradius(self) -> float:
        return float(np.linalg.norm(self.half))


@dataclass(frozen=True)
class GJKResult:
    """``distance`` ≥ 0 between the shapes (0 when they intersect), closest
    points on A and B, the iterations used and whether they intersect."""

    distance: float
    point_a: np.ndarray
    point_b: np.ndarray
    iterations: int
    intersect: bool


Vec = tuple[float, float, float]


def _dot(a: Vec, b: Vec) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _sub(a: Vec, b: Vec) -> Vec:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _comb(P: list[Vec], lam: list[float]) -> Vec:
    x = y = z = 0.0
    for p, w in zip(P, lam, strict=True):
        x += w * p[0]
        y += w * p[1]
        z += w * p[2]
    return (x, y, z)


def _closest_segment(a: Vec, b: Vec) -> tuple[list[int], list[float]]:
    ab = _sub(b, a)
    t = -_dot(a, ab) / max(_dot(ab, ab), 1e-300)
    if t <= 0.0:
        return [0], [1.0]
    if t >= 1.0:
        return [1], [1.0]
    return [0, 1], [1.0 - t, t]


def _closest_triangle(a: Vec, b: Vec, c: Vec) -> tuple[list[int], list[float]]:
    """Ericson, Real-Time Collision Detection §5.1.5, for the query point at the origin."""
    ab, ac = _sub(b, a), _sub(c, a)
    ap = (-a[0], -a[1], -a[2])
    d1, d2 = _dot(ab, ap), _dot(ac, ap)
    if d1 <= 0.0 and d2 <= 0.0:
        return [0], [1.0]
    bp = (-b[0], -b[1], -b[2])
    d3, d4 = _dot(ab, bp), _dot(ac, bp)
    if d3 >= 0.0 and d4 <= d3:
        return [1], [1.0]
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return [0, 1], [1.0 - v, v]
    cp = (-c[0], -c[1], -c[2])
    d5, d6 = _dot(ab, cp), _dot(ac, cp)
    if d6 >= 0.0 and d5 <= d6:
        return [2], [1.0]
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return [0, 2], [1.0 - w, w]
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return [1, 2], [1.0 - w, w]
    den = 1.0 / (va + vb + vc)
    v, w = vb * den, vc * den
    return [0, 1, 2], [1.0 - v - w, v, w]


def _outside_plane(a: Vec, b: Vec, c: Vec, d: Vec) -> bool:
    """Whether the origin and ``d`` lie on opposite sides of plane abc."""
    ab, ac = _sub(b, a), _sub(c, a)
    n = (
        ab[1] * ac[2] - ab[2] * ac[1],
        ab[2] * ac[0] - ab[0] * ac[2],
        ab[0] * ac[1] - ab[1] * ac[0],
    )
    so = -_dot(a, n)
    sd = _dot(_sub(d, a), n)
    return so * sd < 0.0


def _closest_on_simplex(W: list[Vec]) -> tuple[list[int], list[float]]:
    """Johnson's sub-algorithm: the sub-simplex (indices, barycentric weights)
    whose point is nearest the origin; a tetrahedron enclosing the origin
    returns all four vertices."""
    n = len(W)
    if n == 1:
        return [0], [1.0]
    if n == 2:
        return _closest_segment(W[0], W[1])
    if n == 3:
        return _closest_triangle(W[0], W[1], W[2])
    best: tuple[float, list[int], list[float]] | None = None
    for f in ((0, 1, 2, 3), (0, 1, 3, 2), (0, 2, 3, 1), (1, 2, 3, 0)):
        a, b, c, d = (W[i] for i in f)
        if not _outside_plane(a, b, c, d):
            continue
        idx, lam = _closest_triangle(a, b, c)
        p = _comb([(a, b, c)[i] for i in idx], lam)
        d2 = _dot(p, p)
        if best is None or d2 < best[0]:
            best = (d2, [f[i] for i in idx], lam)
    if best is None:  # inside every face plane: the origin is in the tetrahedron
        return [0, 1, 2, 3], [0.25] * 4
    return best[1], best[2]


def gjk_distance(
    support_a: Callable[[Vec], Vec],
    support_b: Callable[[Vec], Vec],
    start: Vec | np.ndarray,
    *,
    tol: float = 1e-12,
    max_iter: int = 64,
) -> GJKResult:
    """GJK distance between convex A and B given their support functions
    (plain-float 3-tuples in and out).

    ``start`` is any vector a − b of the Minkowski difference (e.g. centre
    difference).  Stops when the support point no longer improves the bound
    (‖v‖² − v·w ≤ tol·‖v‖²) or the simplex encloses the origin.
    """
    v: Vec = (float(start[0]), float(start[1]), float(start[2]))
    if _dot(v, v) < 1e-30:
        v = (1.0, 0.0, 0.0)
    Wa: list[Vec] = []
    Wb: list[Vec] = []
    lam: list[float] = []
    it = 0
    for it in range(1, max_iter + 1):
        a = support_a((-v[0], -v[1], -v[2]))
        b = support_b(v)
        w = _sub(a, b)
        vv = _dot(v, v)
        if Wa and vv - _dot(v, w) <= tol * max(vv, 1e-30):
            break
        Wa.append(a)
        Wb.append(b)
        W = [_sub(x, y) for x, y in zip(Wa, Wb, strict=True)]
        idx, lam = _closest_on_simplex(W)
        Wa = [Wa[i] for i in idx]
        Wb = [Wb[i] for i in idx]
        v = _comb([W[i] for i in idx], lam)
        if len(idx) == 4 or _dot(v, v) <= 1e-24:
            return GJKResult(0.0, np.array(_comb(Wa, lam)), np.array(_comb(Wb, lam)), it, True)
    pa, pb = np.array(_comb(Wa, lam)), np.array(_comb(Wb, lam))
    return GJKResult(float(np.linalg.norm(pa - pb)), pa, pb, it, False)


def sphere_box_gjk(center: np.ndarray, radius: float, box: Cuboid) -> tuple[float, np.ndarray]:
    """Signed distance d_ij and unit direction u_ij (box → sphere) by GJK.

    The sphere is its centre point grown by ``radius``; a centre inside the
    box (GJK reports intersection) falls back to the nearest face.
    """
    c = np.asarray(center, dtype=float)
    ct = (float(c[0]), float(c[1]), float(c[2]))
    res = gjk_distance(lambda d: ct, box.support_tuple, c - box.center)
    if res.intersect or res.distance < 1e-12:
        d, u = _inside_box(c, box)
        return d - radius, u
    u = (res.point_a - res.point_b) / res.distance
    return res.distance - radius, u


def _inside_box(c: np.ndarray, box: Cuboid) -> tuple[float, np.ndarray]:
    """Negative depth of a point inside a box and the outward normal of the nearest face."""
    local = box.rotation.T @ (c - box.center)
    gap = box.half - np.abs(local)
    k = int(np.argmin(gap))
    n = np.zeros(3)
    n[k] = 1.0 if local[k] >= 0 else -1.0
    return -float(gap[k]), box.rotation @ n


def boxes_arrays(boxes: Sequence[Cuboid]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stack boxes into centres (M,3), half extents (M,3), rotations (M,3,3)."""
    if not boxes:
        return np.zeros((0, 3)), np.ones((0, 3)), np.zeros((0, 3, 3))
    return (
        np.array([b.center for b in boxes]),
        np.array([b.half for b in boxes]),
        np.array([b.rotation for b in boxes]),
    )


def sphere_box_exact(
    centers: np.ndarray,
    radii: np.ndarray,
    boxes: Sequence[Cuboid] | tuple[np.ndarray, np.ndarray, np.ndarray],
    *,
    directions: bool = True,
) -> tuple[np.ndarray, np.ndarray | None]:
    """Closed-form signed distances (…,N,M) and unit directions (…,N,M,3) box → sphere.

    ``centers`` (…,N,3) may carry leading batch axes (time steps); so may the
    box centres (…,M,3) and rotations (…,M,3,3) when given as arrays.  With
    ``directions=False`` only distances are computed (second item None).
    """
    bc, bh, bR = boxes if isinstance(boxes, tuple) else boxes_arrays(boxes)
    c = np.asarray(centers, dtype=float)
    r = np.asarray(radii, dtype=float)
    rel = c[..., :, None, :] - bc[..., None, :, :]  # (…,N,M,3); boxes may carry the batch axes too
    # local_i = Σ_j R_ji·rel_j: the centre in each box's own axes
    local = np.matmul(rel[..., None, :], bR[..., None, :, :, :])[..., 0, :]
    a = np.abs(local)
    excess = np.maximum(a - bh, 0.0)
    dist_out = np.sqrt(np.einsum("...i,...i->...", excess, excess))
    depth = np.min(bh - a, axis=-1)
    inside = dist_out <= 0.0
    d = np.where(inside, -depth, dist_out) - r[..., :, None]
    if not directions:
        return d, None
    diff = np.sign(local) * excess
    k = np.argmin(bh - a, axis=-1)
    n_in = np.zeros_like(local)
    side = np.where(np.take_along_axis(local, k[..., None], axis=-1) >= 0.0, 1.0, -1.0)
    np.put_along_axis(n_in, k[..., None], side, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        n_out = diff / dist_out[..., None]
    n_local = np.where(inside[..., None], n_in, n_out)
    u = np.matmul(bR[..., None, :, :, :], n_local[..., :, None])[..., 0]
    return d, u


def sphere_box_bruteforce(center: np.ndarray, radius: float, box: Cuboid, n: int = 41) -> float:
    """Distance by sampling the box surface on an n×n grid per face (reference only)."""
    g = np.linspace(-1.0, 1.0, n)
    pts = []
    for axis in range(3):
        o = [i for i in range(3) if i != axis]
        A, B = np.meshgrid(g, g, indexing="ij")
        for s in (-1.0, 1.0):
            P = np.zeros((n * n, 3))
            P[:, axis] = s
            P[:, o[0]] = A.ravel()
            P[:, o[1]] = B.ravel()
            pts.append(P)
    local = np.concatenate(pts) * box.half
    world = box.center + local @ box.rotation.T
    dmin = float(np.min(np.linalg.norm(world - center, axis=1)))
    inside = np.all(np.abs(box.rotation.T @ (np.asarray(center) - box.center)) <= box.half)
    return (-dmin if inside else dmin) - radius
