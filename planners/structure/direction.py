"""A member's direction as the one along which its points collapse most.

A steel member is a prism: seen along its true axis, every visible part of
its surface (a web here, a flange edge there) projects onto the section's
outline, a thin curve; seen along a direction tilted by θ, each part smears
over ``t·sin θ`` across the section.  A least-squares line instead follows
where the points are (the web seen at one end, the flange at the other),
which tilts a short, deep member by several degrees (a 2 m UPN 300 cross
girder at 2 cm: 6–12°).  This module searches a cone of directions around a
first estimate for the one whose projection occupies the fewest section
cells (cells of about two spacings: the outline's thickness under noise),
or, for a member of a few dozen points whose section is a cell or two
wide, the one whose projection has the smallest convex hull.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.spatial import ConvexHull, QhullError

#: most points projected per direction (a deterministic stride picks them)
MAX_POINTS = 2000
#: coarse rings (degrees off the first estimate) and azimuths per ring
RINGS_DEG = (2.0, 4.0, 6.0, 8.0, 10.0, 12.0)
AZIMUTHS = 12
#: then a pattern search round the best: first and last step (degrees)
FINE_START_DEG = 1.0
FINE_END_DEG = 0.25
FINE_AZIMUTHS = 8
#: a direction is taken only when it occupies at most this share of the
#: cells the first estimate does (ties and noise keep the first estimate)
MIN_GAIN = 0.9
#: the same for the hull search (any gain, 0.999: 10 cm recall +0.000…+0.004,
#: precision −0.014 (Pratt) … +0.019 (grillage): not taken)
HULL_MIN_GAIN = 0.9


def section_frames(dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(K, 3) unit u and v across each unit direction of ``dirs`` (K, 3), the
    frame :func:`planners.structure.faces.cross_section` uses."""
    near_z = np.abs(dirs[:, 2]) >= 0.9
    ref = np.where(near_z[:, None], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0])
    u = np.cross(dirs, ref)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    return u, np.cross(dirs, u)


#: a bitmap marks the cells when the columns' cell ranges hold at most this
#: many cells a point (its zeroing then costs less than a sort), else a sort
BITMAP_CELLS_PER_POINT = 8


