"""Collinear chains: one member seen as pieces across long occlusion shadows.

A main girder of a deck grillage seen from scanners beside the deck comes
out of a coarse scan as two or three pieces with metres of nothing between
them: the deck and the girders nearer the scanners hide the rest.  The
refit rounds join collinear pieces only across a stretch that holds steel
(:func:`.assign.gap_filled`), so these stay apart, each too short to find
the girder.

Pieces of one member lie on one line; two members side by side do not.  So
the test is one line fitted through all the pieces' points (PCA,
:func:`.lines.fit_line`), not one piece's line carried on to the other (a
piece of a few dozen points seen on one flange leans by a degree or two,
which over a 5 m shadow misses the other piece by more than a section).  A
chain is the consensus of a RANSAC line (Fischler & Bolles 1981) whose
inliers are whole pieces: every piece's axis ends lie within
``CHAIN_END_RADII`` of its section radius of the chain's line, and its
points' median distance to that line within ``CHAIN_MEDIAN_RADII`` radii.

The axis a chain is given is the line through its pieces' own axes
(:func:`through_pieces`), which sit at their sections' centres, not
through the points, which lean to the side a coarse scan saw.

Chains grow by agglomeration: each chain tries the others within
``merge_angle_deg`` whose ends lie at most ``CHAIN_GAP_GAPS`` ×
``max_gap_m`` (and at most both chains' lengths together) past its own,
nearest first, and takes the first that fits one line with it; a chain's
line and length, not its first piece's, decide what it reaches next.  A
member that passes through a gap between the pieces, crossing it at
``CROSSING_DEG`` or more with its own steel on both sides, stops the
chain: two beams in line meet a column between them, while the cross
girders framing into an occluded main girder stop at it.

Bounded: each test is one vectorised pass over the chains alive (M at a
time, not M²), each fit reads the points of the pieces tried.
"""

from __future__ import annotations

import numpy as np

from planners.structure.indices import points_by_label
from planners.structure.joints import closest_points
from planners.structure.lines import fit_line, line_coords
from planners.structure.model import Member

#: pieces at most this many ``max_gap_m`` apart are chained
CHAIN_GAP_GAPS = 3.0
#: pieces overlapping by more than this many section radii are side by side
#: (faces of one member, which the refit rounds join), not a chain
CHAIN_OVERLAP_RADII = 2.0
#: a piece's axis ends lie within this many of its section radii of the chain's line
CHAIN_END_RADII = 1.0
#: and its points' median distance to the line within this many
CHAIN_MEDIAN_RADII = 0.75
#: a member crossing a gap at this angle or more, with steel on both sides, stops a chain
CROSSING_DEG = 20.0


def collinear_chains(
    points: np.ndarray,
    labels: np.ndarray,
    members: list[Member],
    radii: np.ndarray,
    merge_angle_deg: float,
    max_gap_m: float,
) -> list[tuple[list[int], np.ndarray]]:
    """Chains of two or more members that are one member seen in pieces:
    the member indices of each (ascending) and its (2, 3) axis.
    ``labels`` (N,) gives each point's member index (−1: none), ``radii``
    each member's section radius."""
    n = len(members)
    if n < 2:
        return []
    # each member's points once (a sort), not one pass over the cloud a test
    own = [points[ix] for ix in points_by_label(labels, n)]
    groups: list[list[int]] = [[i] for i in range(n)]
    axes = [np.asarray(m.axis, float) for m in members]
    rad = [float(r) for r in radii]
    cos_max = float(np.cos(np.radians(merge_angle_deg)))
    tan_max = float(np.tan(np.radians(merge_angle_deg)))
    max_gap = CHAIN_GAP_GAPS * max_gap_m
    alive = list(range(n))
    # a pair of chains that fits no line is not tried again on later passes
    failed: set[tuple[tuple[int, ...], tuple[int, ...]]] = set()
    changed = True
    while changed:
        changed = False
        for i in list(alive):
            if i not in alive:
                continue
            rest = np.array([j for j in alive if j != i], dtype=np.int64)
            if len(rest) == 0:
                break
            a = np.array([axes[j] for j in rest])
            d_i = axes[i][1] - axes[i][0]
            len_i = float(np.linalg.norm(d_i))
            if len_i <= 0:
                continue
            d_i = d_i / len_i
            d_r = a[:, 1] - a[:, 0]
            len_r = np.linalg.norm(d_r, axis=1)
            ok = np.abs(d_r @ d_i) >= cos_max * np.maximum(len_r, 1e-12)
            # the others' ends in i's frame: along and across its line
            e = a - axes[i][0]
            along = e @ d_i
            across = np.linalg.norm(e - along[..., None] * d_i, axis=2).max(axis=1)
            gap = np.maximum(along.min(axis=1) - len_i, -along.max(axis=1))
            r = np.maximum(rad[i], np.array([rad[j] for j in rest]))
            ok &= gap >= -CHAIN_OVERLAP_RADII * r
            ok &= gap <= np.minimum(max_gap, len_i + len_r)
            # a rough pre-test (i's own line carried on leans): the chain's
            # line decides
            ok &= across <= 2.0 * r + tan_max * np.maximum(gap, 0.0)
            for k in np.flatnonzero(ok)[np.argsort(gap[ok], kind="stable")]:
                j = int(rest[k])
                key = (tuple(groups[i]), tuple(groups[j]))
                if key in failed:
                    continue
                group = groups[i] + groups[j]
                axis = chain_axis(group, [own[g] for g in group], members, radii)
                if axis is None:
                    failed.add(key)
                    continue
                groups[i], axes[i], rad[i] = group, axis, max(rad[i], rad[j])
                alive.remove(j)
                changed = True
                break
    return [
        (sorted(groups[i]), through_pieces(groups[i], [own[g] for g in groups[i]], members))
        for i in alive
        if len(groups[i]) > 1
    ]


