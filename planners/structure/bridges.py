"""Bridging rows: members seen as a handful of points between two members.

A cross girder far from every scanner, or seen past a main girder, can come
out of a 10 cm scan as four to seven points along one flange: too few for a
line feature or a sparse row on its own (:mod:`.sparse` asks for
``SPARSE_MIN_POINTS``), where a random row of a handful of points in
clutter is common.  What tells the two apart is the structure round it:
the row's line, carried on past both of its ends, meets a member at each,
crossing it
— the way a cross girder spans between main girders, or a diagonal between
chords.  That is a line hypothesis (a RANSAC-style consensus, Fischler &
Bolles 1981) verified by the members already found rather than by its
own points alone.

The long reach and the short rows (coarse scans only), the points inside
the members met and the flanges' duplicate rule, together, 20 seeds at
10 cm: grillage visible recall 0.935 → 0.945, precision 0.954 → 0.954;
Warren 0.970 → 0.973 and Pratt 0.984 → 0.987, precision the same; frame
recall the same, precision 0.965 → 0.963 (one member more in 438).  At
2 cm and 5 mm every type's members are the same, seed by seed.

The rows come from the sparse-row walk (:func:`.sparse.walk_rows`) over
the points still unlabelled once the members are kept (the first walk ran
before the refits, joins and clutter tests freed or took points), rows of
``BRIDGE_MIN_FREE`` points or more and as long as the shortest member (on
a coarse scan, ``BRIDGE_ROW_LENGTHS`` of that: the member runs between its
supports, and that span is held to the shortest member's length).  A row
becomes a member when:

* it is not a piece of a member already found, nor of a bridge taken
  before it (the two flanges of one cross girder make two rows): no member
  within ``DUPLICATE_DEG`` of its direction passes within that member's
  section radius plus ``DUPLICATE_SPACINGS`` of the row's middle;
* its line, lengthened past each end by ``BRIDGE_REACH_LENGTHS`` of its own
  length (at least the joints' reach, and at least ``gap_reach``: the
  longest occlusion shadow the model bridges along a member, for a cross
  girder seen only by the half near one of its girders), comes within a
  member's section radius (at least the largest section's expected, a
  quarter of ``max_section_m``) plus one spacing of two different members, one
  beyond each end, each crossing it at ``CROSSING_DEG`` or more;
* it still holds ``BRIDGE_MIN_POINTS`` points no earlier bridge took (or
  ``BRIDGE_MIN_FREE``, with the rest on its line inside the two members
  it meets, between its ends and their axes), and its free points lie
  within an RMS distance of ``BRIDGE_MAX_RMS_SPACINGS`` of its line (a
  row on a flange lies at 0.1–0.25 spacings, a diagonal's scattered
  section up to 0.5; points strewn evenly over the walk's one-spacing tube
  at about 0.7).

The new member's axis runs along the row's line between the two crossings;
its points are the row's, its section is fitted in the sections stage (a
handful of points: ``unknown``).  Every query is bounded: one ball query
per row sample, rows × members closest-point tests with the rows capped by
the walk's ``BRIDGE_MAX_ATTEMPTS``, and for a row of ``BRIDGE_MIN_FREE``
the points of its two members (sorted by member once).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from planners.structure.assign import near_line
from planners.structure.indices import points_by_label
from planners.structure.joints import closest_points
from planners.structure.lines import LineCandidate, line_coords
from planners.structure.model import Member

#: points a bridging row needs at least: unlabelled ones, or as few as
#: ``BRIDGE_MIN_FREE`` with the rest on its line inside the two members it
#: meets (where it frames in, its points went to them).  20 seeds at 10 cm:
#: grillage visible recall 0.939 → 0.941 (a cross girder of four free
#: points and a fifth in its girder's envelope), precision and the other
#: types the same
BRIDGE_MIN_POINTS = 5
BRIDGE_MIN_FREE = 4
#: on a coarse scan (:func:`.scattered.coarse_scan`), a row is at least
#: this many of the shortest member's length long (elsewhere, that
#: length).  20 seeds at 10 cm, 1.0 → 0.5: grillage visible recall 0.941 → 0.945 (four
#: points over 0.58 m of a 2 m cross girder), precision the same
BRIDGE_ROW_LENGTHS = 0.5
#: seeds the walk over the points left free tries at most
BRIDGE_MAX_ATTEMPTS = 150
#: rows are seeded from at most ``BRIDGE_SEED_POINTS`` free points, those
#: in the cells (``BRIDGE_CELL_SPACINGS`` wide) holding the fewest free
#: points: a row of a handful of points is alone in its cells, while a
#: surface (ground, a slab) fills them; bounds the walk's scoring on a fine
#: scan (a 5 mm Warren leaves 375k points free, 1.4 s to score them all)
BRIDGE_CELL_SPACINGS = 10.0
BRIDGE_SEED_POINTS = 3000
#: the row's points lie within this RMS distance (spacings) of its line:
#: points strewn evenly over the walk's one-spacing tube lie at ~0.7
BRIDGE_MAX_RMS_SPACINGS = 0.5
#: the row's line is carried this many of its own lengths past each end
BRIDGE_REACH_LENGTHS = 1.0
#: a member it meets crosses it at this angle or more
CROSSING_DEG = 20.0
#: a row this close (degrees) to a member's direction and near its axis is a
#: piece of that member
DUPLICATE_DEG = 20.0
DUPLICATE_SPACINGS = 4.0


@dataclass
class Bridge:
    """A row accepted as a member: ``axis`` (2, 3) between the two members
    it meets (``ends``), ``points`` the indices of its points."""

    axis: np.ndarray
    points: np.ndarray
    ends: tuple[int, int]
    radius: float


def seed_points(points: np.ndarray, free: np.ndarray, spacing: float) -> np.ndarray:
    """Mask of the ``BRIDGE_SEED_POINTS`` ``free`` points in the emptiest
    cells of ``BRIDGE_CELL_SPACINGS`` spacings (ties by index: deterministic;
    one ``np.unique`` over the cell keys and one sort: n log n)."""
    out = np.zeros(len(points), bool)
    idx = np.flatnonzero(free)
    if len(idx) <= BRIDGE_SEED_POINTS:
        out[idx] = True
        return out
    ijk = np.floor((points[idx] - points[idx].min(axis=0)) / (BRIDGE_CELL_SPACINGS * spacing))
    _, inverse, counts = np.unique(
        ijk.astype(np.int64), axis=0, return_inverse=True, return_counts=True
    )
    emptiest = np.argsort(counts[inverse.reshape(-1)], kind="stable")[:BRIDGE_SEED_POINTS]
    out[idx[emptiest]] = True
    return out


def along_member(
    mid: np.ndarray, d: np.ndarray, members: list[Member], radii: np.ndarray, slack: float
) -> bool:
    """Whether a member within ``DUPLICATE_DEG`` of ``d`` passes within its
    radius plus ``slack`` of ``mid``: a line there is a piece of it."""
    cos_dup = float(np.cos(np.radians(DUPLICATE_DEG)))
    for m, r in zip(members, radii, strict=True):
        if abs(float(m.direction @ d)) < cos_dup:
            continue
        p, q, _, _ = closest_points(mid, mid, m.axis[0], m.axis[1])
        if float(np.linalg.norm(p - q)) <= r + slack:
            return True
    return False


def _supports(
    c: np.ndarray,
    d: np.ndarray,
    t0: float,
    t1: float,
    members: list[Member],
    radii: np.ndarray,
    spacing: float,
    reach: float,
    min_radius: float = 0.0,
) -> tuple[tuple[int, float] | None, tuple[int, float] | None]:
    """The nearest member crossing the line beyond each end of the row
    ``[t0, t1]`` (within ``reach``), passing within its section radius (at
    least ``min_radius``) plus a spacing: ``(member index, parameter)`` or
    ``None``."""
    cos_cross = float(np.cos(np.radians(CROSSING_DEG)))
    length = t1 - t0
    seg = (c + (t0 - reach) * d, c + (t1 + reach) * d)
    ends: list[tuple[int, float] | None] = [None, None]
    for j, m in enumerate(members):
        if abs(float(m.direction @ d)) > cos_cross:
            continue
        p, q, _, _ = closest_points(seg[0], seg[1], m.axis[0], m.axis[1])
        if float(np.linalg.norm(p - q)) > max(radii[j], min_radius) + spacing:
            continue
        t = float((p - c) @ d)
        # a crossing inside the row's last tenth still meets its end
        if t <= t0 + 0.1 * length:
            k, gap = 0, abs(t0 - t)
        elif t >= t1 - 0.1 * length:
            k, gap = 1, abs(t - t1)
        else:
            continue
        best = ends[k]
        if best is None or gap < abs(best[1] - (t0 if k == 0 else t1)):
            ends[k] = (j, t)
    return ends[0], ends[1]


def _framed_in(
    q: np.ndarray,
    c: np.ndarray,
    d: np.ndarray,
    before: tuple[float, float],
    after: tuple[float, float],
    spacing: float,
) -> int:
    """How many of the supports' points ``q`` lie within a spacing of the
    row's line ``c + t·d``, between a support's crossing and the row's end
    (``before``: [crossing, row start), ``after``: (row end, crossing])."""
    t, perp = line_coords(q, c, d)
    between = ((t >= before[0]) & (t < before[1])) | ((t > after[0]) & (t <= after[1]))
    return int(((perp <= spacing) & between).sum())


def bridging_rows(
    points: np.ndarray,
    free: np.ndarray,
    rows: list[LineCandidate],
    members: list[Member],
    radii: np.ndarray,
    spacing: float,
    min_length: float,
    joint_reach: float,
    min_radius: float = 0.0,
    gap_reach: float = 0.0,
    held: np.ndarray | None = None,
) -> list[Bridge]:
    """The ``rows`` that span between two of ``members`` (``radii``: their
    section radii, each taken as at least ``min_radius``) through at least
    ``BRIDGE_MIN_POINTS`` of the ``free`` points (mask over ``points``),
    each as a :class:`Bridge`.  A point goes to one bridge at most.

    ``min_radius``: a girder seen by one flange at a coarse spacing
    measures that flange's radius (0.16 m for an HEB 400 whose cross
    girders frame in 0.37 m from the flange's line); the model passes the
    largest section's radius it expects.

    ``gap_reach``: how far past its ends a row's line is carried at least
    (the model passes ``max_gap_m`` on a coarse scan, else 0).  A UPN 300
    cross girder of grillage seed 0 at 10 cm is seen as a 0.7 m row by its
    near girder, its far girder 1.95 m beyond; carried by its own length
    only it met one.  20 seeds at 10 cm: grillage visible recall 0.935 →
    0.939, precision the same once a row along a bridge taken is a piece of
    it (without that, 0.954 → 0.950: both flanges of one cross girder were
    bridged).

    ``held`` (N,): each point's member index (−1: none).  Given, a row of
    ``BRIDGE_MIN_FREE`` free points is taken when the points of the two
    members it meets that lie on its line, between its ends and theirs,
    make up the rest; without it, every point must be free."""
    least = BRIDGE_MIN_POINTS if held is None else min(BRIDGE_MIN_FREE, BRIDGE_MIN_POINTS)
    if len(members) < 2 or not rows or int(free.sum()) < least:
        return []
    by_member: list[np.ndarray] | None = None  # the members' points, sorted once when asked
    idx = np.flatnonzero(free)
    sub = points[idx]
    tree: cKDTree | None = None  # built for the first row that meets two members
    taken = np.zeros(len(idx), bool)
    out: list[Bridge] = []
    # a row along a bridge taken before it is a piece of that bridge too:
    # the two flanges of one cross girder make two rows
    known, known_radii = list(members), list(radii)
    for row in rows:
        c, d, t0, t1 = row.centre, row.direction, row.t0, row.t1
        mid = c + 0.5 * (t0 + t1) * d
        if along_member(mid, d, known, np.asarray(known_radii), DUPLICATE_SPACINGS * spacing):
            continue
        reach = max(BRIDGE_REACH_LENGTHS * (t1 - t0), joint_reach, gap_reach)
        start, end = _supports(c, d, t0, t1, members, radii, spacing, reach, min_radius)
        if start is None or end is None or start[0] == end[0]:
            continue
        if end[1] - start[1] < min_length:
            continue
        if tree is None:
            tree = cKDTree(sub)
        near, t, perp = near_line(sub, tree, c, d, t0, t1, 0.5 * spacing)
        on = (perp <= spacing) & (t >= t0) & (t <= t1) & ~taken[near]
        mine = near[on]
        if len(mine) < least:
            continue
        if len(mine) < BRIDGE_MIN_POINTS and held is not None:
            if by_member is None:
                by_member = points_by_label(held, len(members))
            inside = np.concatenate([by_member[start[0]], by_member[end[0]]])
            framed = _framed_in(points[inside], c, d, (start[1], t0), (t1, end[1]), spacing)
            if len(mine) + framed < BRIDGE_MIN_POINTS:
                continue
        if float(np.sqrt(np.mean(perp[on] ** 2))) > BRIDGE_MAX_RMS_SPACINGS * spacing:
            continue
        taken[mine] = True
        axis = np.array([c + start[1] * d, c + end[1] * d])
        out.append(Bridge(axis, idx[mine], (start[0], end[0]), max(row.radius, spacing)))
        known.append(Member(-1, axis, "unknown", 0.0, 0.0))
        known_radii.append(out[-1].radius)
    return out
