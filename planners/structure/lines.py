"""Member lines from line features: region growing, line fit, fragment joining.

Linear voxels whose principal directions agree are linked to their touching
neighbours (region growing on the voxel adjacency); each connected region
is one member candidate and gets a least-squares 3D line (PCA of its voxel
centroids, unweighted so that range-dependent density does not bias it).
Candidates that are collinear and separated by an occlusion gap, or
parallel and overlapping within one section depth (the two flanges of a
girder), are then joined by union-find, nearest pairs first and never into
a group deeper than one section (pairwise joins would otherwise chain a
truss's chords and the edges between them into one member).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from planners.structure.features import QUERY_WORKERS, LineFeatures
from planners.structure.indices import hit_union, sorted_unique

#: linear voxels each voxel may link to (its nearest ones)
LINK_K = 8
#: a link may also reach this many times the step between a voxel's
#: neighbours along its line (:func:`_row_step`): a member far from every
#: scanner is a sparse row (a cross girder seen in a 2 cm scan as 31 points
#: over 2.7 m, 9 cm apart; a diagonal in a 10 cm scan as one point every
#: 10–30 cm, one or two across), each voxel beyond the plain cap from the
#: next, and every voxel was a region of its own.  Such a long link is kept
#: only along the voxel's own line (``LINK_ROW_ALIGN_DEG``) and within
#: ``ROW_REACH_SPACINGS`` scan spacings.  20 seeds, visible recall /
#: precision, 1.2 in any direction (the earlier setting) → 8 along the
#: line: 10 cm Warren 0.831 / 0.895 → 0.925 / 0.929, Pratt 0.822 / 0.927 →
#: 0.899 / 0.931, frame 0.960 / 0.946 → 0.982 / 0.921, grillage 0.683 /
#: 0.829 → 0.802 / 0.821; every 2 cm row still met, 5 mm Pratt 0.981 /
#: 0.992 → 0.971 / 0.987 and the other 5 mm rows unchanged
#: (docs/inspection.md).  In any direction, factors above 2 linked the
#: ground's scan rows and neighbouring members sideways (2.5: five seeds
#: the tests pin broke); 0: off
LINK_ROW = 8.0
#: a link longer than the plain cap runs within this angle of the voxel's
#: own direction: a sparse row continues along itself, while the ground's
#: scan rows, a parallel member or a crossing one lie beside it.  At 6° a
#: person-sized box under a 2 cm grillage's girder end became a member
#: (seed 1), at 10° 10 cm grillage precision fell to 0.770; 4° keeps both
LINK_ROW_ALIGN_DEG = 4.0
#: the row link's reach in scan spacings at most (1.2 m at 10 cm, 0.24 m at
#: 2 cm, 6 cm at 5 mm): two collinear members 0.5 m apart in a fine scan
#: stay two regions (the fragment join decides later whether they are one
#: member).  16 spacings found no more at 10 cm and changed the chaotic
#: Pratt 5 mm seed 8 (recall 0.963 over 20 seeds); 8 broke a sparse 2 cm
#: row (12 cm steps, noise) into pieces
ROW_REACH_SPACINGS = 12.0


def _row_step(centres: np.ndarray, direction: np.ndarray, nb: np.ndarray) -> np.ndarray:
    """(m,) median step between successive neighbours along each voxel's line.

    ``centres`` (m, 3), ``direction`` (m, 3) unit, ``nb`` (m, k) the k nearest
    (the voxel itself first; ``m`` where fewer exist).  ``2r / (n − 1)``, the
    neighbourhood's spacing, assumes it full on both sides; at the end of a
    row it is one-sided and twice the step, which let a row's last voxel
    link across an occlusion gap.  The neighbours projected on the voxel's
    direction and sorted give the step wherever the voxel is; ``inf`` where
    all neighbours project to one place."""
    m = len(nb)
    inside = nb < m
    rel = centres[np.where(inside, nb, 0)] - centres[:, None, :]
    t = np.where(inside, np.einsum("ijk,ik->ij", rel, direction), np.nan)
    steps = np.diff(np.sort(t, axis=1), axis=1)
    steps = np.where(steps > 0, steps, np.nan)  # NaN sorts last: no step past it
    ok = np.isfinite(steps).any(axis=1)
    out = np.full(m, np.inf)
    out[ok] = np.nanmedian(steps[ok], axis=1)
    return out


@dataclass
class LineCandidate:
    """A member candidate: voxels ``voxels`` of the finest grid, the line
    through ``centre`` along unit ``direction`` from parameter ``t0`` to ``t1``,
    and ``radius`` the 95th percentile distance of its voxels from the line."""

    voxels: np.ndarray
    centre: np.ndarray
    direction: np.ndarray
    t0: float
    t1: float
    radius: float
    fragments: int = 1

    @property
    def length(self) -> float:
        return self.t1 - self.t0

    @property
    def ends(self) -> np.ndarray:
        return self.centre + np.outer([self.t0, self.t1], self.direction)


def line_coords(q: np.ndarray, c: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Of the points ``q`` on the line ``c + t·d`` (``d`` a unit vector):
    each one's parameter ``t`` and distance from the line."""
    w = q - c
    t = w @ d
    return t, np.linalg.norm(w - np.outer(t, d), axis=1)


