"""Frozen copy of ``segment_default`` as it was before it was split into
named steps (commit 111f02a, ``planners/navigation/segmentation.py``): the
reference that ``test_segment_default_matches_the_frozen_copy`` compares the
refactored function with, label for label.  Do not edit; the helpers it
calls (``_chords``, ``_fit_line``, ...) are unchanged by the split and are
imported from the module.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from planners.errors import InvalidInputError
from planners.navigation.segmentation import (
    _EIGHT,
    _FOUR,
    Segmentation,
    _axis_angles,
    _bridge,
    _chords,
    _components,
    _count_runs,
    _disk,
    _fit_line,
    _Line,
    _one_strip,
)


def segment_default_reference(
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
    """Deterministic strip-based segmentation (see module docstring, "default")."""
    uv = np.asarray(uv, dtype=float)
    if len(uv) < 3:
        raise InvalidInputError(f"segmentation needs at least 3 points, got {len(uv)}")
    c = float(grid_m)
    # Local point spacing: mean distance to the 3 nearest neighbours.  Density
    # falls ~10× with range, so gaps are closed with a radius per point.
    dk = np.asarray(cKDTree(uv).query(uv, k=min(4, len(uv)))[0])  # k ≥ 2: an array
    nn = dk[:, 1]
    local = dk[:, 1:].mean(axis=1)
    r_pt = np.clip(np.ceil(1.2 * local / c), 1, 6).astype(np.int64)
    pad = int(r_pt.max()) + 3
    origin = uv.min(axis=0) - pad * c
    ij = np.floor((uv - origin) / c).astype(np.int64)
    shape = tuple(ij.max(axis=0) + pad + 1)
    occ = np.zeros(shape, dtype=bool)
    occ[ij[:, 0], ij[:, 1]] = True

    # 1. Close the gaps of the sparse far field (each radius class on its own
    #    points: a closing is extensive, so the union keeps every point), fill
    #    small dropout holes, drop specks.
    mask = occ.copy()
    for r in np.unique(r_pt):
        sub = np.zeros(shape, dtype=bool)
        sel = r_pt == r
        sub[ij[sel, 0], ij[sel, 1]] = True
        # Neighbouring points of smaller radius still bridge the gap edges.
        sub |= occ & ndimage.binary_dilation(sub, structure=_disk(int(r)))
        mask |= ndimage.binary_closing(sub, structure=_disk(int(r)))
    r_close = int(np.median(r_pt))
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
    mask = big[comp]
    cells = np.argwhere(mask)
    q = len(cells)
    if q == 0:
        raise InvalidInputError("no steel area left after rasterising the points")
    index = np.full(shape, -1, dtype=np.int64)
    index[cells[:, 0], cells[:, 1]] = np.arange(q)

    # 2. Directional chords; cells with one run of long directions are bar cells
    #    with an axis angle.
    chords = _chords(cells, n_directions)
    width = chords.min(axis=1)
    w_med = float(np.median(width))
    long_dir = chords >= np.maximum(long_factor * width, long_factor * w_med)[:, None]
    long_dir = _bridge(long_dir, gap_bridge)
    single = (_count_runs(long_dir) == 1) & ~long_dir.all(axis=1)
    angle = _axis_angles(chords)

    # 3. Bar pieces: 4-connected single-run cells whose axis angles agree.
    a_list, b_list = [cells[:0, 0]], [cells[:0, 0]]
    for di, dj in ((1, 0), (0, 1)):
        nb = cells + (di, dj)
        ok = (nb[:, 0] < shape[0]) & (nb[:, 1] < shape[1])
        src = np.nonzero(ok)[0]
        dst = index[nb[ok, 0], nb[ok, 1]]
        keep = dst >= 0
        src, dst = src[keep], dst[keep]
        diff = np.abs(np.angle(np.exp(2j * (angle[src] - angle[dst])))) / 2
        keep = single[src] & single[dst] & (diff < np.deg2rad(piece_angle_deg))
        a_list.append(src[keep])
        b_list.append(dst[keep])
    piece = _components(q, np.concatenate(a_list), np.concatenate(b_list))
    piece = np.where(single, piece, -1)
    xy = cells.astype(float)
    pieces: list[tuple[np.ndarray, _Line]] = []
    order = np.argsort(piece, kind="stable")
    ids, starts = np.unique(piece[order], return_index=True)
    bounds = np.append(starts, q)
    for k, pid in enumerate(ids):  # per piece (tens to hundreds)
        if pid < 0:
            continue
        sel = order[bounds[k] : bounds[k + 1]]
        ang = 0.5 * float(np.angle(np.exp(2j * angle[sel]).mean()))
        line = _fit_line(xy[sel], ang, width[sel])
        # A piece must be long and span most of its own flange width: a sliver
        # along a ragged (far, noisy) edge is not a bar of its own.
        _, t = line.coords(xy[sel])
        thick = float(np.subtract(*np.percentile(t, [95, 5]))) + 1.0
        if (line.s_hi - line.s_lo) * c >= max(min_piece_m, 1.5 * line.width * c) and (
            thick >= 0.5 * line.width
        ):
            pieces.append((sel, line))

    # 4. Pieces → lines, largest first: a piece mostly inside an accepted
    #    line's strip is part of that line (joined when parallel, otherwise a
    #    fringe artefact of a crossing and dropped); any other piece starts a
    #    new line.
    pieces.sort(key=lambda p: -len(p[0]))
    line_cells: list[np.ndarray] = []
    lines: list[_Line] = []
    for sel, line in pieces:
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
            ang = 0.5 * float(np.angle(np.exp(2j * angle[merged]).mean()))
            lines[best] = _fit_line(xy[merged], ang, width[merged])
            line_cells[best] = merged
    # Two lines fitted to the same bar from distant pieces (a long chord) can
    # both survive; merge near-parallel lines when one strip explains both.
    merged_any = True
    while merged_any:
        merged_any = False
        for i in range(len(lines)):
            for j in range(i + 1, len(lines)):
                if abs(float(lines[i].d @ lines[j].d)) < np.cos(np.deg2rad(2 * line_angle_deg)):
                    continue
                cells_ij = np.concatenate([line_cells[i], line_cells[j]])
                line, ok = _one_strip(xy[cells_ij], angle[cells_ij], width[cells_ij])
                if not ok:
                    continue
                lines[i], line_cells[i] = line, cells_ij
                del lines[j], line_cells[j]
                merged_any = True
                break
            if merged_any:
                break

    # 5. Strip membership of every steel cell; cross cells lie on two or more.
    #    A strip runs along its line as far as steel continues from its pieces
    #    (through the crossings at its ends to the far edge of the crossing bar).
    member = np.zeros((q, len(lines)), dtype=bool)
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
    n_member = member.sum(axis=1)
    cross_cells = np.zeros(shape, dtype=bool)
    cross_cells[cells[:, 0], cells[:, 1]] = n_member >= 2
    # A dropout notch can split one crossing in two with a sliver of bar
    # between: close gaps narrower than about half a flange.
    r_cross = max(1, round(0.5 * w_med))
    cross_cells = ndimage.binary_closing(cross_cells, structure=_disk(r_cross)) & mask
    cross_lab, n_cross = ndimage.label(cross_cells, structure=_EIGHT)
    if n_cross:
        area = np.bincount(cross_lab.ravel(), minlength=n_cross + 1)
        ok = area * c * c >= (0.3 * w_med * c) ** 2
        ok[0] = False
        cross_lab, n_cross = ndimage.label(ok[cross_lab], structure=_EIGHT)

    # 6. Bars: cells on exactly one line, split by the cross areas (4-connected).
    owner = np.where(n_member == 1, np.argmax(member, axis=1), -1)
    bar_lab = np.zeros(shape, dtype=np.int64)
    n_bar = 0
    for k in range(len(lines)):
        on = np.zeros(shape, dtype=bool)
        sel = owner == k
        on[cells[sel, 0], cells[sel, 1]] = True
        on &= cross_lab == 0
        lab, n = ndimage.label(on, structure=_FOUR)
        bar_lab = np.where(lab > 0, lab + n_bar, bar_lab)
        n_bar += n
    # Fragments shorter than min_bar_length_m are not bars: they are left
    # unlabelled and join their neighbour below.
    if n_bar:
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
            good[b + 1] = float(np.ptp(cen @ vt[0])) * c >= min_bar_length_m
        bar_lab = np.where(good[bar_lab], bar_lab, 0)

    # 7. Every other steel cell takes the label of the nearest labelled cell.
    raw = np.where(cross_lab > 0, cross_lab, np.where(bar_lab > 0, n_cross + bar_lab, 0))
    if np.any(raw > 0):
        _, (ii, jj) = ndimage.distance_transform_edt(raw == 0, return_indices=True)
        raw = np.where(mask, raw[ii, jj], 0)

    # Renumber deterministically: cross areas first, then bars, each by (u, v)
    # of their point centroid.
    praw = raw[ij[:, 0], ij[:, 1]]
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
    labels = remap[praw]
    kinds = [kinds_raw[k] for k in order_k]
    return Segmentation(
        labels=labels,
        kinds=kinds,
        method="default",
        info={
            "point_spacing_m": float(np.median(nn)),
            "closing_radius_cells": r_close,
            "median_width_m": w_med * c,
            "n_lines": len(lines),
            "n_cross": kinds.count("cross"),
            "n_bar": kinds.count("bar"),
        },
    )
