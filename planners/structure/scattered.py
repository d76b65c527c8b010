"""Scattered lines: a deep member seen as points strewn over its whole section.

At a coarse spacing, a deep girder seen past others (a grillage's inner
main girder, an IPE 500 behind the outer one at 10 cm) comes out as a few
dozen points scattered over its 0.2 × 0.5 m section along 15–19 m: no
voxel neighbourhood looks linear (each is 8–20° off the girder), no row of
single points lies on a line, so neither the line features nor the sparse
rows see it.  What does show it is a tube: the points within a section's
radius of one line, all along it, with next to nothing beside the tube.

This is a RANSAC line search (Fischler & Bolles 1981) over the points
still unlabelled, run only where the scan is too coarse to resolve such a
section (its radius is at most ``SCATTER_MAX_SPACINGS`` spacings):

* a hypothesis is the line through a free point and a free point 2–6 m
  from it; hypotheses are scored in batches (bounded arrays) by the free
  points within the tube radius of their line, and beside it, within
  ``PAIR_MAX_M`` of the first point;
* those with the fewest free points beside the tube for those in it are
  refitted first (principal axis of their inliers, ``REFINE_ROUNDS``
  rounds) and kept when the inliers along the longest stretch with no
  gap over ``max_gap_m`` number ``SCATTER_MIN_POINTS`` or more over
  ``SCATTER_MIN_LENGTH_M`` or more, and the free points in the ring
  between one and ``SCATTER_RING_RADII`` tube radii are at most
  ``SCATTER_RING_MAX`` of them (a strip of ground has more beside the
  tube than in it);
* it is not a member already found (no member within ``DUPLICATE_DEG``
  passes within its radius plus the tube's of the stretch's middle), and
  at least ``SCATTER_MIN_CROSSINGS`` other members cross it within the
  tube radius plus the joints' reach: a girder carries cross girders, a
  line of ground carries nothing.

The search's arrays are bounded by the seed pool (at most
:data:`.bridges.BRIDGE_SEED_POINTS` points) times the batch size.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from planners.structure.bridges import CROSSING_DEG, along_member, seed_points
from planners.structure.joints import closest_points
from planners.structure.lines import fit_line
from planners.structure.model import Member

#: the tube's radius, as a share of the largest section expected
#: (``max_section_m``): 0.3 m by default, about an IPE 500's
#: half-diagonal (0.27 m)
SCATTER_RADIUS_SECTIONS = 0.25
#: only where the tube's radius is at most this many spacings: a finer
#: scan resolves such a section, and its line features find it
SCATTER_MAX_SPACINGS = 4.0
#: inliers a line needs, and its shortest stretch (m)
SCATTER_MIN_POINTS = 25
SCATTER_MIN_LENGTH_M = 4.0
#: free points in the ring between one and ``SCATTER_RING_RADII`` tube
#: radii, at most this share of the inliers: a girder has nothing free
#: beside it (grillage seed 14 at 10 cm: 16 of 78, all within two radii), a
#: strip of sparse ground 1.5–3 times as many as in the tube
SCATTER_RING_RADII = 4.0
SCATTER_RING_MAX = 0.35
#: members crossing the line it needs
SCATTER_MIN_CROSSINGS = 2
#: a hypothesis' second point lies this far (m) from its first
PAIR_MIN_M = 2.0
PAIR_MAX_M = 6.0
#: hypotheses per round, scored this many at a time; rounds at most
SCATTER_ATTEMPTS = 3000
SCATTER_BATCH = 32
SCATTER_MAX_LINES = 6
#: hypotheses refitted per round (the best scored)
SCATTER_REFITS = 32
#: principal-axis refits of a hypothesis to its inliers
REFINE_ROUNDS = 3


@dataclass
class ScatteredLine:
    """A line of scattered points taken as a member: ``axis`` (2, 3) over
    its stretch, ``points`` the indices of its inliers, ``crossings`` the
    members crossing it."""

    axis: np.ndarray
    points: np.ndarray
    crossings: tuple[int, ...]
    radius: float


def tube_radius(max_section: float) -> float:
    """The tube radius (m) for the largest section expected."""
    return SCATTER_RADIUS_SECTIONS * max_section


def coarse_scan(spacing: float, max_section: float) -> bool:
    """Whether the scan is too coarse to resolve the largest section expected
    (its tube radius at most ``SCATTER_MAX_SPACINGS`` spacings)."""
    return tube_radius(max_section) <= SCATTER_MAX_SPACINGS * spacing


def _stretch(t: np.ndarray, max_gap: float) -> tuple[float, float, int]:
    """The longest run of sorted parameters ``t`` with no gap over ``max_gap``:
    its ends and how many it holds."""
    ts = np.sort(t)
    breaks = np.flatnonzero(np.diff(ts) > max_gap)
    starts = np.concatenate([[0], breaks + 1])
    ends = np.concatenate([breaks, [len(ts) - 1]])
    k = int(np.argmax(ts[ends] - ts[starts]))
    return float(ts[starts[k]]), float(ts[ends[k]]), int(ends[k] - starts[k] + 1)


def _crossing_members(
    a: np.ndarray,
    b: np.ndarray,
    d: np.ndarray,
    members: list[Member],
    reach: float,
) -> tuple[int, ...]:
    """The members crossing segment ``ab`` (direction ``d``) at
    ``CROSSING_DEG`` or more within ``reach`` of it."""
    cos_cross = float(np.cos(np.radians(CROSSING_DEG)))
    out = []
    for m in members:
        if abs(float(m.direction @ d)) > cos_cross:
            continue
        p, q, _, _ = closest_points(a, b, m.axis[0], m.axis[1])
        if float(np.linalg.norm(p - q)) <= reach:
            out.append(m.id)
    return tuple(out)


def _score(
    pool: np.ndarray, origins: np.ndarray, dirs: np.ndarray, radius: float
) -> tuple[np.ndarray, np.ndarray]:
    """Points of ``pool`` within ``radius`` of each line (``origins``, unit
    ``dirs``) and ``PAIR_MAX_M`` of its origin, and those in the ring
    between one and ``SCATTER_RING_RADII`` radii: one (batch, pool) array."""
    rel = pool[None, :, :] - origins[:, None, :]
    along = np.einsum("bnk,bk->bn", rel, dirs)
    perp2 = np.einsum("bnk,bnk->bn", rel, rel) - along**2
    # within the pair's reach of the first point: far along, a hypothesis
    # a few degrees off has left its member
    perp2 = np.where(np.abs(along) <= PAIR_MAX_M, perp2, np.inf)
    inside = (perp2 <= radius * radius).sum(axis=1)
    ring = (perp2 <= (SCATTER_RING_RADII * radius) ** 2).sum(axis=1) - inside
    return inside, ring


def scattered_lines(
    points: np.ndarray,
    free: np.ndarray,
    members: list[Member],
    radii: np.ndarray,
    spacing: float,
    max_section: float,
    max_gap: float,
    joint_reach: float,
    seed: int = 0,
) -> list[ScatteredLine]:
    """The lines of scattered ``free`` points (mask over ``points``) that
    are members, found as the module says; a point goes to one line at
    most.  Nothing where the scan resolves a section of ``max_section``
    (the tube is wider than ``SCATTER_MAX_SPACINGS`` spacings)."""
    radius = tube_radius(max_section)
    if not coarse_scan(spacing, max_section) or len(members) < SCATTER_MIN_CROSSINGS:
        return []
    pool_idx = np.flatnonzero(seed_points(points, free, spacing))
    if len(pool_idx) < SCATTER_MIN_POINTS:
        return []
    pool = points[pool_idx]
    tree = cKDTree(pool)
    rng = np.random.default_rng(seed)
    taken = np.zeros(len(pool), bool)
    found: list[ScatteredLine] = []
    for _ in range(SCATTER_MAX_LINES):
        avail = np.flatnonzero(~taken)
        if len(avail) < SCATTER_MIN_POINTS:
            break
        sub = pool[avail]
        firsts = rng.choice(avail, SCATTER_ATTEMPTS)
        hyps = []
        for i in firsts:
            near = tree.query_ball_point(pool[i], PAIR_MAX_M)
            near = [j for j in near if not taken[j]]
            if not near:
                continue
            j = near[int(rng.integers(len(near)))]
            step = pool[j] - pool[i]
            n = float(np.linalg.norm(step))
            if n >= PAIR_MIN_M:
                hyps.append((pool[i], step / n))
        if not hyps:
            break
        origins = np.array([h[0] for h in hyps])
        dirs = np.array([h[1] for h in hyps])
        scored = [
            _score(sub, origins[k : k + SCATTER_BATCH], dirs[k : k + SCATTER_BATCH], radius)
            for k in range(0, len(hyps), SCATTER_BATCH)
        ]
        inside = np.concatenate([x[0] for x in scored])
        ring = np.concatenate([x[1] for x in scored])
        # a hypothesis is scored within its window, the refit looks along the
        # whole line; the clearest tubes first (ground fills the ring)
        ok = np.flatnonzero(inside >= SCATTER_MIN_POINTS // 2)
        order = ok[np.argsort(ring[ok] / inside[ok], kind="stable")][:SCATTER_REFITS]
        best: ScatteredLine | None = None
        best_local: np.ndarray | None = None
        for k in order:
            got = _refine(sub, origins[k], dirs[k], radius, max_gap)
            if got is None:
                continue
            local, a, b = got
            d = (b - a) / float(np.linalg.norm(b - a))
            if along_member(0.5 * (a + b), d, members, radii, radius):
                continue
            crossing = _crossing_members(a, b, d, members, radius + joint_reach)
            if len(crossing) < SCATTER_MIN_CROSSINGS:
                continue
            if best is None or len(local) > len(best.points):
                best = ScatteredLine(np.array([a, b]), pool_idx[avail[local]], crossing, radius)
                best_local = local
        if best is None or best_local is None:
            break
        taken[avail[best_local]] = True
        found.append(best)
    return found


def _refine(
    sub: np.ndarray, origin: np.ndarray, d: np.ndarray, radius: float, max_gap: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The hypothesis refitted to its inliers and cut to its longest
    stretch: the inliers' indices into ``sub`` and the stretch's ends, or
    ``None`` when it falls short of the module's tests."""
    rel = sub - origin
    along = rel @ d
    perp2 = np.einsum("nk,nk->n", rel, rel) - along**2
    inside = (perp2 <= radius * radius) & (np.abs(along) <= PAIR_MAX_M)
    for _ in range(REFINE_ROUNDS):
        if int(inside.sum()) < 3:
            return None
        c, d2, _, _, _ = fit_line(sub[inside])
        rel = sub - c
        along = rel @ d2
        perp = np.sqrt(np.maximum(np.einsum("nk,nk->n", rel, rel) - along**2, 0.0))
        inside = perp <= radius
    t0, t1, n = _stretch(along[inside], max_gap)
    if n < SCATTER_MIN_POINTS or t1 - t0 < SCATTER_MIN_LENGTH_M:
        return None
    within = (along >= t0) & (along <= t1)
    ring = int(((perp > radius) & (perp <= SCATTER_RING_RADII * radius) & within).sum())
    if ring > SCATTER_RING_MAX * n:
        return None
    local = np.flatnonzero(inside & within)
    return local, c + t0 * d2, c + t1 * d2