def fit_line(
    pts: np.ndarray, lo_pct: float = 1.0, hi_pct: float = 99.0
) -> tuple[np.ndarray, np.ndarray, float, float, float]:
    """PCA line of ``pts``: centre, direction, trimmed extent and 95th-percentile radius."""
    c = pts.mean(axis=0)
    r = pts - c
    _, _, vt = np.linalg.svd(r, full_matrices=False)
    d = vt[0]
    # a sign convention makes results independent of the voxel order
    d = d if d[np.argmax(np.abs(d))] > 0 else -d
    t = r @ d
    perp = np.linalg.norm(r - np.outer(t, d), axis=1)
    t0, t1 = np.percentile(t, [lo_pct, hi_pct])
    return c, d, float(t0), float(t1), float(np.percentile(perp, 95))


def grow_regions(
    feat: LineFeatures,
    linearity_min: float,
    angle_deg: float,
    keep: np.ndarray,
    spacing: float,
) -> np.ndarray:
    """(V,) region id per finest voxel (−1: not on a line).  Voxels closer
    than 1.8 cells are neighbours; a link needs both ends linear and their
    directions within ``angle_deg``.  A sparse row's voxels also link along
    their line up to ``LINK_ROW`` steps, at most ``ROW_REACH_SPACINGS`` ×
    ``spacing`` (the scan's measured point spacing, m)."""
    grid = feat.grid
    lin = (feat.linearity >= linearity_min) & keep
    ids = np.flatnonzero(lin)
    out = np.full(len(grid.centres), -1, dtype=np.int64)
    if len(ids) == 0:
        return out
    # k nearest linear voxels, not a fixed radius: density falls with range
    # in a scan, and a far member's voxels do not touch; the cap (a quarter
    # of the voxel's scale) keeps links local
    sub = grid.centres[ids]
    kk = min(LINK_K + 1, len(ids))
    dist, nb = cKDTree(sub).query(sub, k=kk, workers=QUERY_WORKERS)
    dist = np.asarray(dist).reshape(len(ids), kk)
    nb = np.asarray(nb).reshape(len(ids), kk)
    base = np.maximum(0.25 * feat.radius[ids], 1.8 * grid.size)
    cap = base
    if LINK_ROW > 0:
        # a dense neighbourhood's step is below the plain cap: unchanged
        row = np.minimum(
            2.0 * feat.radius[ids] / np.maximum(feat.neighbours[ids] - 1, 1),
            _row_step(sub, feat.direction[ids], nb),
        )
        reach = np.minimum(LINK_ROW * row, ROW_REACH_SPACINGS * spacing)
        cap = np.maximum(cap, reach)
    rows = np.repeat(np.arange(len(ids)), kk)
    cols = nb.ravel()
    ok = (cols != rows) & (cols < len(ids)) & (dist.ravel() <= np.repeat(cap, kk))
    far = np.flatnonzero(ok & (dist.ravel() > np.repeat(base, kk)))
    if len(far):
        v = sub[cols[far]] - sub[rows[far]]
        along = np.abs(np.einsum("ij,ij->i", v, feat.direction[ids][rows[far]]))
        ok[far] = along >= np.cos(np.radians(LINK_ROW_ALIGN_DEG)) * np.linalg.norm(v, axis=1)
    pairs = np.column_stack([rows[ok], cols[ok]])
    if len(pairs):
        d = feat.direction[ids]
        cos = np.abs(np.einsum("ij,ij->i", d[pairs[:, 0]], d[pairs[:, 1]]))
        pairs = pairs[cos >= np.cos(np.radians(angle_deg))]
    m = len(ids)
    adj = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(m, m))
    _, comp = connected_components(adj, directed=False)
    out[ids] = comp
    return out


