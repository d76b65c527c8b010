"""Member label per input point: among the members whose envelope (axis
segment thickened by the member's radius plus a margin) holds the point,
the one it is deepest inside relative to the envelope's radius
(distance / radius), or −1.  Relative depth, not distance: a wide beam's
flange lies closer to a slender diagonal's axis than to its own, but deep
in the beam's envelope and at the rim of the diagonal's.  Points inside two envelopes are flagged
as joint-zone points for the face test of :mod:`.pipeline`.

Each member looks only at the points a KD-tree finds near its axis; the
face distances run point × face in row chunks bounded by ``BUDGET``
elements, so memory does not grow with the product of two counts.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from planners.structure.indices import hit_union
from planners.structure.model import Face

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
    tree: cKDTree | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """``(labels, shared)``: (N,) member index per point (−1 outside every
    envelope) and (N,) whether the point lies inside two or more envelopes.

    Per member, only the points near it are looked at: the axis is sampled
    every envelope radius h, and a point within the envelope (radius ρ) of
    the segment is within ρ + h/2 of a sample, so a ball query on the
    points' KD-tree (``tree``, built here when not given) finds them all.
    Work and memory follow the points near each member, not N × M."""
    n, m = len(points), len(centres)
    out = np.full(n, -1, dtype=np.int64)
    count = np.zeros(n, dtype=np.int32)
    best = np.full(n, np.inf)
    if m == 0 or n == 0:
        return out, count >= 2
    tree = tree if tree is not None else cKDTree(points)
    for k in range(m):
        reach = float(radius[k] + margin)
        h = max(reach, 1e-3)
        ns = max(2, int(np.ceil((t1[k] - t0[k]) / h)) + 1)
        samples = centres[k] + np.outer(np.linspace(t0[k], t1[k], ns), dirs[k])
        hits = tree.query_ball_point(samples, reach + 0.5 * h, return_sorted=False)
        idx = hit_union(hits)
        if len(idx) == 0:
            continue
        d = segment_distances(
            points[idx], centres[k : k + 1], dirs[k : k + 1], t0[k : k + 1], t1[k : k + 1]
        )[:, 0]
        inside = d <= reach
        idx, depth = idx[inside], d[inside] / radius[k]
        count[idx] += 1
        better = depth < best[idx]  # strict: the lower member index wins a tie
        best[idx[better]] = depth[better]
        out[idx[better]] = k
    return out, count >= 2


def face_distances(
    points: np.ndarray, faces: list[Face], extend: np.ndarray | None = None
) -> np.ndarray:
    """(n, F) distance from each point to each face rectangle (its boundary's
    bounding box in the face plane, lengthened by ``extend`` (F,) at both
    ends along the member), computed in one block: callers chunk."""
    o = np.array([f.origin for f in faces])
    x = np.array([f.x_axis for f in faces])
    nrm = np.array([f.normal for f in faces])
    y = np.cross(nrm, x)
    lo = np.array([f.boundary.min(axis=0) for f in faces])
    hi = np.array([f.boundary.max(axis=0) for f in faces])
    if extend is not None:
        lo[:, 0] -= extend
        hi[:, 0] += extend
    rel = points[:, None, :] - o[None]
    px = np.einsum("nfi,fi->nf", rel, x)
    py = np.einsum("nfi,fi->nf", rel, y)
    pz = np.einsum("nfi,fi->nf", rel, nrm)
    dx = np.maximum(np.maximum(lo[None, :, 0] - px, px - hi[None, :, 0]), 0.0)
    dy = np.maximum(np.maximum(lo[None, :, 1] - py, py - hi[None, :, 1]), 0.0)
    return np.sqrt(dx**2 + dy**2 + pz**2)


def relabel_by_faces(
    points: np.ndarray,
    labels: np.ndarray,
    which: np.ndarray,
    faces: list[Face],
    tol: float,
    extend: np.ndarray | None = None,
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
        d = face_distances(points[sel], faces, extend)
        k = np.argmin(d, axis=1)
        ok = d[np.arange(len(sel)), k] <= tol
        out[sel[ok]] = owner[k[ok]]
    return out


#: a stretch up to this many tube diameters either side of its middle is
#: queried as one ball (a superset of the tube that callers filter): one
#: query is ~4x cheaper than a sample's worth of them
NEAR_LINE_ONE_BALL = 4.0


def near_line(
    points: np.ndarray,
    tree: cKDTree,
    centre: np.ndarray,
    direction: np.ndarray,
    t_lo: float,
    t_hi: float,
    radius: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(idx, t, perp)`` of the points within two ``radius`` of the stretch
    ``[t_lo, t_hi]`` of the line (a ball query a sample, one radius apart:
    bounded by the stretch's length; one ball for a short stretch), with
    their parameter along the line and their distance from it.  The indices
    are ascending; points beyond the tube may be among them (callers filter
    by ``t`` and the distance)."""
    h = max(radius, 1e-3)
    half = 0.5 * (t_hi - t_lo)
    if half <= NEAR_LINE_ONE_BALL * 2.0 * h:
        # a short stretch: one ball round its middle holds the whole tube
        samples = (centre + (t_lo + half) * direction)[None]
        reach = half + 2.0 * h
    else:
        ns = max(2, int(np.ceil((t_hi - t_lo) / h)) + 1)
        samples = centre + np.outer(np.linspace(t_lo, t_hi, ns), direction)
        reach = 2.0 * radius + 0.5 * h
    hits = tree.query_ball_point(samples, reach, return_sorted=False)  # a list a sample
    idx = hit_union(hits)
    rel = points[idx] - centre
    t = rel @ direction
    return idx, t, np.linalg.norm(rel - np.outer(t, direction), axis=1)