def chain_axis(
    group: list[int],
    own: list[np.ndarray],
    members: list[Member],
    radii: np.ndarray,
) -> np.ndarray | None:
    """The (2, 3) axis of the chain ``group`` (member indices; ``own``
    their points) when all its pieces lie on one line and no member passes
    through a gap between them, else ``None``.  The axis runs along the
    line through all the pieces' points, from the outermost piece end to
    the other: the line the chain is grown along, not the one it is given
    (:func:`through_pieces`)."""
    if any(len(p) == 0 for p in own):
        return None
    c, d, _, _, _ = fit_line(np.vstack(own))
    spans = []
    for i, p in zip(group, own, strict=True):
        r = float(radii[i])
        if float(_off_line(members[i].axis, c, d).max()) > CHAIN_END_RADII * r:
            return None
        if float(np.median(_off_line(p, c, d))) > CHAIN_MEDIAN_RADII * r:
            return None
        spans.append((members[i].axis - c) @ d)
    if _crossed(group, spans, c, d, members, radii):
        return None
    return _spanned(c, d, spans)


def through_pieces(group: list[int], own: list[np.ndarray], members: list[Member]) -> np.ndarray:
    """The (2, 3) axis of a chain: the line through its points each moved
    onto its own piece's axis (PCA of those feet), from the outermost piece
    end to the other.

    A piece's axis is its section's box centre (the refit's), where the
    mean of its points is not: a coarse scan sees one side of a flange more
    than the other (grillage seed 11 at 10 cm: an HEB 400 main girder's
    points 0.12 m to one side of its web on average, the chain's line
    through them 0.24 m from its centroid, its tolerance).  The feet keep
    each piece's weight (its points) and its place along the line."""
    feet = []
    for g, p in zip(group, own, strict=True):
        start, along = members[g].axis[0], members[g].direction
        feet.append(start + np.outer(line_coords(p, start, along)[0], along))
    c, d, _, _, _ = fit_line(np.vstack(feet))
    return _spanned(c, d, [(members[g].axis - c) @ d for g in group])


def _spanned(c: np.ndarray, d: np.ndarray, spans: list[np.ndarray]) -> np.ndarray:
    """The (2, 3) segment of the line ``c + t·d`` from the least of the
    pieces' end parameters ``spans`` to the greatest."""
    t = np.concatenate(spans)
    return np.array([c + t.min() * d, c + t.max() * d])


def _off_line(q: np.ndarray, c: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Distances of the points ``q`` from the line ``c + t·d`` (``d`` a unit vector)."""
    return line_coords(q, c, d)[1]


def _crossed(
    group: list[int],
    spans: list[np.ndarray],
    c: np.ndarray,
    d: np.ndarray,
    members: list[Member],
    radii: np.ndarray,
) -> bool:
    """Whether a member outside ``group`` passes through a gap between its
    pieces (``spans``: each piece's end parameters on the line ``c +
    t·d``): it crosses at ``CROSSING_DEG`` or more, comes within both
    section radii of the gap, and its axis goes on past that point by as
    much on both sides."""
    gaps = []
    order = sorted((float(s.min()), float(s.max())) for s in spans)
    reach = order[0][1]
    for lo, hi in order[1:]:
        if lo > reach:
            gaps.append((reach, lo))
        reach = max(reach, hi)
    if not gaps:
        return False
    inside = set(group)
    r_chain = float(max(radii[i] for i in group))
    cos_cross = float(np.cos(np.radians(CROSSING_DEG)))
    for k, m in enumerate(members):
        if k in inside or abs(float(m.direction @ d)) >= cos_cross:
            continue
        margin = r_chain + float(radii[k])
        length = m.length_m
        for start, end in gaps:
            p, q, _, t = closest_points(c + start * d, c + end * d, m.axis[0], m.axis[1])
            if float(np.linalg.norm(p - q)) <= margin and margin < t * length < length - margin:
                return True
    return False