def region_lines(
    feat: LineFeatures,
    vox: np.ndarray,
    angle_deg: float,
    min_voxels: int,
    rng: np.random.Generator,
    hypotheses: int = 48,
    max_lines: int = 16,
) -> list[np.ndarray]:
    """Split one grown region into straight lines by sequential voting: each
    of ``hypotheses`` random voxels proposes the line through its
    neighbourhood mean along its direction; the line with most voxels whose
    means lie within half its scale and whose directions agree wins, its
    voxels are removed, and so on.  Region growing alone chains a chord into
    a diagonal through the joint, where neighbourhood directions turn
    gradually; voting keeps the straight parts and drops the turn."""
    left = vox.copy()
    out: list[np.ndarray] = []
    cos_min = float(np.cos(np.radians(angle_deg)))
    means, dirs, rad = feat.mean, feat.direction, feat.radius
    for _ in range(max_lines):
        if len(left) < min_voxels:
            break
        hyp = left[rng.choice(len(left), size=min(hypotheses, len(left)), replace=False)]
        best: np.ndarray | None = None
        for h in hyp:
            rel = means[left] - means[h]
            t = rel @ dirs[h]
            perp = np.linalg.norm(rel - np.outer(t, dirs[h]), axis=1)
            ok = (perp <= 0.5 * rad[h]) & (np.abs(dirs[left] @ dirs[h]) >= cos_min)
            if best is None or ok.sum() > best.sum():
                best = ok
        if best is None or best.sum() < min_voxels:
            break
        out.append(left[best])
        left = left[~best]
    return out


def candidates_from_regions(
    feat: LineFeatures,
    region: np.ndarray,
    min_length: float,
    angle_deg: float,
    seed: int = 0,
    min_voxels: int = 6,
) -> list[LineCandidate]:
    """Straight line candidates (:func:`region_lines`) of every region, kept
    when at least ``min_length`` long."""
    rng = np.random.default_rng(seed)
    out: list[LineCandidate] = []
    order = np.argsort(region, kind="stable")
    r_sorted = region[order]
    starts = np.searchsorted(r_sorted, np.arange(r_sorted.max() + 2 if len(r_sorted) else 1))
    for k in range(len(starts) - 1):
        vox = order[starts[k] : starts[k + 1]]
        if len(vox) < min_voxels or region[vox[0]] < 0:
            continue
        for part in region_lines(feat, vox, angle_deg, min_voxels, rng):
            c, d, t0, t1, rad = fit_line(feat.grid.centres[part])
            if t1 - t0 >= min_length:
                out.append(LineCandidate(part, c, d, t0, t1, rad))
    return out


class _UnionFind:
    def __init__(self, n: int) -> None:
        self.p = list(range(n))

    def find(self, a: int) -> int:
        while self.p[a] != a:
            self.p[a] = self.p[self.p[a]]
            a = self.p[a]
        return a

    def union(self, a: int, b: int) -> None:
        ra, rb = self.find(a), self.find(b)
        if ra != rb:
            self.p[max(ra, rb)] = min(ra, rb)


