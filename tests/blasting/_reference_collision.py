"""Reference only (tests and benchmarks): the hand-written spheroid–box kernel
that ``planners/blasting/collision.py`` used before coal,
kept verbatim (the kernel alone; the shapes and the rest of the module
are imported from the product) so the coal path is checked against an independent
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

from typing import Any

import numpy as np

from planners.blasting import collision as _product
from planners.blasting.collision import (
    Box,
    Obstacles,
    Spheroids,
    box_support_min,
    spheroid_closest,
    spheroid_point_distance,
    spheroid_support,
)

__all__ = ["clearance", "spheroid_box_distance", "spheroid_project"]


def spheroid_project(S: Spheroids, p: np.ndarray) -> np.ndarray:
    """Nearest point of the solid spheroid (points inside stay put)."""
    q, d = spheroid_closest(S, p)
    return np.where((d <= 0)[..., None], p, q)


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


def clearance(S: Spheroids, obstacles: Obstacles, **kw: Any) -> np.ndarray:
    """The product's clearance with this kernel for spheroid–box pairs."""
    return _product.clearance(S, obstacles, box_distance=spheroid_box_distance, **kw)
