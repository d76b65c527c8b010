"""Sphere–cuboid distances for the arm's obstacle avoidance (seed §3.2, Fig. 12–13).

The arm is covered by spheres C_i, the guardrail, brackets and climbing
mechanism are cuboids D_j.  :func:`sphere_box_exact` is the closed form for
spheres against oriented boxes — clamp the centre into the box in its own
axes, d_ij = ‖centre − clamp‖ − r_i — vectorised over all pairs (and time
steps); it gives d_ij and the unit direction u_ij from the closest point of
D_j to the closest point of C_i used by Eq. 15.  Penetration (a centre inside
a box) gets a negative distance (the depth to the nearest face, which is the
true penetration depth of a sphere in a box) and that face's normal.

It replaced a plain-float GJK (Gilbert, Johnson & Keerthi 1988; kept as a
test reference in ``tests/cmbot/_reference_gjk.py``): the closed form is
exact, and measured faster than both that GJK and coal's per query
(``tests/benchmarks/bench_collision.py``).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
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


def boxes_arrays(boxes: Sequence[Cuboid]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stack boxes into centres (M,3), half extents (M,3), rotations (M,3,3)."""
    if not boxes:
        return np.zeros((0, 3)), np.ones((0, 3)), np.zeros((0, 3, 3))
    return (
        np.array([b.center for b in boxes]),
        np.array([b.half for b in boxes]),
        np.array([b.rotation for b in boxes]),
    )


def point_box_closed_form(
    rel: np.ndarray,
    half: np.ndarray,
    R: np.ndarray,
    *,
    directions: bool = True,
) -> tuple[np.ndarray, np.ndarray | None]:
    """Signed distance (…) and unit direction (…,3) from oriented boxes to points.

    ``rel`` (…,3) is the point minus the box centre, ``half`` (…,3) the half
    extents and ``R`` (…,3,3) the box axes (columns), all broadcast together.
    Outside: ‖local − clamp(local)‖ and the normalised difference; inside: minus
    the depth to the nearest face and that face's normal.  Written per axis
    (no reductions over the length-3 axis): numpy's reductions and small
    matmuls over tiny trailing axes cost far more than the arithmetic.
    """
    if not directions:
        return _point_box_distance(rel, half, R), None
    r0, r1, r2 = rel[..., 0:1], rel[..., 1:2], rel[..., 2:3]
    # local_i = Σ_j R_ji·rel_j: the point in the box's own axes
    local = r0 * R[..., 0, :] + r1 * R[..., 1, :] + r2 * R[..., 2, :]
    gap = half - np.abs(local)
    excess = np.maximum(-gap, 0.0)
    e0, e1, e2 = excess[..., 0], excess[..., 1], excess[..., 2]
    dist_out = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
    g0, g1, g2 = gap[..., 0], gap[..., 1], gap[..., 2]
    depth = np.minimum(np.minimum(g0, g1), g2)
    inside = dist_out <= 0.0
    d = np.where(inside, -depth, dist_out)
    if not directions:
        return d, None
    # Inside: the nearest face's outward normal (first axis on ties, as argmin).
    first = (g0 <= g1) & (g0 <= g2)
    second = ~first & (g1 <= g2)
    third = ~first & ~second
    side = np.where(local >= 0.0, 1.0, -1.0)
    n_in = side * np.stack([first, second, third], axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        n_out = np.sign(local) * excess / dist_out[..., None]
    n = np.where(inside[..., None], n_in, n_out)
    u = R[..., :, 0] * n[..., 0:1] + R[..., :, 1] * n[..., 1:2] + R[..., :, 2] * n[..., 2:3]
    return d, u


def _point_box_distance(rel: np.ndarray, half: np.ndarray, R: np.ndarray) -> np.ndarray:
    """:func:`point_box_closed_form`'s distance alone, one array per component
    (no length-3 trailing axis in any operation: those run numpy's inner
    loops three elements at a time).  The same operations in the same order
    per element, so the same floats."""
    r0, r1, r2 = rel[..., 0], rel[..., 1], rel[..., 2]
    gaps, ex = [], []
    for k in range(3):
        local = r0 * R[..., 0, k] + r1 * R[..., 1, k] + r2 * R[..., 2, k]
        g = half[..., k] - np.abs(local)
        gaps.append(g)
        ex.append(np.maximum(-g, 0.0))
    dist_out = np.sqrt(ex[0] * ex[0] + ex[1] * ex[1] + ex[2] * ex[2])
    depth = np.minimum(np.minimum(gaps[0], gaps[1]), gaps[2])
    return np.where(dist_out <= 0.0, -depth, dist_out)


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
    d, u = point_box_closed_form(
        rel, bh[..., None, :, :], bR[..., None, :, :, :], directions=directions
    )
    return d - r[..., :, None], u


def sphere_box_pairs(
    centers: np.ndarray,
    radii: np.ndarray,
    boxes: tuple[np.ndarray, np.ndarray, np.ndarray],
    spheres_idx: np.ndarray,
    boxes_idx: np.ndarray,
) -> np.ndarray:
    """Signed distances (…,P) of the P listed sphere–box pairs only (static boxes):
    sphere ``spheres_idx[p]`` of ``centers`` (…,N,3) against box ``boxes_idx[p]``."""
    bc, bh, bR = boxes
    rel = centers[..., spheres_idx, :] - bc[boxes_idx]
    d, _ = point_box_closed_form(rel, bh[boxes_idx], bR[boxes_idx], directions=False)
    return d - np.asarray(radii, dtype=float)[spheres_idx]


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