#: ``bridge(a, b, t_from, t_to)``: whether the stretch ``[t_from, t_to]`` of
#: ``a``'s line between two collinear pieces is steel (points all along it)
Bridge = Callable[[LineCandidate, LineCandidate, float, float], bool]


def _should_join(
    a: LineCandidate,
    b: LineCandidate,
    cos_min: float,
    cos_side: float,
    max_gap: float,
    max_section: float,
    bridge: Bridge | None = None,
    bridge_gap: float = 0.0,
) -> float | None:
    """How far apart ``a`` and ``b`` lie (m) when they are one member's pieces,
    else ``None``.  Collinear pieces further apart than ``max_gap`` (up to
    ``bridge_gap``) are one member when ``bridge`` finds the stretch between
    them filled: a girder's middle far from every scanner is sparse, its
    pieces' directions uncertain, and the pieces found stop metres apart."""
    if (b.length, *b.centre) > (a.length, *a.centre):  # ties: either order, one answer
        # the shorter piece is measured against the longer one's line: the
        # longer direction is the surer (a 1.3 m piece 1.9° off puts the far
        # end of a 6.5 m neighbour 0.2 m off its line)
        a, b = b, a
    cos = abs(float(a.direction @ b.direction))
    if cos < cos_side:
        return None
    # b's end points in a's line frame
    rel = b.ends - a.centre
    t = rel @ a.direction
    perp = np.linalg.norm(rel - np.outer(t, a.direction), axis=1)
    apart = float(perp.max())
    lo, hi = float(t.min()), float(t.max())
    overlap = min(hi, a.t1) - max(lo, a.t0)
    shorter = min(a.length, b.length)
    if overlap > 0.5 * shorter:
        # side by side: two faces of one member when within one section (the
        # direction of a short face is less certain: the linking tolerance)
        return apart if apart <= max_section else None
    if cos < cos_min:
        return None
    gap = max(lo - a.t1, a.t0 - hi)
    # collinear fragments: the lines must be as close as the sections are wide
    tol = max(a.radius, b.radius, 0.05)
    if apart > tol:
        return None
    if gap <= max_gap:
        return apart
    # a bridge spans more, so it asks for half the offset: collinear rows of
    # cross girders, each framing into a main girder, stand a few cm apart
    if bridge is None or gap > bridge_gap or apart > 0.5 * tol:
        return None
    span = (a.t1, lo) if lo - a.t1 >= a.t0 - hi else (hi, a.t0)
    return apart if bridge(a, b, *span) else None


#: directions over which a group's section extent is measured: the largest
#: extent over them is at least cos(90° / SECTION_DIRECTIONS) of the true one
SECTION_DIRECTIONS = 16