def _distinct_cells(i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """(K,) distinct ``(i, j)`` pairs in each column of two (n, K) integer arrays."""
    i = i - i.min(axis=0)
    j = j - j.min(axis=0)
    span = j.max(axis=0) + 1
    size = (i.max(axis=0) + 1) * span
    keys = i * span + j
    total = int(size.sum())
    if total <= BITMAP_CELLS_PER_POINT * keys.size:
        start = np.concatenate([[0], np.cumsum(size)[:-1]])
        mark = np.zeros(total, bool)
        mark[keys + start] = True
        return np.add.reduceat(mark, start, dtype=np.int64)
    keys = np.sort(keys.T, axis=1)
    return 1 + (np.diff(keys, axis=1) != 0).sum(axis=1)


def _cells(
    rel: np.ndarray, dirs: np.ndarray, cell: float, offsets: tuple[float, ...]
) -> np.ndarray:
    """(K,) section cells occupied, summed over grids shifted by ``offsets``
    cells; each direction's projection is computed once for all grids."""
    out = np.zeros(len(dirs), dtype=np.int64)
    for k0 in range(0, len(dirs), 32):  # (MAX_POINTS, 32) keys at a time
        u, v = section_frames(dirs[k0 : k0 + 32])
        pu = rel @ u.T / cell
        pv = rel @ v.T / cell
        for offset in offsets:
            i = np.floor(pu + offset).astype(np.int64)
            j = np.floor(pv + offset).astype(np.int64)
            out[k0 : k0 + u.shape[0]] += _distinct_cells(i, j)
    return out


def occupied_cells(
    rel: np.ndarray, dirs: np.ndarray, cell: float, offset: float = 0.0
) -> np.ndarray:
    """(K,) section cells of size ``cell`` that ``rel`` (points minus a
    centre, at most ``MAX_POINTS``) occupies seen along each of ``dirs`` (K, 3);
    the grid shifted by ``offset`` cells."""
    return _cells(rel, dirs, cell, (offset,))


def _score(rel: np.ndarray, dirs: np.ndarray, cell: float) -> np.ndarray:
    """Cells occupied on two grids half a cell apart: less quantisation noise than one."""
    return _cells(rel, dirs, cell, (0.0, 0.5))


def _cone(d: np.ndarray, rings: tuple[float, ...], azimuths: int) -> np.ndarray:
    (u,), (v,) = section_frames(d[None])
    out = []
    for r in rings:
        a = np.radians(r)
        phi = np.linspace(0.0, 2 * np.pi, azimuths, endpoint=False)
        side = np.outer(np.cos(phi), u) + np.outer(np.sin(phi), v)
        out.append(np.cos(a) * d + np.sin(a) * side)
    return np.vstack(out)


def compact_direction(points: np.ndarray, d: np.ndarray, cell: float) -> np.ndarray:
    """Unit direction within ``RINGS_DEG[-1]`` of ``d`` along which ``points``
    occupy the fewest section cells of size ``cell``; ``d`` itself unless
    another direction needs at most ``MIN_GAIN`` of its cells."""
    d = d / np.linalg.norm(d)
    if len(points) < 3 or cell <= 0:
        return d
    rel = _centred_sample(points)
    return _cone_search(d, lambda dirs: _score(rel, dirs, cell).astype(float), MIN_GAIN)


def _centred_sample(points: np.ndarray) -> np.ndarray:
    """At most ``MAX_POINTS`` of ``points`` (a deterministic stride), minus their mean."""
    stride = -(-len(points) // MAX_POINTS)
    sample = points[::stride]
    return sample - sample.mean(axis=0)


def _cone_search(
    d: np.ndarray, score: Callable[[np.ndarray], np.ndarray], min_gain: float
) -> np.ndarray:
    """The direction within ``RINGS_DEG[-1]`` of unit ``d`` with the lowest
    ``score`` ((K, 3) directions → (K,) values): the coarse rings, then a
    pattern search round the best (move while a neighbour is better, else
    halve the step); ``d`` itself unless the best scores at most
    ``min_gain`` of ``d``'s.  The sense of ``d`` is kept."""
    first = float(score(d[None])[0])
    coarse = _cone(d, RINGS_DEG, AZIMUTHS)
    values = score(coarse)
    k = int(np.argmin(values))
    best_d, best = d, first
    if values[k] < best:
        best_d, best = coarse[k], float(values[k])
        step = FINE_START_DEG
        while step >= FINE_END_DEG:
            near = _cone(best_d, (step,), FINE_AZIMUTHS)
            values = score(near)
            k = int(np.argmin(values))
            if values[k] < best:
                best_d, best = near[k] / np.linalg.norm(near[k]), float(values[k])
            else:
                step /= 2
    if best > min_gain * first:
        return d
    best_d = best_d / np.linalg.norm(best_d)
    return best_d if float(best_d @ d) >= 0 else -best_d


def _hull_areas(rel: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """(K,) area of the convex hull of ``rel`` projected along each of ``dirs``."""
    u, v = section_frames(dirs)
    out = np.empty(len(dirs))
    for k in range(len(dirs)):
        q = np.column_stack([rel @ u[k], rel @ v[k]])
        try:
            out[k] = ConvexHull(q).volume  # a 2-D hull's "volume" is its area
        except QhullError:  # all on a line: no area
            out[k] = 0.0
    return out


def hull_direction(points: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Unit direction within ``RINGS_DEG[-1]`` of ``d`` along which the convex
    hull of ``points`` projected across it is smallest; ``d`` itself unless
    another direction's hull is at most ``HULL_MIN_GAIN`` of its area.

    For a member of a few dozen points (a 10 cm scan), section cells of two
    spacings are as wide as the section and cannot tell a tilt, but the
    hull can: seen along the axis each visible part of the surface
    collapses onto the outline, tilted it smears across by ``t·sin θ``.
    A least-squares line follows where the points are (a post's web seen
    at one end, its flange at the other: 6.5° off over 200 such 30-point
    members, the hull 3.1°).  Points in one plane (a web alone) project to
    a segment along any direction in that plane, so a tilt within it is
    not seen; nothing is lost there, the first estimate is kept."""
    d = d / np.linalg.norm(d)
    if len(points) < 4:
        return d
    rel = _centred_sample(points)
    return _cone_search(d, lambda dirs: _hull_areas(rel, dirs), HULL_MIN_GAIN)
