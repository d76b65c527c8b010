"""Clutter test: is a member candidate part of a larger surface?

A member's faces end at the member's edges; a strip of ground, a slab or a
wall that happens to look linear at some scale is a face whose plane goes
on beyond it.  For the candidate's largest face, the points within the
plane tolerance in two bands beside the face (each ``band`` wide, over the
face's length) are binned into cells; when most cells hold a point, the
plane continues and the candidate is a piece of a larger surface.  Coverage,
not density: the plane of a truss also holds its diagonals, which cross the
band as a few narrow strips.  Point lookups go through a KD-tree over
sampled band centres, so the work is bounded by the band area.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from planners.structure.indices import hit_union
from planners.structure.model import Face


def _near(
    tree: cKDTree,
    pts: np.ndarray,
    face: Face,
    centres: np.ndarray,
    reach: float,
    own: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """In-plane x, y and height over ``face`` of the points within
    ``reach`` of any of ``centres``, those flagged in ``own`` left out."""
    found = tree.query_ball_point(centres, reach, return_sorted=False)
    idx = hit_union(found)
    if own is not None and len(idx):
        idx = idx[~own[idx]]
    rel = pts[idx] - face.origin
    return rel @ face.x_axis, rel @ face.y_axis, rel @ face.normal


def plane_continuation(
    tree: cKDTree,
    pts: np.ndarray,
    face: Face,
    band: float,
    tol: float,
    cell: float,
    own: np.ndarray | None = None,
) -> float:
    """Fraction of the ``cell``-sized cells in the better covered of the two
    bands beside ``face`` that hold a point of its plane — the smaller of
    that over the band and over its first row of cells along the face's
    edge (0: the plane ends with the face on both sides).  Points flagged in
    ``own`` (the member's own: its side faces meet this face's edge) are
    not counted."""
    lo, hi = face.boundary.min(axis=0), face.boundary.max(axis=0)
    length = float(hi[0] - lo[0])
    if length <= 0 or hi[1] <= lo[1]:
        return 0.0
    step = band
    xs = (
        np.arange(lo[0] + 0.5 * step, hi[0], step)
        if length > step
        else np.array([0.5 * (lo[0] + hi[0])])
    )
    ys = np.array([lo[1] - 0.5 * band, hi[1] + 0.5 * band])
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    centres = face.to_world(np.column_stack([gx.ravel(), gy.ravel()]))
    reach = float(np.hypot(0.5 * step, 0.5 * band)) + tol
    x, y, z = _near(tree, pts, face, centres, reach, own)
    n_x = max(1, int(np.ceil(length / cell)))
    n_y = max(1, int(np.ceil(band / cell)))
    total = 2 * n_x * n_y
    if len(x) == 0:
        return 0.0
    left = (y < lo[1]) & (y >= lo[1] - band)
    right = (y > hi[1]) & (y <= hi[1] + band)
    beside = (np.abs(z) <= tol) & (x >= lo[0]) & (x <= hi[0]) & (left | right)
    if not beside.any():
        return 0.0
    cx = np.minimum(((x[beside] - lo[0]) / cell).astype(np.int64), n_x - 1)
    off = np.where(left[beside], lo[1] - y[beside], y[beside] - hi[1])
    cy = np.minimum((off / cell).astype(np.int64), n_y - 1)
    side = right[beside].astype(np.int64)
    cells = np.unique((side * n_x + cx) * n_y + cy)
    per_side = np.bincount(cells // (n_x * n_y), minlength=2) / (total / 2)
    # the plane must go on from the face's very edge: a neighbouring member
    # in the same plane (two stringers side by side) leaves a strip empty
    edge = cells[(cells % n_y) == 0]
    at_edge = np.bincount(edge // (n_x * n_y), minlength=2) / n_x
    # the better-covered side: a strip at the edge of the ground continues on one side only
    return float(np.minimum(per_side, at_edge).max())


def parallel_rows(
    tree: cKDTree,
    pts: np.ndarray,
    face: Face,
    band: float,
    tol: float,
    cell: float,
    own: np.ndarray | None = None,
    along: float = 0.6,
) -> float:
    """Fraction of the ``cell``-wide lanes parallel to ``face``, in a
    ``band`` beside it (the better side), whose plane points run along at
    least ``along`` of the face's length, bridging gaps of one cell.

    A coarse scan of the ground is rows: strips of points parallel to the
    candidate, a row spacing apart, with empty cells between them, so the
    cell coverage of :func:`plane_continuation` stays low while the plane
    goes on.  Lanes see the rows whole.  A parallel member of the same
    plane (the next girder, two metres away) fills one or two lanes of the
    band; members crossing the candidate cover a lane in pieces, which the
    one-cell bridge joins only when they stand about a metre apart or less
    (a truss's posts and diagonals: the pipeline looks again without the
    crossing steel).  Points flagged in ``own`` are not counted.  The
    KD-tree lookups cover the band in steps of ``band``, so the work is
    bounded by its area."""
    lo, hi = face.boundary.min(axis=0), face.boundary.max(axis=0)
    length = float(hi[0] - lo[0])
    if length <= 0 or hi[1] <= lo[1] or band <= 0:
        return 0.0
    mid = 0.5 * (lo[1] + hi[1])
    xs = np.append(np.arange(lo[0], hi[0], band), hi[0])
    centres = face.to_world(np.column_stack([xs, np.full(len(xs), mid)]))
    reach = float(np.hypot(band, 0.5 * (hi[1] - lo[1]) + band)) + tol
    x, y, z = _near(tree, pts, face, centres, reach, own)
    if len(x) == 0:
        return 0.0
    n_x = max(1, int(np.ceil(length / cell)))
    n_y = max(1, int(np.ceil(band / cell)))
    best = 0.0
    for off in (lo[1] - y, y - hi[1]):
        keep = (np.abs(z) <= tol) & (x >= lo[0]) & (x <= hi[0]) & (off > 0) & (off <= band)
        if not keep.any():
            continue
        cx = np.minimum(((x[keep] - lo[0]) / cell).astype(np.int64), n_x - 1)
        cy = np.minimum((off[keep] / cell).astype(np.int64), n_y - 1)
        covered = np.zeros((n_y, n_x), bool)
        covered[cy, cx] = True
        # a row's points can miss one cell (noise, a pole's shadow)
        if n_x > 2:
            covered[:, 1:-1] |= covered[:, :-2] & covered[:, 2:]
        best = max(best, float((_longest_runs(covered) >= along * n_x).mean()))
    return best


def _longest_runs(covered: np.ndarray) -> np.ndarray:
    """Per row of a boolean grid, the length of its longest run of ``True``."""
    edges = np.diff(np.pad(covered.astype(np.int8), ((0, 0), (1, 1))), axis=1)
    rows_s, starts = np.nonzero(edges == 1)
    _, ends = np.nonzero(edges == -1)
    out = np.zeros(len(covered), dtype=np.int64)
    # starts and ends pair up row by row in the same (row-major) order
    np.maximum.at(out, rows_s, ends - starts)
    return out
