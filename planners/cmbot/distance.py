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
(``tests/benchmarks/bench_collision.py``, issue #13 §1).
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
