"""Sparse member rows: lines through the points no member candidate explains.

A member far from every scanner, or seen past others, comes out of a coarse
scan as a row of single points, one every 10–50 cm with the section's width
of scatter across it: a voxel neighbourhood on it holds too few points, or
its neighbours' steel too, to look linear, and the line features miss it
(a 10 cm Pratt's posts, 13–23 points over 1.2 m).

The points outside every candidate's envelope are searched by a seeded
line walk (a deterministic cousin of RANSAC, Fischler & Bolles 1981, that
needs no random hypotheses): a seed is a point whose ``SPARSE_K`` nearest
free neighbours make a line; seeds are taken most isolated first, each
walks along its neighbours' principal direction, one end at a time, to the
furthest point within ``SPARSE_GAP_SPACINGS`` and ``SPARSE_TOL_SPACINGS``
of the line, and the line is refitted through the row and walked again
while that finds more points.

A row is kept when it holds ``SPARSE_MIN_POINTS``, is as long as a member
and is not a piece of something larger: the free points beside it within
``SPARSE_SIDE_SPACINGS`` lie off every plane through it (at most
``SPARSE_PLANE_MAX`` per inlier on the best one; a scan ring on the ground
has the next rings beside it).  Rows go through the same assignment,
refit, joins and clutter tests as the features' candidates; :mod:`.bridges`
asks the same walk for rows of fewer points (down to ``short_points``).  Every query is a ball or
k-nearest query of bounded size; nothing is pairwise.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from planners.structure.assign import near_line
from planners.structure.features import QUERY_WORKERS
from planners.structure.indices import sorted_unique
from planners.structure.lines import LineCandidate, fit_line

#: inliers a sparse row needs at least
SPARSE_MIN_POINTS = 8
#: an inlier lies within this many spacings of the line
SPARSE_TOL_SPACINGS = 1.0
#: consecutive inliers along a row are at most this many spacings apart
SPARSE_GAP_SPACINGS = 8.0
#: neighbours (within ``SPARSE_SIDE_SPACINGS``) of the linearity test, and
#: the (λ1 − λ2)/λ1 a hypothesis's points need
SPARSE_K = 8
SPARSE_LINEARITY = 0.6
#: the plane test looks this many spacings to either side of the row
SPARSE_SIDE_SPACINGS = 10.0
#: free points on the best plane through the row, per inlier, at most
SPARSE_PLANE_MAX = 1.0
#: seeds tried and rows kept at most: bound the stage's work
SPARSE_MAX_ATTEMPTS = 400
SPARSE_MAX_ROWS = 48
#: a rejected row's points stay free for the seeds after it; True retires
#: them with it, as the stage first did: rows walked across a post from
#: off it (too short, or on a plane) took its points a few at a time and
#: left too little of it (10 cm Pratt recall 0.924 with it, 0.938 without)
RETIRE_REJECTED = False
#: refits of a row's line while its walk finds more points
SPARSE_REFITS = 6
#: steps an end of a row may take (bounds the walk along a long row)
_MAX_STEPS = 2_000
#: plane directions tried round the row
_PLANE_DIRECTIONS = 16


def _along(
    pts: np.ndarray,
    tree: cKDTree,
    centre: np.ndarray,
    d: np.ndarray,
    lo: float,
    hi: float,
    tol: float,
) -> np.ndarray:
    """Indices of the points within ``tol`` of the stretch ``[lo, hi]`` of the
    line (:func:`.assign.near_line`: bounded by the stretch's length)."""
    idx, t, perp = near_line(pts, tree, centre, d, lo, hi, 0.5 * tol)
    return idx[(perp <= tol) & (t >= lo) & (t <= hi)]


def _grow(
    pts: np.ndarray,
    tree: cKDTree,
    centre: np.ndarray,
    d: np.ndarray,
    seed_t: float,
    tol: float,
    gap: float,
) -> np.ndarray:
    """The inliers of the row through ``centre + seed_t·d``: from the seed,
    each end moves on to the furthest inlier within ``gap`` of it until none
    is left (each step queries one gap's stretch: bounded by the row)."""
    found = [_along(pts, tree, centre, d, seed_t - gap, seed_t + gap, tol)]
    for sign in (1.0, -1.0):
        end = seed_t
        for _ in range(_MAX_STEPS):
            lo, hi = (end, end + gap) if sign > 0 else (end - gap, end)
            idx = _along(pts, tree, centre, d, lo, hi, tol)
            if not len(idx):
                break
            t = (pts[idx] - centre) @ d
            new_end = float(t.max()) if sign > 0 else float(t.min())
            if sign * (new_end - end) <= 0.25 * tol:
                break
            found.append(idx)
            end = new_end
    return sorted_unique(np.concatenate(found))


def _on_a_plane(
    pts: np.ndarray,
    tree: cKDTree,
    centre: np.ndarray,
    d: np.ndarray,
    lo: float,
    hi: float,
    tol: float,
    side: float,
) -> int:
    """The most free points beside the row (within ``side``, beyond ``tol``)
    that lie within ``tol`` of one plane through the row."""
    idx, t, r = near_line(pts, tree, centre, d, lo, hi, 0.5 * side)
    off = pts[idx] - centre - np.outer(t, d)
    near = (t >= lo) & (t <= hi) & (r > tol) & (r <= side)
    if not near.any():
        return 0
    u = np.cross(d, [1.0, 0.0, 0.0] if abs(d[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(d, u)
    ang = np.linspace(0.0, np.pi, _PLANE_DIRECTIONS, endpoint=False)
    normals = np.outer(np.cos(ang), u) + np.outer(np.sin(ang), v)  # (K, 3)
    dist = np.abs(off[near] @ normals.T)  # (near, K): bounded by the side band
    return int((dist <= tol).sum(axis=0).max())


def _linear(
    pts: np.ndarray, tree: cKDTree, side: float, at: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """``(score, direction)`` per point of ``pts`` (``tree`` is theirs), or per
    point ``at`` (indices) only: its nearest ``SPARSE_K`` neighbours within
    ``side`` and their principal direction; the score is how many they are
    when they make a line ((λ1 − λ2)/λ1 ≥ ``SPARSE_LINEARITY``), else 0 (a
    point of a scan ring on the ground has the next rings beside it).  k is
    fixed: bounded."""
    data = pts
    if at is not None:
        pts = pts[at]
    k = min(SPARSE_K + 1, len(data))
    if len(pts) == 0:
        return np.zeros(0, np.int64), np.zeros((0, 3))
    dist, nb = tree.query(pts, k=k, distance_upper_bound=side, workers=QUERY_WORKERS)
    dist = np.asarray(dist).reshape(len(pts), k)
    nb = np.asarray(nb).reshape(len(pts), k)
    ok = np.isfinite(dist)
    n = ok.sum(axis=1)
    q = data[np.where(ok, nb, 0)]  # (N, k, 3)
    w = ok[:, :, None].astype(float)
    mean = (q * w).sum(axis=1) / np.maximum(n, 1)[:, None]
    r = (q - mean[:, None, :]) * w
    cov = np.einsum("nki,nkj->nij", r, r) / np.maximum(n, 1)[:, None, None]
    ev, vec = np.linalg.eigh(cov)  # ascending
    lin = (ev[:, 2] - ev[:, 1]) / np.maximum(ev[:, 2], 1e-18)
    score = np.where((n >= 3) & (lin >= SPARSE_LINEARITY), n, 0)
    return score, vec[:, :, 2]


def sparse_rows(
    points: np.ndarray,
    free: np.ndarray,
    spacing: float,
    min_length: float,
) -> list[LineCandidate]:
    """Line candidates (no voxels) through sparse rows of the ``free``
    points (a boolean mask over ``points``) at least ``min_length`` long,
    of ``SPARSE_MIN_POINTS`` or more (:func:`walk_rows`)."""
    return walk_rows(points, free, spacing, min_length)


def walk_rows(
    points: np.ndarray,
    free: np.ndarray,
    spacing: float,
    min_length: float,
    short_points: int | None = None,
    max_attempts: int | None = None,
    seeds: np.ndarray | None = None,
) -> list[LineCandidate]:
    """Line candidates (no voxels) through sparse rows of the ``free``
    points (a boolean mask over ``points``) at least ``min_length`` long, of
    ``SPARSE_MIN_POINTS`` or more; then the rows that pass every test but
    hold only ``short_points`` to ``SPARSE_MIN_POINTS`` − 1 points (none when
    ``short_points`` is ``None``).  A short row keeps its points free for
    the seeds after it, as a rejected one does, so asking for them changes
    no other row.  At most ``max_attempts`` seeds (default
    ``SPARSE_MAX_ATTEMPTS``) are walked, and only free points also in
    ``seeds`` (a mask over ``points``) seed rows when it is given; rows take
    their points from every free point.
    Deterministic: seeds are tried most isolated first (linear neighbours
    per point within ``SPARSE_SIDE_SPACINGS``; then the most neighbours, a
    row's middle before its ends), each along its neighbours' principal
    direction."""
    min_points = SPARSE_MIN_POINTS
    if max_attempts is None:
        max_attempts = SPARSE_MAX_ATTEMPTS
    least = min_points if short_points is None else min(short_points, min_points)
    idx = np.flatnonzero(free)
    if len(idx) < least:
        return []
    pts = points[idx]
    tree = cKDTree(pts)
    tol = SPARSE_TOL_SPACINGS * spacing
    gap = SPARSE_GAP_SPACINGS * spacing
    side = SPARSE_SIDE_SPACINGS * spacing
    if seeds is None:
        score, dirs = _linear(pts, tree, side)
    else:
        # only the points allowed to seed a row are scored
        at = np.flatnonzero(seeds[idx])
        score = np.zeros(len(pts), np.int64)
        dirs = np.zeros((len(pts), 3))
        score[at], dirs[at] = _linear(pts, tree, side, at)
    order = np.flatnonzero(score)
    # isolated rows first: a point of a row has few free points round it
    # besides its row's, a point of a ring on the ground the next rings too
    ball = np.asarray(
        tree.query_ball_point(pts[order], side, return_length=True, workers=QUERY_WORKERS)
    )
    priority = score[order] / np.maximum(ball, 1)
    order = order[np.lexsort((order, -score[order], -priority))]
    alive = np.ones(len(pts), bool)
    out: list[LineCandidate] = []
    short: list[LineCandidate] = []
    for i in order[:max_attempts]:
        if not alive[i]:
            continue
        inl = _grow(pts, tree, pts[i], dirs[i], 0.0, tol, gap)
        inl = inl[alive[inl]]
        for _ in range(SPARSE_REFITS):
            # a few neighbours' direction drifts off a long row: refit
            # through the row's points so far and walk it again
            if len(inl) < 3:
                break
            c, d2, _, _, _ = fit_line(pts[inl], 0.0, 100.0)
            again = _grow(pts, tree, c, d2, float((pts[i] - c) @ d2), tol, gap)
            again = again[alive[again]]
            if len(again) <= len(inl):
                break
            inl = again
        alive[i] = False
        if RETIRE_REJECTED:
            alive[inl] = False
        if len(inl) < least:
            continue
        c, d, t0, t1, rad = fit_line(pts[inl], 0.0, 100.0)
        if t1 - t0 < min_length:
            continue
        if _on_a_plane(pts, tree, c, d, t0, t1, tol, side) > SPARSE_PLANE_MAX * len(inl):
            continue
        row = LineCandidate(np.zeros(0, np.int64), c, d, t0, t1, max(rad, spacing))
        if len(inl) < min_points:
            short.append(row)
            continue
        alive[inl] = False
        out.append(row)
        if len(out) >= SPARSE_MAX_ROWS:
            break
    return out + short
