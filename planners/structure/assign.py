"""Member label per input point: among the members whose envelope (axis
segment thickened by the member's radius plus a margin) holds the point,
the one it is deepest inside relative to the envelope's radius
(distance / radius), or −1.  Relative depth, not distance: a wide beam's
flange lies closer to a slender diagonal's axis than to its own, but deep
in the beam's envelope and at the rim of the diagonal's.  Points inside two envelopes are flagged
as joint-zone points for the face test of :mod:`.pipeline`.

Distances are computed point × member in row chunks bounded by ``BUDGET``
elements, so memory does not grow with the product of the two counts.
"""

from __future__ import annotations

import numpy as np

#: point × member distance elements per chunk
BUDGET = 4_000_000


def segment_distances(
    points: np.ndarray, centres: np.ndarray, dirs: np.ndarray, t0: np.ndarray, t1: np.ndarray
) -> np.ndarray:
    """(n, M) distances from points to the M axis segments ``centre + t·dir``, t ∈ [t0, t1]."""
    rel = points[:, None, :] - centres[None]
    t = np.clip(np.einsum("nmi,mi->nm", rel, dirs), t0[None], t1[None])
    return np.linalg.norm(rel - t[..., None] * dirs[None], axis=2)


def assign_points(
    points: np.ndarray,
    centres: np.ndarray,
    dirs: np.ndarray,
    t0: np.ndarray,
    t1: np.ndarray,
    radius: np.ndarray,
    margin: float,
) -> tuple[np.ndarray, np.ndarray]:
    """``(labels, shared)``: (N,) member index per point (−1 outside every
    envelope) and (N,) whether the point lies inside two or more envelopes."""
    n, m = len(points), len(centres)
    out = np.full(n, -1, dtype=np.int64)
    shared = np.zeros(n, dtype=bool)
    if m == 0 or n == 0:
        return out, shared
    step = max(1, BUDGET // (3 * m))
    reach = radius[None] + margin
    for a in range(0, n, step):
        d = segment_distances(points[a : a + step], centres, dirs, t0, t1)
        inside = d <= reach
        depth = np.where(inside, d / radius[None], np.inf)
        best = np.argmin(depth, axis=1)
        ok = inside.any(axis=1)
        out[a : a + step] = np.where(ok, best, -1)
        shared[a : a + step] = inside.sum(axis=1) >= 2
    return out, shared


def face_distances(points: np.ndarray, faces: list) -> np.ndarray:  # list[Face]
    """(n, F) distance from each point to each face rectangle (its boundary's
    bounding box in the face plane), computed in one block: callers chunk."""
    o = np.array([f.origin for f in faces])
    x = np.array([f.x_axis for f in faces])
    nrm = np.array([f.normal for f in faces])
    y = np.cross(nrm, x)
    lo = np.array([f.boundary.min(axis=0) for f in faces])
    hi = np.array([f.boundary.max(axis=0) for f in faces])
    rel = points[:, None, :] - o[None]
    px = np.einsum("nfi,fi->nf", rel, x)
    py = np.einsum("nfi,fi->nf", rel, y)
    pz = np.einsum("nfi,fi->nf", rel, nrm)
    dx = np.maximum(np.maximum(lo[None, :, 0] - px, px - hi[None, :, 0]), 0.0)
    dy = np.maximum(np.maximum(lo[None, :, 1] - py, py - hi[None, :, 1]), 0.0)
    return np.sqrt(dx**2 + dy**2 + pz**2)


def relabel_by_faces(
    points: np.ndarray, labels: np.ndarray, which: np.ndarray, faces: list, tol: float
) -> np.ndarray:
    """``labels`` with the points ``which`` given to the member owning the
    nearest face within ``tol`` (others unchanged); face × point blocks bounded."""
    out = labels.copy()
    idx = np.flatnonzero(which)
    if len(idx) == 0 or not faces:
        return out
    owner = np.array([f.member for f in faces])
    step = max(1, BUDGET // (3 * len(faces)))
    for a in range(0, len(idx), step):
        sel = idx[a : a + step]
        d = face_distances(points[sel], faces)
        k = np.argmin(d, axis=1)
        ok = d[np.arange(len(sel)), k] <= tol
        out[sel[ok]] = owner[k[ok]]
    return out
