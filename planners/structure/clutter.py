"""Clutter test: is a member candidate part of a larger surface?

A member's faces end at the member's edges; a strip of ground, a slab or a
wall that happens to look linear at some scale is a face whose plane goes
on beyond it.  For the candidate's largest face, the points within the
plane tolerance in two bands beside the face (each ``band`` wide, over the
face's length) are counted; when their density is a sizeable fraction of
the face's own, the candidate is a piece of a larger plane, not a member.
Point lookups go through a KD-tree over sampled band centres, so the work
is bounded by the band area, not by the cloud.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from planners.structure.model import Face


def plane_continuation(
    tree: cKDTree, pts: np.ndarray, face: Face, band: float, tol: float
) -> float:
    """Density of points in the face's plane beside it, relative to the
    density on the face (0: the plane ends with the face)."""
    lo, hi = face.boundary.min(axis=0), face.boundary.max(axis=0)
    length = float(hi[0] - lo[0])
    width = float(hi[1] - lo[1])
    if length <= 0 or width <= 0 or face.n_points == 0:
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
    found = tree.query_ball_point(centres, reach)
    idx = (
        np.unique(np.concatenate([np.asarray(f, dtype=np.int64) for f in found]))
        if len(found)
        else np.zeros(0, np.int64)
    )
    if len(idx) == 0:
        return 0.0
    rel = pts[idx] - face.origin
    x = rel @ face.x_axis
    y = rel @ face.y_axis
    z = rel @ face.normal
    beside = (
        (np.abs(z) <= tol)
        & (x >= lo[0])
        & (x <= hi[0])
        & (((y < lo[1]) & (y >= lo[1] - band)) | ((y > hi[1]) & (y <= hi[1] + band)))
    )
    density_beside = beside.sum() / (2 * band * length)
    density_face = face.n_points / (length * width)
    return float(density_beside / density_face)
