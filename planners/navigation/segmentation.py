"""Steel-structure segmentation into bars and cross areas (seed Alg. 3, Eq. 4.1).

Two methods over the processed 2D points (plane coordinates, metres):

``"thesis"`` — Algorithm 3 as printed: EM-GMM (scikit-learn
``GaussianMixture``, fixed seed) for every cluster count ``nc`` in
``[Ncmin, Ncmax]``; two clusters are neighbours when they share a border of
length ≥ ``lb``; ``nm``/``ns`` are the most / second most neighbour counts;
the count with the highest ``r = nm/(nm+ns) + nm/nc`` (Eq. 4.1) is refitted;
the clusters with ``nm`` neighbours (nm ≥ 2) are the cross areas.  As the seed
reports (§5.2.3), this fails on the I shape (two cross areas make
``nm = ns``, so a 3-blob split scores higher) and on trusses, where a
Gaussian blob cannot follow a bar.

``"default"`` — a deterministic strip-based segmentation (no random
initialisation at all).  It keeps the seed's idea (§4.1: bars are long in one
direction, cross areas are where bars meet) but measures it directly instead
of inferring it from a mixture's neighbour counts:

1. rasterise the points (``grid_m``); close gaps with a radius per point
   from its local spacing (density falls ~10× with range); fill small
   enclosed dropout holes; drop specks;
2. for every steel cell, the chord length of steel through it in
   ``n_directions`` directions over [0, π) — exact run lengths along naive
   digital lines, one sort per direction;
3. a direction is *long* where its chord is ≥ ``long_factor`` × the cell's
   shortest chord (its flange width) and × the median width; cells with one
   run of long directions are bar cells with an axis angle (longest chord);
   4-connected bar cells with agreeing angles form *pieces*;
4. pieces that are long and span their flange become *lines* (trimmed PCA),
   largest first; a piece lying inside an accepted strip joins it (or is a
   fringe artefact of a crossing); near-parallel lines one strip explains are
   merged;
5. each line's strip runs along it as far as steel continues; cells on two
   or more strips are cross areas (an L corner too, which the neighbour count
   of Eq. 4.1 cannot see); the rest of each strip, split by the cross areas,
   are the bars; fragments shorter than ``min_bar_length_m`` and other
   leftovers take the nearest label.

Both return per-point labels (−1 = noise) and a kind per cluster.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from planners.errors import InvalidInputError


@dataclass
class Segmentation:
    """Per-point cluster labels (−1 = noise) and the kind of every cluster."""

    labels: np.ndarray  # (M,) int
    kinds: list[str]  # "bar" | "cross" per cluster id
    method: str
    info: dict[str, float | int | list[float]] = field(default_factory=dict)

    @property
    def n_clusters(self) -> int:
        return len(self.kinds)


@dataclass(frozen=True)
class Border:
    """Shared border of two neighbour clusters ``a < b`` (seed §4.1, Fig. 4.2)."""

    a: int
    b: int
    length_m: float
    midpoint: np.ndarray  # (2,) mean of the border points of both sides
    points: np.ndarray  # indices of the border points (both sides)


def point_spacing(uv: np.ndarray) -> float:
    """Median nearest-neighbour distance (metres) of a 2D cloud."""
    if len(uv) < 2:
        return 0.0
    # k ≥ 2 gives arrays; asarray narrows the stubs' scalar-or-array result
    d = np.asarray(cKDTree(uv).query(uv, k=2)[0])
    return float(np.median(d[:, 1]))


def borders(
    uv: np.ndarray, labels: np.ndarray, *, eps_m: float, lb_m: float, k: int = 6
) -> list[Border]:
    """Neighbour clusters: pairs sharing a border of length ≥ ``lb_m`` (seed §4.1).

    Border points of clusters a and b are the points of either that have a
    point of the other among their ``k`` nearest neighbours within ``eps_m``
    (k-nearest rather than a fixed radius, because density falls ~10× with
    range); the border length is their extent along their principal
    direction.  Sorted by (a, b).
    """
    if len(uv) < 2:
        return []
    kk = min(k + 1, len(uv))
    dist_q, nb_q = cKDTree(uv).query(uv, k=kk)
    dist, nb = np.asarray(dist_q), np.asarray(nb_q)  # k ≥ 2: arrays (narrowed for the stubs)
    src = np.repeat(np.arange(len(uv)), kk - 1)
    dst = nb[:, 1:].ravel()
    close = dist[:, 1:].ravel() <= eps_m
    pairs = np.column_stack([src[close], dst[close]])
    if len(pairs) == 0:
        return []
    la, lb_ = labels[pairs[:, 0]], labels[pairs[:, 1]]
    cross = (la != lb_) & (la >= 0) & (lb_ >= 0)
    pairs, la, lb_ = pairs[cross], la[cross], lb_[cross]
    lo, hi = np.minimum(la, lb_), np.maximum(la, lb_)
    key = lo.astype(np.int64) * (int(labels.max()) + 1) + hi
    order = np.argsort(key, kind="stable")
    key, pairs, lo, hi = key[order], pairs[order], lo[order], hi[order]
    uniq, starts = np.unique(key, return_index=True)
    bounds = np.append(starts, len(key))
    out: list[Border] = []
    for g in range(len(uniq)):  # one iteration per cluster pair
        sl = slice(bounds[g], bounds[g + 1])
        idx = np.unique(pairs[sl].ravel())
        p = uv[idx]
        c = p.mean(axis=0)
        if len(p) >= 2:
            _, _, vt = np.linalg.svd(p - c, full_matrices=False)
            proj = (p - c) @ vt[0]
            length = float(np.ptp(proj))
        else:
            length = 0.0
        if length >= lb_m:
            out.append(Border(int(lo[sl][0]), int(hi[sl][0]), length, c, idx))
    return out


# ------------------------------------------------------------------ default
def _disk(radius: int) -> np.ndarray:
    r = np.arange(-radius, radius + 1)
    return (r[:, None] ** 2 + r[None, :] ** 2) <= radius * radius + 1e-9


_FOUR = np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], dtype=bool)
_EIGHT = np.ones((3, 3), dtype=bool)


def _chords(cells: np.ndarray, n_dirs: int) -> np.ndarray:
    """Chord length (in cells) of the steel run through each cell, per direction.

    ``cells`` (Q, 2) integer coordinates of the steel cells.  For direction θ
    the cells are bucketed into digital lines ``round(t / max(|cos θ|, |sin θ|))``
    (t across θ: one cell per column or row, 8-connected, like a naive digital
    line) and sorted along s; a gap wider than 1.5 cells ends a run (neighbours
    on a digital line are at most √2 apart, a missing cell makes it ≥ 1.8).
    Returns (Q, n_dirs).
    """
    q = len(cells)
    out = np.empty((q, n_dirs))
    xy = cells.astype(float)
    for k in range(n_dirs):  # one vectorised pass per direction
        th = np.pi * k / n_dirs
        s = xy[:, 0] * np.cos(th) + xy[:, 1] * np.sin(th)
        band = max(abs(np.cos(th)), abs(np.sin(th)))
        t = np.rint((-xy[:, 0] * np.sin(th) + xy[:, 1] * np.cos(th)) / band).astype(np.int64)
        order = np.lexsort((s, t))
        ss, tt = s[order], t[order]
        new = np.ones(q, dtype=bool)
        new[1:] = (tt[1:] != tt[:-1]) | (np.diff(ss) > 1.5)
        run = np.cumsum(new) - 1
        starts = np.nonzero(new)[0]
        ends = np.append(starts[1:], q) - 1
        length = ss[ends] - ss[starts] + 1.0
        out[order, k] = length[run]
    return out


def _bridge(flags: np.ndarray, bridge: int) -> np.ndarray:
    """Close circular gaps of at most ``bridge`` False entries between True runs."""
    f = flags.copy()
    for g in range(1, bridge + 1):
        for off in range(1, g + 1):
            f |= np.roll(flags, off, axis=1) & np.roll(flags, off - g - 1, axis=1)
    return f


def _count_runs(flags: np.ndarray) -> np.ndarray:
    """Number of circular runs of True per row of a (Q, D) boolean array."""
    return np.count_nonzero(flags & ~np.roll(flags, 1, axis=1), axis=1)


def _components(n: int, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Connected-component id of ``n`` nodes joined by edges ``a[i]–b[i]``."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    g = coo_matrix((np.ones(len(a), dtype=np.int8), (a, b)), shape=(n, n))
    return connected_components(g, directed=False)[1]


@dataclass
class _Line:
    """A straight steel strip: unit direction, offset across it, width, s-range (cells)."""

    d: np.ndarray
    rho: float
    width: float
    s_lo: float
    s_hi: float

    def coords(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        s = xy @ self.d
        t = xy[:, 1] * self.d[0] - xy[:, 0] * self.d[1]
        return s, t


def _fit_line(xy: np.ndarray, angle: float, widths: np.ndarray) -> _Line:
    """Line through cells ``xy``: direction by trimmed PCA when the cells are
    long (≥ 3 widths: a long baseline beats the per-cell angles, quantised to
    the chord directions; trimming drops cells of a crossing bar caught at a
    piece's end), else the given mean axis ``angle``; offset = median."""
    width = float(np.median(widths))
    d = np.array([np.cos(angle), np.sin(angle)])
    keep = np.ones(len(xy), dtype=bool)
    for _ in range(3):
        if np.count_nonzero(keep) < 3:
            break
        sub = xy[keep]
        cen = sub - sub.mean(axis=0)
        _, _, vt = np.linalg.svd(cen, full_matrices=False)
        if np.ptp(cen @ vt[0]) < 3.0 * width:
            break
        d = vt[0] if float(vt[0] @ d) >= 0 else -vt[0]
        t = xy[:, 1] * d[0] - xy[:, 0] * d[1]
        keep = np.abs(t - np.median(t[keep])) <= 0.5 * width + 1.0
    line = _Line(d, 0.0, width, 0.0, 0.0)
    s, t = line.coords(xy)
    line.rho = float(np.median(t[keep])) if np.any(keep) else float(np.median(t))
    line.s_lo, line.s_hi = float(s.min()), float(s.max())
    return line


def _one_strip(xy: np.ndarray, angle: np.ndarray, widths: np.ndarray) -> tuple[_Line, bool]:
    """Fit one line to ``xy``; True when ≥ 90 % of the cells lie in its strip."""
    ang = 0.5 * float(np.angle(np.exp(2j * angle).mean()))
    line = _fit_line(xy, ang, widths)
    _, t = line.coords(xy)
    inside = np.abs(t - line.rho) <= 0.5 * line.width + max(1.0, 0.15 * line.width)
    return line, bool(np.mean(inside) >= 0.9)


def _axis_angles(chords: np.ndarray) -> np.ndarray:
    """Per cell, the direction of its longest chord, refined by a parabola
    through the neighbouring directions (radians in [0, π))."""
    n_dirs = chords.shape[1]
    k = np.argmax(chords, axis=1)
    rows = np.arange(len(k))
    c0 = chords[rows, k]
    cm = chords[rows, (k - 1) % n_dirs]
    cp = chords[rows, (k + 1) % n_dirs]
    denom = cm - 2 * c0 + cp
    off = np.where(denom < 0, 0.5 * (cm - cp) / np.where(denom < 0, denom, -1.0), 0.0)
    return (np.pi * (k + np.clip(off, -0.5, 0.5)) / n_dirs) % np.pi


@dataclass
class _Raster:
    """The points on a ``c``-metre grid: each point's cell ``ij``, the grid
    ``shape``, the occupied cells ``occ``, the per-point closing radius
    ``r_pt`` (cells) and each point's nearest-neighbour distance ``nn``."""

    c: float
    ij: np.ndarray
    shape: tuple[int, int]
    occ: np.ndarray
    r_pt: np.ndarray
    nn: np.ndarray


@dataclass
class _Steel:
    """The steel cells: grid ``mask``, their (Q, 2) coordinates ``cells``
    (``xy`` as floats) and the cell index per grid position (−1 off steel)."""

    mask: np.ndarray
    cells: np.ndarray
    xy: np.ndarray
    index: np.ndarray


@dataclass
class _Chords:
    """Step 2 per steel cell: flange width (shortest chord, cells), median
    width, whether it is a bar cell (one run of long directions) and its axis
    angle (rad in [0, π))."""

    width: np.ndarray
    w_med: float
    single: np.ndarray
    angle: np.ndarray


def _rasterise(uv: np.ndarray, c: float) -> _Raster:
    """Step 1a (replaces Alg. 3's GMM input): the points on a ``c`` grid, with a
    closing radius per point of 1.2 × its mean distance to its 3 nearest
    neighbours (1–6 cells): density falls ~10× with range (§5.2.1)."""
    dk = np.asarray(cKDTree(uv).query(uv, k=min(4, len(uv)))[0])  # k ≥ 2: an array
    nn = dk[:, 1]
    local = dk[:, 1:].mean(axis=1)
    r_pt = np.clip(np.ceil(1.2 * local / c), 1, 6).astype(np.int64)
    pad = int(r_pt.max()) + 3
    origin = uv.min(axis=0) - pad * c
    ij = np.floor((uv - origin) / c).astype(np.int64)
    shape = (int(ij[:, 0].max()) + pad + 1, int(ij[:, 1].max()) + pad + 1)
    occ = np.zeros(shape, dtype=bool)
    occ[ij[:, 0], ij[:, 1]] = True
    return _Raster(c, ij, shape, occ, r_pt, nn)


def _close_gaps(ras: _Raster) -> np.ndarray:
    """Step 1b: a morphological closing per radius class, each on its own
    points (a closing is extensive, so the union keeps every point);
    neighbouring points of smaller radius still bridge the gap edges."""
    mask = ras.occ.copy()
    for r in np.unique(ras.r_pt):
        sub = np.zeros(ras.shape, dtype=bool)
        sel = ras.r_pt == r
        sub[ras.ij[sel, 0], ras.ij[sel, 1]] = True
        sub |= ras.occ & ndimage.binary_dilation(sub, structure=_disk(int(r)))
        mask |= ndimage.binary_closing(sub, structure=_disk(int(r)))
    return mask


def _fill_holes_drop_specks(
    mask: np.ndarray, c: float, hole_fill_m2: float, min_component_m2: float
) -> np.ndarray:
    """Step 1c: fill enclosed holes smaller than ``hole_fill_m2`` (dropout),
    then drop 8-connected steel components smaller than ``min_component_m2``."""
    mask = mask.copy()
    holes, n_holes = ndimage.label(~mask)
    if n_holes:
        area = np.bincount(holes.ravel(), minlength=n_holes + 1)
        edge_ids = np.unique(np.concatenate([holes[0], holes[-1], holes[:, 0], holes[:, -1]]))
        small = area * c * c < hole_fill_m2
        small[edge_ids] = False
        small[0] = False
        mask |= small[holes]
    comp, n_comp = ndimage.label(mask, structure=_EIGHT)
    area = np.bincount(comp.ravel(), minlength=n_comp + 1)
    big = area * c * c >= min_component_m2
    big[0] = False
    return np.asarray(big[comp])


def _steel_cells(mask: np.ndarray) -> _Steel:
    """The steel cells of ``mask`` and their index grid; raises
    :class:`InvalidInputError` when none is left."""
    cells = np.argwhere(mask)
    if len(cells) == 0:
        raise InvalidInputError("no steel area left after rasterising the points")
    index = np.full(mask.shape, -1, dtype=np.int64)
    index[cells[:, 0], cells[:, 1]] = np.arange(len(cells))
    return _Steel(mask, cells, cells.astype(float), index)


def _bar_cells(cells: np.ndarray, n_dirs: int, long_factor: float, bridge: int) -> _Chords:
    """Step 2 (§4.1's premise, "bars are long in one direction", measured):
    exact chords in ``n_dirs`` directions; a direction is long where its chord
    is ≥ ``long_factor`` × the cell's width and × the median width; cells with
    one run of long directions (gaps ≤ ``bridge`` closed) are bar cells."""
    chords = _chords(cells, n_dirs)
    width = chords.min(axis=1)
    w_med = float(np.median(width))
    long_dir = chords >= np.maximum(long_factor * width, long_factor * w_med)[:, None]
    long_dir = _bridge(long_dir, bridge)
    single = (_count_runs(long_dir) == 1) & ~long_dir.all(axis=1)
    return _Chords(width, w_med, single, _axis_angles(chords))


def _piece_ids(steel: _Steel, ch: _Chords, piece_angle_deg: float) -> np.ndarray:
    """Step 3a: per steel cell its piece id (−1: not a bar cell) — components
    of 4-connected bar cells whose axis angles differ by < ``piece_angle_deg``."""
    cells, index, angle, single = steel.cells, steel.index, ch.angle, ch.single
    a_list, b_list = [cells[:0, 0]], [cells[:0, 0]]
    for di, dj in ((1, 0), (0, 1)):
        nb = cells + (di, dj)
        ok = (nb[:, 0] < index.shape[0]) & (nb[:, 1] < index.shape[1])
        src = np.nonzero(ok)[0]
        dst = index[nb[ok, 0], nb[ok, 1]]
        keep = dst >= 0
        src, dst = src[keep], dst[keep]
        diff = np.abs(np.angle(np.exp(2j * (angle[src] - angle[dst])))) / 2
        keep = single[src] & single[dst] & (diff < np.deg2rad(piece_angle_deg))
        a_list.append(src[keep])
        b_list.append(dst[keep])
    piece = _components(len(cells), np.concatenate(a_list), np.concatenate(b_list))
    return np.where(single, piece, -1)


def _fit_pieces(
    piece: np.ndarray, steel: _Steel, ch: _Chords, c: float, min_piece_m: float
) -> list[tuple[np.ndarray, _Line]]:
    """Step 3b: a line per piece (trimmed PCA, :func:`_fit_line`), kept when the
    piece is long (≥ ``min_piece_m`` and 1.5 widths) and spans at least half
    its flange: a sliver along a ragged (far, noisy) edge is no bar."""
    xy = steel.xy
    pieces: list[tuple[np.ndarray, _Line]] = []
    order = np.argsort(piece, kind="stable")
    ids, starts = np.unique(piece[order], return_index=True)
    bounds = np.append(starts, len(piece))
    for k, pid in enumerate(ids):  # per piece (tens to hundreds)
        if pid < 0:
            continue
        sel = order[bounds[k] : bounds[k + 1]]
        ang = 0.5 * float(np.angle(np.exp(2j * ch.angle[sel]).mean()))
        line = _fit_line(xy[sel], ang, ch.width[sel])
        _, t = line.coords(xy[sel])
        thick = float(np.subtract(*np.percentile(t, [95, 5]))) + 1.0
        if (line.s_hi - line.s_lo) * c >= max(min_piece_m, 1.5 * line.width * c) and (
            thick >= 0.5 * line.width
        ):
            pieces.append((sel, line))
    return pieces


def _lines_from_pieces(
    pieces: list[tuple[np.ndarray, _Line]], xy: np.ndarray, ch: _Chords, line_angle_deg: float
) -> tuple[list[_Line], list[np.ndarray]]:
    """Step 4a: pieces → lines, largest first.  A piece mostly (≥ 50 %) inside
    an accepted line's strip is part of it — joined and refitted when within
    ``line_angle_deg`` of parallel, otherwise a fringe artefact of a crossing
    and dropped; any other piece starts a new line."""
    line_cells: list[np.ndarray] = []
    lines: list[_Line] = []
    for sel, line in sorted(pieces, key=lambda p: -len(p[0])):
        best, best_frac = -1, 0.0
        for k, other in enumerate(lines):
            _, t = other.coords(xy[sel])
            frac = float(np.mean(np.abs(t - other.rho) <= 0.5 * other.width + 1.0))
            if frac > best_frac:
                best, best_frac = k, frac
        if best_frac < 0.5:
            lines.append(line)
            line_cells.append(sel)
        elif abs(float(lines[best].d @ line.d)) >= np.cos(np.deg2rad(line_angle_deg)):
            merged = np.concatenate([line_cells[best], sel])
            ang = 0.5 * float(np.angle(np.exp(2j * ch.angle[merged]).mean()))
            lines[best] = _fit_line(xy[merged], ang, ch.width[merged])
            line_cells[best] = merged
    return lines, line_cells


def _merge_parallel_lines(
    lines: list[_Line],
    line_cells: list[np.ndarray],
    xy: np.ndarray,
    ch: _Chords,
    line_angle_deg: float,
) -> tuple[list[_Line], list[np.ndarray]]:
    """Step 4b: two lines fitted to one bar from distant pieces can both
    survive step 4a; merge near-parallel (< 2 × ``line_angle_deg``) pairs
    that one strip explains (:func:`_one_strip`), first pair first, until
    none is left."""
    lines, line_cells = list(lines), list(line_cells)
    cos_max = np.cos(np.deg2rad(2 * line_angle_deg))
    merged_any = True
    while merged_any:
        merged_any = False
        for i, j in itertools.combinations(range(len(lines)), 2):
            if abs(float(lines[i].d @ lines[j].d)) < cos_max:
                continue
            cells_ij = np.concatenate([line_cells[i], line_cells[j]])
            line, ok = _one_strip(xy[cells_ij], ch.angle[cells_ij], ch.width[cells_ij])
            if ok:
                lines[i], line_cells[i] = line, cells_ij
                del lines[j], line_cells[j]
                merged_any = True
                break
    return lines, line_cells


def _strip_membership(lines: list[_Line], xy: np.ndarray) -> np.ndarray:
    """Step 5a: (Q, lines) — the steel cells on each line's strip.  A strip
    runs along its line as far as steel continues from its own pieces
    (through the crossings at its ends to the far edge of the crossing bar)."""
    member = np.zeros((len(xy), len(lines)), dtype=bool)
    for k, line in enumerate(lines):
        s, t = line.coords(xy)
        half = 0.5 * line.width + max(1.0, 0.1 * line.width)
        in_strip = np.abs(t - line.rho) <= half
        sbin = np.floor(s).astype(np.int64)
        lo = int(sbin.min())
        present = np.zeros(int(sbin.max()) - lo + 2, dtype=bool)
        present[sbin[in_strip] - lo] = True
        run = np.cumsum(present & ~np.r_[False, present[:-1]])
        own = (s >= line.s_lo) & (s <= line.s_hi) & in_strip
        active = np.zeros(int(run.max()) + 1, dtype=bool)
        active[run[sbin[own] - lo]] = True
        member[:, k] = in_strip & active[run[sbin - lo]] & present[sbin - lo]
    return member


def _cross_areas(
    n_member: np.ndarray, steel: _Steel, w_med: float, c: float
) -> tuple[np.ndarray, int]:
    """Step 5b (Alg. 3's cross areas, seen directly rather than by Eq. 4.1's
    neighbour count): cells on two or more strips; gaps narrower than half a
    flange closed (a dropout notch can split one crossing); 8-connected areas
    of at least (0.3 flange)² kept.  Returns the label grid and the count."""
    cross_cells = np.zeros(steel.mask.shape, dtype=bool)
    cross_cells[steel.cells[:, 0], steel.cells[:, 1]] = n_member >= 2
    r_cross = max(1, round(0.5 * w_med))
    cross_cells = ndimage.binary_closing(cross_cells, structure=_disk(r_cross)) & steel.mask
    cross_lab, n_cross = ndimage.label(cross_cells, structure=_EIGHT)
    if n_cross:
        area = np.bincount(cross_lab.ravel(), minlength=n_cross + 1)
        ok = area * c * c >= (0.3 * w_med * c) ** 2
        ok[0] = False
        cross_lab, n_cross = ndimage.label(ok[cross_lab], structure=_EIGHT)
    return cross_lab, int(n_cross)


def _bars(member: np.ndarray, steel: _Steel, cross_lab: np.ndarray) -> tuple[np.ndarray, int]:
    """Step 5c (Alg. 3's bars): per line, its cells on no other strip and in no
    cross area, split into 4-connected bars.  Returns the label grid (1..n)
    and n."""
    n_member = member.sum(axis=1)
    owner = np.where(n_member == 1, np.argmax(member, axis=1), -1)
    bar_lab = np.zeros(steel.mask.shape, dtype=np.int64)
    n_bar = 0
    for k in range(member.shape[1]):
        on = np.zeros(steel.mask.shape, dtype=bool)
        sel = owner == k
        on[steel.cells[sel, 0], steel.cells[sel, 1]] = True
        on &= cross_lab == 0
        lab, n = ndimage.label(on, structure=_FOUR)
        bar_lab = np.where(lab > 0, lab + n_bar, bar_lab)
        n_bar += n
    return bar_lab, n_bar


def _drop_short_bars(bar_lab: np.ndarray, n_bar: int, c: float, min_len_m: float) -> np.ndarray:
    """Step 5d: bars whose extent along their principal axis is shorter than
    ``min_len_m`` are no bars: unlabelled, they join a neighbour in step 6."""
    if not n_bar:
        return bar_lab
    bar_cells = np.argwhere(bar_lab > 0)
    bid = bar_lab[bar_cells[:, 0], bar_cells[:, 1]]
    srt = np.argsort(bid, kind="stable")
    starts = np.searchsorted(bid[srt], np.arange(1, n_bar + 1))
    ends = np.append(starts[1:], len(srt))
    good = np.zeros(n_bar + 1, dtype=bool)
    for b in range(n_bar):
        pts = bar_cells[srt[starts[b] : ends[b]]].astype(float)
        if len(pts) < 2:
            continue
        cen = pts - pts.mean(axis=0)
        _, _, vt = np.linalg.svd(cen, full_matrices=False)
        good[b + 1] = float(np.ptp(cen @ vt[0])) * c >= min_len_m
    return np.where(good[bar_lab], bar_lab, 0)


def _fill_nearest(raw: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Step 6: every other steel cell takes the label of the nearest labelled
    cell (Euclidean distance transform)."""
    if not np.any(raw > 0):
        return raw
    _, (ii, jj) = ndimage.distance_transform_edt(raw == 0, return_indices=True)
    return np.where(mask, raw[ii, jj], 0)


def _renumber(praw: np.ndarray, uv: np.ndarray, n_cross: int) -> tuple[np.ndarray, list[str]]:
    """Step 7: per-point labels renumbered deterministically — cross areas
    first, then bars, each by the (u, v) of their points' centroid (raw
    labels 1..``n_cross`` are cross areas); 0 → −1 (noise)."""
    present = np.unique(praw[praw > 0])
    kinds_raw = ["cross" if r <= n_cross else "bar" for r in present]
    cent = [uv[praw == r].mean(axis=0) for r in present]
    order_k = sorted(
        range(len(present)),
        key=lambda k: (
            kinds_raw[k] != "cross",
            round(float(cent[k][0]), 6),
            round(float(cent[k][1]), 6),
        ),
    )
    remap = np.full(int(praw.max()) + 1, -1, dtype=np.int64)
    for new, k in enumerate(order_k):
        remap[present[k]] = new
    return remap[praw], [kinds_raw[k] for k in order_k]


def segment_default(
    uv: np.ndarray,
    *,
    grid_m: float = 0.01,
    n_directions: int = 24,
    long_factor: float = 2.5,
    gap_bridge: int = 2,
    piece_angle_deg: float = 12.0,
    line_angle_deg: float = 6.0,
    min_piece_m: float = 0.08,
    hole_fill_m2: float = 0.01,
    min_component_m2: float = 0.002,
    min_bar_length_m: float = 0.15,
) -> Segmentation:
    """Deterministic strip-based segmentation (module docstring, ``"default"``;
    replaces Alg. 3's GMM and Eq. 4.1's neighbour count by §4.1's premise
    measured directly).  Steps: 1 rasterise, close gaps, fill holes; 2 bar
    cells by their chords; 3 pieces; 4 lines; 5 strips → cross areas and
    bars; 6 leftovers to the nearest label; 7 deterministic numbering."""
    uv = np.asarray(uv, dtype=float)
    if len(uv) < 3:
        raise InvalidInputError(f"segmentation needs at least 3 points, got {len(uv)}")
    c = float(grid_m)
    ras = _rasterise(uv, c)
    mask = _fill_holes_drop_specks(_close_gaps(ras), c, hole_fill_m2, min_component_m2)
    steel = _steel_cells(mask)
    ch = _bar_cells(steel.cells, n_directions, long_factor, gap_bridge)
    pieces = _fit_pieces(_piece_ids(steel, ch, piece_angle_deg), steel, ch, c, min_piece_m)
    lines, cells_of = _lines_from_pieces(pieces, steel.xy, ch, line_angle_deg)
    lines, cells_of = _merge_parallel_lines(lines, cells_of, steel.xy, ch, line_angle_deg)
    member = _strip_membership(lines, steel.xy)
    cross_lab, n_cross = _cross_areas(member.sum(axis=1), steel, ch.w_med, c)
    bar_lab, n_bar = _bars(member, steel, cross_lab)
    bar_lab = _drop_short_bars(bar_lab, n_bar, c, min_bar_length_m)
    raw = np.where(cross_lab > 0, cross_lab, np.where(bar_lab > 0, n_cross + bar_lab, 0))
    raw = _fill_nearest(raw, mask)
    labels, kinds = _renumber(raw[ras.ij[:, 0], ras.ij[:, 1]], uv, n_cross)
    return Segmentation(
        labels=labels,
        kinds=kinds,
        method="default",
        info={
            "point_spacing_m": float(np.median(ras.nn)),
            "closing_radius_cells": int(np.median(ras.r_pt)),
            "median_width_m": ch.w_med * c,
            "n_lines": len(lines),
            "n_cross": kinds.count("cross"),
            "n_bar": kinds.count("bar"),
        },
    )


# ------------------------------------------------------------------- thesis
def ratio_r(degrees: np.ndarray) -> float:
    """Eq. 4.1: ``r = nm/(nm+ns) + nm/nc`` for the neighbour counts of ``nc`` clusters.

    ``nm``/``ns`` are the most / second most neighbour counts (``ns = 0`` for
    one cluster; ``r`` has no first term when nobody has a neighbour).
    """
    deg = np.sort(np.asarray(degrees, dtype=np.int64))[::-1]
    nc = len(deg)
    if nc == 0:
        return 0.0
    nm = int(deg[0])
    ns = int(deg[1]) if nc > 1 else 0
    return (nm / (nm + ns) if nm + ns else 0.0) + nm / nc


def segment_thesis(
    uv: np.ndarray,
    *,
    n_clusters_min: int = 2,
    n_clusters_max: int = 12,
    lb_m: float = 0.03,
    eps_m: float | None = None,
    max_points: int = 4000,
    seed: int = 0,
) -> Segmentation:
    """Algorithm 3 as printed, with Eq. 4.1 choosing the cluster count (see module doc).

    EM runs on at most ``max_points`` points (an evenly strided subset, as the
    seed ran it on a down-sampled cloud); all points are then labelled by the
    fitted mixture.  ``eps_m`` (border contact distance) defaults to 2.5 × the
    point spacing.
    """
    from sklearn.mixture import GaussianMixture
    from threadpoolctl import threadpool_limits

    uv = np.asarray(uv, dtype=float)
    lo, hi = int(n_clusters_min), int(n_clusters_max)
    if lo < 1 or hi < lo:
        raise InvalidInputError(
            f"thesis cluster range must satisfy 1 <= min <= max, got ({n_clusters_min}, {n_clusters_max})"
        )
    if len(uv) < hi:
        raise InvalidInputError(f"segmentation needs at least {hi} points, got {len(uv)}")
    eps = 2.5 * point_spacing(uv) if eps_m is None else float(eps_m)
    stride = max(1, int(np.ceil(len(uv) / max_points)))
    fit_pts = uv[::stride]
    centre = uv.mean(axis=0)

    def fit(nc: int) -> np.ndarray:
        gmm = GaussianMixture(nc, covariance_type="full", random_state=seed, max_iter=200)
        # One BLAS/OpenMP thread: these fits are tiny, and on a shared 2-core
        # machine thread start-up made each one ~10× slower.
        with threadpool_limits(limits=1):
            gmm.fit(fit_pts - centre)
            return gmm.predict(uv - centre).astype(np.int64)

    scores: list[float] = []
    degrees: dict[int, np.ndarray] = {}
    for nc in range(lo, hi + 1):  # Alg. 3 lines 3–12
        lab = fit(nc)
        deg = np.zeros(nc, dtype=np.int64)
        for br in borders(uv, lab, eps_m=eps, lb_m=lb_m):
            deg[br.a] += 1
            deg[br.b] += 1
        scores.append(ratio_r(deg))
        degrees[nc] = deg
    best = lo + int(np.argmax(scores))  # first maximum: the smallest count wins ties
    labels = fit(best)  # Alg. 3 line 14 (same seed: same mixture)
    deg = degrees[best]
    nm = int(deg.max())
    kinds = ["cross" if (d == nm and nm >= 2) else "bar" for d in deg]
    # Empty mixture components (no point predicted) are dropped and ids compacted.
    used = np.unique(labels)
    remap = np.full(best, -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return Segmentation(
        labels=remap[labels],
        kinds=[kinds[u] for u in used],
        method="thesis",
        info={"n_clusters": int(best), "ratio_r": scores, "eps_m": eps},
    )
