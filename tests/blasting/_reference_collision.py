"""Reference only (tests and benchmarks): the hand-written spheroid–box kernel
that ``planners/blasting/collision.py`` used before coal (issue #13 §1),
copied verbatim so the coal path is checked against an independent
implementation.  Its overlap value is a probe depth, not the penetration
depth.  Original module docstring:

Force-field collision model of the arm (seed §3.4.2, Eq. 3.14–3.15).

Each link is covered by a prolate spheroid whose foci F1, F2 lie on the link
and whose major axis is ``C_f = L·Kp`` (L = |F1F2|, Kp > 1; the seed uses
Kp = [1.05, 1.10, 1.10], §4.2.5).  A point is inside when
``R1 + R2 ≤ C_f`` (Eq. 3.14).  Distances are Euclidean, signed (negative
inside): point–spheroid exactly (2-D reduction, Eberly's bisection), and
spheroid–box by alternating projections between the two convex sets (their
closest pair), pruned with bounding spheres so only pairs that can be the
nearest are refined.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from planners.errors import InvalidInputError

_BISECT = 64  # bisection steps: enough for double precision on the root


@dataclass(frozen=True)
class Box:
    """Oriented box: centre (3,), half extents (3,), rotation (3,3) whose
    columns are the box axes in the world."""

    center: np.ndarray
    half: np.ndarray
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    name: str = ""

    @classmethod
    def from_bounds(cls, lo: Sequence[float], hi: Sequence[float], name: str = "") -> Box:
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
        for o in obstacles or ():  # type: ignore[union-attr]
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

    def __getitem__(self, idx: object) -> Spheroids:
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


def spheroid_project(S: Spheroids, p: np.ndarray) -> np.ndarray:
    """Nearest point of the solid spheroid (points inside stay put)."""
    q, d = spheroid_closest(S, p)
    return np.where((d <= 0)[..., None], p, q)


def spheroid_support(S: Spheroids, n: np.ndarray) -> np.ndarray:
    """Support function h(n) = max over the spheroid of n·x (unit n)."""
    nu = np.einsum("...d,...d->...", n, S.axis)
    return np.einsum("...d,...d->...", n, S.center) + np.sqrt(
        S.a**2 * nu**2 + S.b**2 * np.maximum(1.0 - nu**2, 0.0)
    )


def box_support_min(box: Box, n: np.ndarray) -> np.ndarray:
    """min over the box of n·x."""
    return n @ box.center - np.abs(n @ box.rotation) @ box.half


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
    """Signed distance between solid spheroids (1-D batch) and a box.

    Separated: alternating projections between the two convex sets converge
    to a closest pair; their gap is an upper bound and the separating-plane
    bound ``min_box(n·x) − h_spheroid(n)`` (n along the gap) a lower bound,
    so each pair iterates until the two agree within ``tol`` or
    ``rel_tol`` × the gap (the returned lower bound may then understate the
    distance by that much, never overstate it; or, with
    ``sign_only``, until the lower bound exceeds ``margin``); the lower
    bound is returned.  Overlapping (a box
    point inside the spheroid, Eq. 3.14): negative, −(depth of the deepest
    of the box corners, the box centre and that point)."""
    n = S.cf.shape[0]
    y = box.project(S.center)
    x = spheroid_project(S, y)
    ub = np.linalg.norm(x - y, axis=-1)
    lb = np.zeros(n)
    # cheap overlap witnesses first: a focus in the box, or a box corner /
    # the box centre inside the spheroid (Eq. 3.14)
    probes = np.concatenate([box.corners(), box.center[None]], axis=0)  # (9,3)
    overlap = (box.distance(S.f1) <= 0) | (box.distance(S.f2) <= 0)
    overlap |= (
        np.linalg.norm(probes[:, None] - S.f1[None], axis=-1)
        + np.linalg.norm(probes[:, None] - S.f2[None], axis=-1)
        <= S.cf[None]
    ).any(axis=0)
    overlap |= ub <= 1e-12
    active = np.nonzero(~overlap)[0]
    it = 0
    if sign_only:
        max_iter = min(max_iter, 64)  # undecided pairs count as not free (see below)
    while len(active) and it < max_iter:
        Sa = S[active]
        xa = x[active]
        for _ in range(4):
            ya = box.project(xa)
            xa = spheroid_project(Sa, ya)
        it += 4
        ya = box.project(xa)
        gap_v = ya - xa
        gap = np.linalg.norm(gap_v, axis=-1)
        x[active] = xa
        ub[active] = gap
        touching = gap <= 1e-12
        nn = gap_v / np.maximum(gap, 1e-300)[:, None]
        lba = box_support_min(box, nn) - spheroid_support(Sa, nn)
        lb[active] = np.where(touching, 0.0, np.maximum(lba, 0.0))
        overlap[active] = touching | Sa.contains(ya)
        done = overlap[active] | (gap - lba <= np.maximum(tol, rel_tol * gap))
        if sign_only:
            done |= lba > margin
        active = active[~done]
    # The lower bound is reported (within tol of the distance once
    # converged; conservative if max_iter stopped the pair), so clearance is
    # never overstated; in sign-only mode it decides (≤ margin: not free).
    dist = lb
    if overlap.any():
        k = np.nonzero(overlap)[0]
        Sk = S[k]
        d_probe = spheroid_point_distance(
            Spheroids(Sk.f1[None], Sk.f2[None], Sk.cf[None]), probes[:, None, :]
        ).min(axis=0)
        d_iter = spheroid_point_distance(Sk, box.project(x[k]))
        dist[k] = np.minimum(np.minimum(d_probe, d_iter), 0.0)
    return dist


def clearance(
    S: Spheroids,
    obstacles: Obstacles,
    *,
    horizon: float = np.inf,
    sign_only: bool = False,
    margin: float = 0.0,
    rel_tol: float = 0.0,
) -> np.ndarray:
    """Smallest signed distance from each set of spheroids (..., E) to any
    obstacle: returns (...,) (``inf`` when there are none).  Pairs whose
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
        lbs = np.stack([b.distance(c) - a for b in obstacles.boxes], axis=1)  # (n,B)
        ubs = np.stack([b.distance(c) for b in obstacles.boxes], axis=1)
        # upper bound per pose (over its E spheroids and all boxes)
        ub_pose = ubs.reshape(-1, E, len(obstacles.boxes)).min(axis=(1, 2))
        ub = np.repeat(ub_pose, E)
        for k, box in enumerate(obstacles.boxes):
            need = np.nonzero((lbs[:, k] <= ub) & (lbs[:, k] <= horizon))[0]
            if len(need):
                d = spheroid_box_distance(
                    flat[need], box, sign_only=sign_only, margin=margin, rel_tol=rel_tol
                )
                best[need] = np.minimum(best[need], d)
            rest = np.setdiff1d(np.arange(n), need)
            best[rest] = np.minimum(best[rest], lbs[rest, k])
    if obstacles._tree is not None:
        d_c, _ = obstacles._tree.query(c, k=1)
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