def section_extent(cands: list[LineCandidate], group: list[int]) -> float:
    """Largest distance (m) across the line ends of ``group`` seen along the
    direction of its longest candidate: how deep a section the group makes."""
    longest = max(group, key=lambda i: cands[i].length)
    d = cands[longest].direction
    ends = np.vstack([cands[i].ends for i in group])
    rel = ends - cands[longest].centre
    rel = rel - np.outer(rel @ d, d)
    u = np.cross(d, [1.0, 0.0, 0.0] if abs(d[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(d, u)
    ang = np.linspace(0.0, np.pi, SECTION_DIRECTIONS, endpoint=False)
    dirs = np.outer(np.cos(ang), u) + np.outer(np.sin(ang), v)  # (K, 3)
    q = rel @ dirs.T  # (2 × group, K): bounded by the directions, not by a pair count
    return float((q.max(axis=0) - q.min(axis=0)).max())


def _pairs_ahead(
    cands: list[LineCandidate], tree: cKDTree, own: np.ndarray, step: float, reach: float
) -> list[np.ndarray]:
    """(i, j) pairs where candidate j's sampled axis lies on candidate i's line
    within ``reach`` past either end: the pieces a bridge may join.  One ball
    query a sample of the extensions: bounded by their length."""
    out = []
    for i, c in enumerate(cands):
        ts = np.arange(step, reach + step, step)
        ext = np.vstack(
            [
                c.centre + np.outer(c.t1 + ts, c.direction),
                c.centre + np.outer(c.t0 - ts, c.direction),
            ]
        )
        hits = tree.query_ball_point(ext, step + max(c.radius, 0.05), return_sorted=False)
        js = sorted_unique(own[hit_union(hits)])
        js = js[js != i]
        if len(js):
            out.append(np.column_stack([np.full(len(js), i), js]))
    return out


def join_groups(
    cands: list[LineCandidate],
    angle_deg: float,
    max_gap: float,
    max_section: float,
    side_angle_deg: float | None = None,
    bridge: Bridge | None = None,
    bridge_gap: float = 0.0,
) -> list[list[int]]:
    """Groups of candidate indices to join: union-find over the pairs near each
    other (KD-tree on their sampled axes: no all-pairs array) that are
    collinear across a gap up to ``max_gap`` (or up to ``bridge_gap`` where
    ``bridge`` finds the gap filled) or side by side within ``max_section``."""
    if len(cands) < 2:
        return [[i] for i in range(len(cands))]
    step = max(0.25, max_gap / 4)
    samples, owner = [], []
    for i, c in enumerate(cands):
        n = max(2, int(np.ceil(c.length / step)) + 1)
        ts = np.linspace(c.t0, c.t1, n)
        samples.append(c.centre + np.outer(ts, c.direction))
        owner.append(np.full(n, i))
    pts = np.vstack(samples)
    own = np.concatenate(owner)
    tree = cKDTree(pts)
    pairs = tree.query_pairs(max(max_gap, max_section) + step, output_type="ndarray")
    found = [np.column_stack([own[pairs[:, 0]], own[pairs[:, 1]]])] if len(pairs) else []
    if bridge is not None and bridge_gap > max_gap:
        found += _pairs_ahead(cands, tree, own, step, bridge_gap)
    cand_pairs = (
        np.unique(np.sort(np.vstack(found), axis=1), axis=0) if found else np.zeros((0, 2), int)
    )
    uf = _UnionFind(len(cands))
    cos_min = float(np.cos(np.radians(angle_deg)))
    cos_side = float(np.cos(np.radians(max(angle_deg, side_angle_deg or angle_deg))))
    joinable = []
    for i, j in cand_pairs:
        if i == j:
            continue
        apart = _should_join(
            cands[i], cands[j], cos_min, cos_side, max_gap, max_section, bridge, bridge_gap
        )
        if apart is not None:
            joinable.append((apart, int(i), int(j)))
    # nearest pieces first, and no group deeper than one section: chained
    # side-by-side joins (top chord – a diagonal's edge – bottom chord, each
    # pair within 1.2 m) once made a whole 1.7 m deep truss one member
    members: dict[int, list[int]] = {i: [i] for i in range(len(cands))}
    for _, i, j in sorted(joinable):
        ri, rj = uf.find(i), uf.find(j)
        if ri == rj:
            continue
        both = members[ri] + members[rj]
        if len(both) > 2 and section_extent(cands, both) > max_section:
            continue
        uf.union(ri, rj)
        members[uf.find(ri)] = both
    groups: dict[int, list[int]] = {}
    for i in range(len(cands)):
        groups.setdefault(uf.find(i), []).append(i)
    return list(groups.values())


def join_fragments(
    cands: list[LineCandidate],
    feat: LineFeatures,
    angle_deg: float,
    max_gap: float,
    max_section: float,
    side_angle_deg: float | None = None,
) -> list[LineCandidate]:
    """Candidates with each :func:`join_groups` group refitted as one line."""
    out: list[LineCandidate] = []
    for group in join_groups(cands, angle_deg, max_gap, max_section, side_angle_deg):
        if len(group) == 1:
            out.append(cands[group[0]])
            continue
        vox = np.concatenate([cands[i].voxels for i in group])
        centre, d, t0, t1, rad = fit_line(feat.grid.centres[vox])
        out.append(
            LineCandidate(vox, centre, d, t0, t1, rad, sum(cands[i].fragments for i in group))
        )
    return out