#: a grown stretch may hold at most this many free points in the ring
#: between one and two radii round the axis per point within one radius: a
#: member continues as a line, a piece of ground or slab as a plane
RING_MAX = 0.5


def grow_end(
    points: np.ndarray,
    tree: cKDTree,
    free: np.ndarray,
    centre: np.ndarray,
    direction: np.ndarray,
    t_end: float,
    sign: float,
    radius: float,
    step: float,
    max_growth: float,
) -> float:
    """How far (m, ≥ 0) a member's end at ``centre + t_end·direction`` moves
    outward (``sign`` ±1) over the ``free`` points continuing its axis.

    The extension is cut in stretches ``step`` long; the walk enters the next
    stretch while it holds free points within ``radius`` of the axis and not
    more than ``RING_MAX`` times as many between one and two radii (a line
    goes on, a plane spreads), and stops after ``max_growth``.  The end moves
    to the farthest point walked.

    A region split by a joint or by a few points lost to a neighbour leaves
    the member's own points unlabelled beyond its end, where no envelope
    reaches; walking over them gives the pieces back their extent, so that
    collinear pieces meet within the occlusion gap allowed.  Only the points
    the KD-tree finds near the extension are looked at (bounded by the
    extension's length, not the cloud's size)."""
    if max_growth <= 0 or radius <= 0 or step <= 0:
        return 0.0
    far_end = t_end + sign * max_growth
    idx, t, perp = near_line(
        points, tree, centre, direction, min(t_end, far_end), max(t_end, far_end), radius
    )
    mine = free[idx]
    t, perp = t[mine], perp[mine]
    ahead = sign * (t - t_end)
    keep = (ahead > 0) & (ahead <= max_growth) & (perp <= 2.0 * radius)
    ahead, inner = ahead[keep], perp[keep] <= radius
    n_bins = int(np.ceil(max_growth / step))
    b = np.minimum((ahead / step).astype(np.int64), n_bins - 1)
    n_in = np.bincount(b[inner], minlength=n_bins)
    n_ring = np.bincount(b[~inner], minlength=n_bins)
    far = np.full(n_bins, 0.0)
    np.maximum.at(far, b[inner], ahead[inner])
    reached = 0.0
    for k in range(n_bins):
        if n_in[k] == 0 or n_ring[k] > RING_MAX * n_in[k]:
            break
        reached = float(far[k])
    return reached


def gap_filled(
    points: np.ndarray,
    tree: cKDTree,
    unlabelled: np.ndarray,
    centre: np.ndarray,
    direction: np.ndarray,
    t_from: float,
    t_to: float,
    radius: float,
    max_empty: float,
) -> bool:
    """Whether the stretch ``[t_from, t_to]`` of the line ``centre +
    t·direction`` is steel: points within ``radius`` of it all along, no
    empty stretch longer than ``max_empty``, and not more than ``RING_MAX``
    ``unlabelled`` points between one and two radii per point within one (a
    piece of ground or slab spreads beside the line; a crossing member's
    points are labelled and do not count).  Only the points a KD-tree finds
    near the stretch are looked at."""
    lo, hi = min(t_from, t_to), max(t_from, t_to)
    if hi - lo <= max_empty:
        return True
    if radius <= 0:
        return False
    idx, t, perp = near_line(points, tree, centre, direction, lo, hi, radius)
    along = (t >= lo) & (t <= hi)
    inner = along & (perp <= radius)
    ring = along & (perp > radius) & (perp <= 2.0 * radius) & unlabelled[idx]
    if not inner.any() or ring.sum() > RING_MAX * inner.sum():
        return False
    ts = np.concatenate([[lo], np.sort(t[inner]), [hi]])
    return float(np.diff(ts).max()) <= max_empty
