"""Force-field collision model of the arm (seed §3.4.2, Eq. 3.14–3.15).

Each link is covered by a prolate spheroid whose foci F1, F2 lie on the link
and whose major axis is ``C_f = L·Kp`` (L = |F1F2|, Kp > 1; the seed uses
Kp = [1.05, 1.10, 1.10], §4.2.5).  A point is inside when
``R1 + R2 ≤ C_f`` (Eq. 3.14).  Distances are Euclidean, signed (negative
inside): point–spheroid exactly (2-D reduction, Eberly's bisection; point
obstacles are found with a KD-tree), and spheroid–box by coal (GJK while
separated, EPA for the true penetration depth when they overlap), pruned
with bounding spheres so only pairs that can be the nearest are refined.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import coal
import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial import cKDTree

from planners.errors import InvalidInputError

_BISECT = 64  # bisection steps: enough for double precision on the root
_GJK_TOL = 1e-9  # coal GJK tolerance: separated distances agree with the exact ones to ~1e-9 m


@dataclass(frozen=True)
class Box:
    """Oriented box: centre (3,), half extents (3,), rotation (3,3) whose
    columns are the box axes in the world."""

    center: np.ndarray
    half: np.ndarray
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    name: str = ""

    @classmethod
    def from_bounds(cls, lo: ArrayLike, hi: ArrayLike, name: str = "") -> Box:
        lo_a, hi_a = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
        if lo_a.shape != (3,) or hi_a.shape != (3,) or np.any(hi_a < lo_a):
            raise InvalidInputError(
                f"box bounds must be two 3-vectors with lo ≤ hi, got {lo!r}, {hi!r}"
            )
        return cls((lo_a + hi_a) / 2.0, (hi_a - lo_a) / 2.0, np.eye(3), name)

    def project(self, p: np.ndarray) -> np.ndarray:
        """Nearest points of the box to points p (...,3)."""
        local = (p - self.center) @ self.rotation
        local = np.clip(local, -self.half, self.half)
        return self.center + local @ self.rotation.T

    def distance(self, p: np.ndarray) -> np.ndarray:
        return np.linalg.norm(p - self.project(p), axis=-1)

    def signed_distance(self, p: np.ndarray) -> np.ndarray:
        """Distance of points p (...,3) to the box, minus the depth to the
        nearest face for points inside."""
        local = (p - self.center) @ self.rotation
        gap = self.half - np.abs(local)
        inside = np.all(gap >= 0.0, axis=-1)
        return np.where(inside, -gap.min(axis=-1), self.distance(p))

    def corners(self) -> np.ndarray:
        s = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1], indexing="ij")).reshape(3, -1).T
        return self.center + (s * self.half) @ self.rotation.T


@dataclass
class Obstacles:
    """Boxes and obstacle points (M,3) in the world frame."""

    boxes: tuple[Box, ...] = ()
    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    def __post_init__(self) -> None:
        self.boxes = tuple(self.boxes)
        self.points = np.asarray(self.points, dtype=float).reshape(-1, 3)
        if not np.all(np.isfinite(self.points)):
            raise InvalidInputError("obstacle points have non-finite values")
        self._tree = cKDTree(self.points) if len(self.points) else None

    @classmethod
    def coerce(cls, obstacles: object) -> Obstacles:
        """Accept an :class:`Obstacles`, or a sequence of :class:`Box` and
        (M,3) point arrays."""
        if isinstance(obstacles, Obstacles):
            return obstacles
        boxes: list[Box] = []
        pts: list[np.ndarray] = []
        # anything but an iterable of boxes and point arrays raises TypeError here
        for o in obstacles or ():  # type: ignore[attr-defined]
            if isinstance(o, Box):
                boxes.append(o)
            else:
                a = np.asarray(o, dtype=float)
                if a.ndim != 2 or a.shape[1] != 3:
                    raise InvalidInputError(
                        f"obstacles must be Box objects or (M,3) point arrays, got shape {a.shape}"
                    )
                pts.append(a)
        return cls(tuple(boxes), np.concatenate(pts) if pts else np.zeros((0, 3)))

    @property
    def empty(self) -> bool:
        return not self.boxes and len(self.points) == 0


# -- spheroids -------------------------------------------------------------------
@dataclass
class Spheroids:
    """A batch of prolate spheroids (...,) given by foci and major axis C_f."""

    f1: np.ndarray  # (...,3)
    f2: np.ndarray  # (...,3)
    cf: np.ndarray  # (...,)

    @property
    def center(self) -> np.ndarray:
        return (self.f1 + self.f2) / 2.0

    @property
    def a(self) -> np.ndarray:
        return self.cf / 2.0

    @property
    def b(self) -> np.ndarray:
        c = np.linalg.norm(self.f2 - self.f1, axis=-1) / 2.0
        return np.sqrt(np.maximum(self.a**2 - c**2, 0.0))

    @property
    def axis(self) -> np.ndarray:
        d = self.f2 - self.f1
        n = np.linalg.norm(d, axis=-1, keepdims=True)
        return np.where(n > 1e-12, d / np.where(n > 1e-12, n, 1.0), np.array([0.0, 0.0, 1.0]))

    def contains(self, p: np.ndarray) -> np.ndarray:
        """Eq. 3.14: R1 + R2 ≤ C_f."""
        return (
            np.linalg.norm(p - self.f1, axis=-1) + np.linalg.norm(p - self.f2, axis=-1) <= self.cf
        )

    def __getitem__(self, idx: int | slice | np.ndarray) -> Spheroids:
        return Spheroids(self.f1[idx], self.f2[idx], self.cf[idx])


def _ellipse_closest(
    a: np.ndarray, b: np.ndarray, y0: np.ndarray, y1: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Closest point (x0, x1) on the ellipse x0²/a² + x1²/b² = 1 (a ≥ b > 0) to
    (y0, y1) with y0, y1 ≥ 0 — Eberly, "Distance from a point to an ellipse"
    (robust bisection), vectorised; valid for points inside too."""
    a, b, y0, y1 = np.broadcast_arrays(a, b, y0, y1)
    x0 = np.zeros(a.shape)
    x1 = np.zeros(a.shape)
    # general case y1 > 0 (y0 ≥ 0)
    z0 = y0 / a
    z1 = y1 / b
    g = z0 * z0 + z1 * z1 - 1.0
    r0 = (a / b) ** 2
    n0 = r0 * z0
    s0 = z1 - 1.0
    s1 = np.where(g < 0, 0.0, np.hypot(n0, z1) - 1.0)
    # on-axis points (y1 = 0) are handled below; keep their iteration finite
    s0 = np.where(y1 > 0, s0, 0.0)
    s1 = np.where(y1 > 0, s1, 1.0)
    # G(s) = (n0/(s+r0))² + (z1/(s+1))² − 1 is convex and decreasing on the
    # bracket [s0, s1] (G(s0) ≥ 0 ≥ G(s1)): Newton from the left end moves
    # monotonically towards the root (never past it in exact arithmetic);
    # a step leaving the bracket is replaced by bisection, and the loop ends
    # once every step is at rounding level (≤ _BISECT iterations, the cost
    # of plain bisection, in the worst case)
    s = s0.copy()
    for _ in range(_BISECT):
        u0 = n0 / (s + r0)
        u1 = z1 / (s + 1.0)
        gs = u0 * u0 + u1 * u1 - 1.0
        pos = gs > 0
        s0 = np.where(pos, s, s0)
        s1 = np.where(pos, s1, s)
        dg = -2.0 * (u0 * u0 / (s + r0) + u1 * u1 / (s + 1.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            sn = s - gs / dg
        bad = ~np.isfinite(sn) | (sn <= s0) | (sn >= s1)
        sn = np.where(bad, 0.5 * (s0 + s1), sn)
        step = np.abs(sn - s)
        s = sn
        if not np.any((step > 4e-16 * np.maximum(np.abs(s), 1.0)) & (s1 - s0 > 0)):
            break
    gx0 = r0 * y0 / (s + r0)
    gx1 = y1 / (s + 1.0)
    # y1 = 0: on the major axis
    numer = a * y0
    denom = a * a - b * b
    inner = numer < denom
    xde = np.where(inner, numer / np.where(denom > 0, denom, 1.0), 1.0)
    ax0 = np.where(inner, a * xde, a)
    ax1 = np.where(inner, b * np.sqrt(np.maximum(1.0 - xde * xde, 0.0)), 0.0)
    on_axis = y1 <= 0.0
    x0 = np.where(on_axis, ax0, gx0)
    x1 = np.where(on_axis, ax1, gx1)
    return x0, x1


def spheroid_closest(S: Spheroids, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closest surface points (...,3) of spheroids to points p (...,3) and the
    signed distance (negative inside)."""
    c = S.center
    u = S.axis
    a = S.a
    b = np.maximum(S.b, 1e-9)
    v = p - c
    z = np.einsum("...d,...d->...", v, u)
    radial = v - z[..., None] * u
    rho = np.linalg.norm(radial, axis=-1)
    x0, x1 = _ellipse_closest(a, np.minimum(b, a), np.abs(z), rho)
    # lift back: radial direction (any ⟂ u when the point is on the axis)
    helper = np.where(
        np.abs(u[..., :1]) < 0.9, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    )
    perp = np.cross(u, helper)
    perp /= np.linalg.norm(perp, axis=-1, keepdims=True)
    rdir = np.where(rho[..., None] > 1e-12, radial / np.maximum(rho, 1e-12)[..., None], perp)
    q = c + (np.sign(z) + (z == 0))[..., None] * x0[..., None] * u + x1[..., None] * rdir
    dist = np.linalg.norm(p - q, axis=-1)
    inside = (z / a) ** 2 + (rho / b) ** 2 < 1.0
    return q, np.where(inside, -dist, dist)


def spheroid_point_distance(S: Spheroids, p: np.ndarray) -> np.ndarray:
    """Signed Euclidean distance from spheroids to points (broadcast)."""
    return spheroid_closest(S, p)[1]


def spheroid_support(S: Spheroids, n: np.ndarray) -> np.ndarray:
    """Support function h(n) = max over the spheroid of n·x (unit n)."""
    nu = np.einsum("...d,...d->...", n, S.axis)
    return np.einsum("...d,...d->...", n, S.center) + np.sqrt(
        S.a**2 * nu**2 + S.b**2 * np.maximum(1.0 - nu**2, 0.0)
    )


def box_support_min(box: Box, n: np.ndarray) -> np.ndarray:
    """min over the box of n·x."""
    return n @ box.center - np.abs(n @ box.rotation) @ box.half


def _coal_box(box: Box) -> tuple[coal.Box, coal.Transform3s]:
    """The box as a coal shape and its pose, built once per :class:`Box`
    (cached on the frozen instance: boxes are static obstacles)."""
    cache = box.__dict__.get("_coal")
    if cache is None:
        shape = coal.Box(*(2.0 * np.asarray(box.half, dtype=float)))  # coal takes full sides
        tf = coal.Transform3s(
            np.ascontiguousarray(box.rotation, dtype=float), np.asarray(box.center, dtype=float)
        )
        cache = (shape, tf)
        object.__setattr__(box, "_coal", cache)
    return cache


def spheroid_frames(S: Spheroids) -> np.ndarray:
    """Rotations (n,3,3) whose first column is each spheroid's major axis —
    the frame in which coal's ``Ellipsoid(a, b, b)`` is the spheroid."""
    u = S.axis
    helper = np.where(
        np.abs(u[..., :1]) < 0.9, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    )
    e1 = np.cross(u, helper)
    e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
    e2 = np.cross(u, e1)  # [u, e1, e2] is right-handed
    return np.ascontiguousarray(np.stack([u, e1, e2], axis=-1))


def spheroid_box_distance(
    S: Spheroids,
    box: Box,
    *,
    tol: float = 1e-5,
    max_iter: int = 200,
    sign_only: bool = False,
    margin: float = 0.0,
    rel_tol: float = 0.0,
) -> np.ndarray:
    """Signed distance between solid spheroids (1-D batch) and a box, by coal.

    Each pair is one coal (3.x) narrow-phase query between an
    ``Ellipsoid(a, b, b)`` posed along the spheroid's major axis and the
    ``Box``: GJK (Gilbert–Johnson–Keerthi 1988) on the support functions
    while separated, EPA (van den Bergen 2001) when they overlap, so an
    overlap reports −(true penetration depth: the shortest translation that
    separates the two), never less deep than any box point's depth inside
    the spheroid (the old probe depth).  Separated distances are coal's GJK
    distance at tolerance 1e-9 (agreement with the converged closed-pair
    reference ≤ 1e-8 m, tests/blasting/test_collision.py).

    ``tol`` is an upper bound on the error of a separated distance (coal's
    GJK tolerance is ``min(tol, 1e-9)``), ``max_iter`` a floor on GJK's
    iteration cap; ``sign_only``, ``margin`` and ``rel_tol`` are accepted for
    the callers' contract (values are exact, so they satisfy it trivially).
    Values are kept within the bounds of the spheroid's inner and outer balls
    (coal's EPA can leave them on overlaps, or give up with −DBL_MAX).
    """
    del sign_only, margin, rel_tol  # exact values satisfy every mode's contract
    n = S.cf.shape[0]
    out = np.empty(n)
    if n == 0:
        return out
    shape_b, tf_b = _coal_box(box)
    req = coal.DistanceRequest()
    req.gjk_tolerance = min(tol, _GJK_TOL)
    req.epa_tolerance = _GJK_TOL
    req.gjk_max_iterations = max(int(max_iter), 128)
    req.enable_signed_distance = True
    res = coal.DistanceResult()
    # rigid links give a handful of distinct (a, b): one coal shape each
    a = np.maximum(S.a, 1e-9)
    b = np.clip(S.b, 1e-9, a)
    keys = list(zip(a.tolist(), b.tolist(), strict=True))
    # one setTransform on list items (~0.4 µs) instead of setRotation +
    # setTranslation on array slices (~4.6 µs, eigenpy conversions)
    R = list(spheroid_frames(S))
    c = list(np.ascontiguousarray(S.center))
    shapes: dict[tuple[float, float], coal.Ellipsoid] = {}
    tf = coal.Transform3s()
    for i, key in enumerate(keys):
        e = shapes.get(key)
        if e is None:
            e = shapes[key] = coal.Ellipsoid(key[0], key[1], key[1])
        tf.setTransform(R[i], c[i])
        res.clear()
        out[i] = coal.distance(e, tf, shape_b, tf_b, req, res)
    # The spheroid lies in the ball of radius a about its centre and holds the
    # ball of radius b, so sd(c) − a ≤ d ≤ sd(c) − b.  coal's EPA can leave that
    # interval on overlaps (measured: −0.665 m for a spheroid of a = 0.175 m whose
    # centre is 5.7 cm outside the box) or give up (−DBL_MAX): such a value is
    # moved to the nearest end, which is closer to the truth; a NaN takes the
    # lower end, so a check never reads a pose as clearer than it is.
    sd = box.signed_distance(S.center)
    lo, hi = sd - S.a, sd - S.b
    out = np.where(np.isnan(out), lo, np.clip(out, lo, hi))
    return out


#: Balls covering a spheroid for the pruning's second lower bound (see
#: :func:`capsule_lower_bound`).
LB_BALLS = 4


def capsule_lower_bound(S: Spheroids, box: Box) -> np.ndarray:
    """A lower bound (n,) on the signed distance between each spheroid and
    ``box`` from box signed distances of points only, at least the outer
    ball's sd(c) − a and often much tighter for slender spheroids.

    The spheroid lies in the capsule of radius b about the axis segment
    c ± (a − b)·u (a point at x = a − s, 0 ≤ s ≤ b, has r² = b²(1 − x²/a²),
    and (b − s)² + r² ≤ b² iff s(1 + b/a) ≤ 2b, true as s ≤ b), hence in the
    :data:`LB_BALLS` balls of radius b + ℓ/2 about the midpoints of equal
    pieces (length ℓ) of that segment.  When every ball is clear of the box
    the spheroid is at least the nearest ball's distance away; a union of
    overlapping balls says nothing about the depth, so there the outer ball
    (radius a, which holds the spheroid) gives the bound."""
    c, a, b, u = S.center, S.a, S.b, S.axis
    outer = box.signed_distance(c) - a
    half = np.maximum(a - b, 0.0)
    ell = 2.0 * half / LB_BALLS
    balls = np.full(len(a), np.inf)
    for j in range(LB_BALLS):
        cj = c + (ell * (j + 0.5) - half)[:, None] * u
        balls = np.minimum(balls, box.signed_distance(cj) - (b + ell / 2.0))
    return np.where(balls >= 0.0, np.maximum(balls, outer), outer)


def clearance(
    S: Spheroids,
    obstacles: Obstacles,
    *,
    horizon: float = np.inf,
    sign_only: bool = False,
    margin: float = 0.0,
    rel_tol: float = 0.0,
    box_distance: Callable[..., np.ndarray] | None = None,
) -> np.ndarray:
    """Smallest signed distance from each set of spheroids (..., E) to any
    obstacle: returns (...,) (``inf`` when there are none).  ``box_distance``
    replaces :func:`spheroid_box_distance` (the benchmark passes the former
    hand-written kernel through it).  Pairs whose
    bounding-sphere lower bound exceeds the best upper bound (or ``horizon``)
    are not refined, so values beyond ``horizon`` are lower bounds; with
    ``sign_only`` only the comparison with ``margin`` is exact (values above
    it are lower bounds); ``rel_tol`` > 0 lets box distances stop at a lower
    bound within that fraction of the gap (see :func:`spheroid_box_distance`)."""
    shape = S.cf.shape[:-1]
    E = S.cf.shape[-1]
    flat = Spheroids(S.f1.reshape(-1, 3), S.f2.reshape(-1, 3), S.cf.reshape(-1))
    n = flat.cf.shape[0]
    best = np.full(n, np.inf)
    c, a = flat.center, flat.a
    if obstacles.boxes:
        dc = np.stack([b.signed_distance(c) for b in obstacles.boxes], axis=1)  # (n,B)
        # The spheroid lies in the ball of radius a about its centre and holds
        # the ball of radius b (its minor semi-axis); a ball's signed distance to
        # a box is sd(centre) − radius, so sd(c) − a ≤ d ≤ sd(c) − b.
        lbs = dc - a[:, None]
        ubs = dc - flat.b[:, None]
        # upper bound per pose (over its E spheroids and all boxes)
        ub_pose = ubs.reshape(-1, E, len(obstacles.boxes)).min(axis=(1, 2))
        ub = np.repeat(ub_pose, E)
        if sign_only:
            # Only the comparison with the margin must be exact: a pose whose
            # bound is already below it is decided, and a pair whose lower bound
            # is above it cannot bring the pose below it.
            ub = np.where(ub < margin, -np.inf, np.minimum(ub, margin))
        for k, box in enumerate(obstacles.boxes):
            need = np.nonzero((lbs[:, k] <= ub) & (lbs[:, k] <= horizon))[0]
            value = lbs[:, k].copy()  # pairs not refined hold their lower bound
            if len(need):
                # the capsule bound prunes most of the rest before the narrow
                # phase (on these pairs only: it costs 4 box distances each)
                value[need] = capsule_lower_bound(flat[need], box)
                need = need[(value[need] <= ub[need]) & (value[need] <= horizon)]
            if len(need):
                value[need] = (box_distance or spheroid_box_distance)(
                    flat[need], box, sign_only=sign_only, margin=margin, rel_tol=rel_tol
                )
            np.minimum(best, value, out=best)
    if obstacles._tree is not None:
        d_c = np.asarray(obstacles._tree.query(c, k=1)[0])  # (N,) for points c (N,3)
        # only points that could beat the pose's current upper bound (the box
        # distances, and each spheroid's distance to its nearest-centre point,
        # which is ≤ d_c) are refined; in sign-only mode only those within
        # the margin matter
        if sign_only:
            bound = np.full(n, max(margin, 0.0))
        else:
            ub_pose = np.minimum(best, d_c).reshape(-1, E).min(axis=1)
            bound = np.minimum(np.repeat(ub_pose, E), horizon)
        lists = obstacles._tree.query_ball_point(c, np.maximum(bound, 0.0) + a)
        lens = np.fromiter((len(li) for li in lists), dtype=np.int64, count=n)
        if lens.sum():
            idx = np.concatenate([np.asarray(li, dtype=np.int64) for li in lists if len(li)])
            owner = np.repeat(np.arange(n), lens)
            d = spheroid_point_distance(flat[owner], obstacles.points[idx])
            np.minimum.at(best, owner, d)
        far = lens == 0
        best[far] = np.minimum(best[far], d_c[far] - a[far])
    # exact where refined; pruned ones only ever hold a lower bound ≥ the pose minimum
    return best.reshape(*shape, E).min(axis=-1)
