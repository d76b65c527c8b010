"""Whole spans through the structure model in overlapping tiles.

A scan of tens of millions of points is modelled tile by tile, so memory
follows the largest tile, not the scan, and the tiles can run in parallel:

1. frame — the cloud's longest horizontal axis (principal axis of the XY of
   a strided subsample) and the one across it (:func:`horizontal_frame`);
2. tiles — the extent along that axis cut into equal cores of about
   ``tile_m``; a tile is its core grown by ``overlap_m`` on every inner
   side.  A tile holding more than ``max_points_per_tile`` points (an upper
   bound from a summed-area table of a point-count grid) is halved across
   its longer core side, recursively, until it fits or its core is no wider
   than the overlap (:func:`plan_tiles`).  The cores partition the plane
   (half-open intervals, the outermost unbounded), so each point has exactly
   one owning tile;
3. model — :func:`planners.structure.pipeline.model_structure` on each
   tile's points, with the whole cloud's measured spacing, through
   ``mapper`` (the builtin ``map``, a process pool, a Dask cluster:
   :func:`model_tile` is the task);
4. merge (:func:`merge_tiles`) — a tile's member is *whole* when neither
   axis end lies within a section of an inner tile side, else a *piece* cut
   by the tile, which is clipped to the tile's core (Liang–Barsky on the
   axis, Sutherland–Hodgman on its faces' outlines).  A whole member is kept
   by the tile whose core holds its midpoint; elsewhere it is a *shadow*
   that only carries its points' labels.  Members of different tiles that
   are collinear (``merge_angle_deg``, an offset within a section), of a
   similar section and overlapping or abutting along their axis (a piece
   is involved; two whole members must overlap by half the shorter) are one
   member (union–find): its axis is the principal line through its parts'
   axes, spanning them all, its faces its parts' clipped faces.  Joints and
   the member graph are then found again on the merged members
   (:func:`.joints.find_joints`, :func:`.joints.member_graph`), with radii
   from each member's section.  Surfaces are clipped to their tile's core
   and coplanar ones of the same kind that touch across a border joined
   (convex hull of their outlines).

A point's label is the one its owning tile gave it, mapped to the merged
member.  Every array is bounded by the scan (labels, the frame coordinates)
or by a tile; nothing is a product of two unbounded counts.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field, replace
from typing import Any

import networkx as nx
import numpy as np
from scipy.spatial import ConvexHull, cKDTree

from planners.errors import EmptyInputError, InternalError, InvalidInputError
from planners.pointcloud._validate import as_points
from planners.pointcloud.spacing import measure_spacing
from planners.structure.joints import extend_to_joints, find_joints, member_graph
from planners.structure.model import Face, Member, StructureModel
from planners.structure.params import StructureParams
from planners.structure.surfaces import PlanarSurface

#: a tile's model never tiles again
NO_TILING = 2**62
#: points of the strided subsample the horizontal frame is fitted to
FRAME_SAMPLE = 200_000
#: point-count grid cells along the longer side of the extent, at most
GRID_CELLS = 4096
#: points per chunk when the whole cloud is walked
CHUNK = 4_000_000
#: axis samples per metre when parts of one member are fitted as one line
FIT_SAMPLES_PER_M = 20.0
#: coplanar surfaces: normals within this angle (degrees) and offsets within this (m)
SURFACE_DEG = 5.0
SURFACE_OFFSET_M = 0.05

Mapper = Callable[..., Iterable[Any]]
Progress = Callable[[float, str], None]


@dataclass(frozen=True)
class TileFrame:
    """Horizontal frame of the tiles: ``a`` along ``axes[0]``, ``b`` along
    ``axes[1]``, both from ``origin`` (XY, input units)."""

    origin: np.ndarray
    axes: np.ndarray

    def ab(self, xyz: np.ndarray) -> np.ndarray:
        """(N, 2) frame coordinates of (N, 3) points (chunked)."""
        out = np.empty((len(xyz), 2))
        for s in range(0, len(xyz), CHUNK):
            out[s : s + CHUNK] = (xyz[s : s + CHUNK, :2] - self.origin) @ self.axes.T
        return out


@dataclass(frozen=True)
class Tile:
    """A tile: ``core`` (a0, a1, b0, b1), half-open, ±inf at the extent's
    edges; its points are those within ``overlap`` of the core."""

    index: int
    core: tuple[float, float, float, float]
    overlap: float

    @property
    def outer(self) -> tuple[float, float, float, float]:
        a0, a1, b0, b1 = self.core
        o = self.overlap
        return (a0 - o, a1 + o, b0 - o, b1 + o)

    def in_core(self, ab: np.ndarray) -> np.ndarray:
        a0, a1, b0, b1 = self.core
        a, b = ab[..., 0], ab[..., 1]
        return (a >= a0) & (a < a1) & (b >= b0) & (b < b1)

    def in_outer(self, ab: np.ndarray) -> np.ndarray:
        a0, a1, b0, b1 = self.outer
        a, b = ab[..., 0], ab[..., 1]
        return (a >= a0) & (a <= a1) & (b >= b0) & (b <= b1)

    def inner_sides(self) -> list[tuple[int, float]]:
        """The outer sides that cut the cloud: (coordinate 0 = a / 1 = b, value)."""
        a0, a1, b0, b1 = self.outer
        return [(k, v) for k, v in ((0, a0), (0, a1), (1, b0), (1, b1)) if math.isfinite(v)]


@dataclass
class TileJob:
    """What one tile's model needs: its points (input frame), which of them
    its core owns, their classification, and the parameters (spacing fixed)."""

    index: int
    points: np.ndarray
    core: np.ndarray
    classification: np.ndarray | None
    params: StructureParams


@dataclass
class TileResult:
    """A tile's model, reduced to what the merge needs: its members and
    surfaces (input frame), the labels of its core points (tile member ids
    or −1), and its stage timings."""

    index: int
    members: list[Member]
    surfaces: list[PlanarSurface]
    core_labels: np.ndarray
    n_points: int
    timings_s: dict[str, float] = field(default_factory=dict)


def horizontal_frame(points: np.ndarray) -> TileFrame:
    """The XY principal axes of a strided subsample (deterministic): ``a``
    along the longest horizontal extent, ``b`` across it."""
    step = max(1, len(points) // FRAME_SAMPLE)
    xy = np.asarray(points[::step, :2], dtype=float)
    origin = xy.mean(axis=0)
    cov = np.cov((xy - origin).T) if len(xy) > 2 else np.eye(2)
    _, vec = np.linalg.eigh(cov)
    ea = vec[:, -1]
    if ea[int(np.argmax(np.abs(ea)))] < 0:
        ea = -ea
    eb = np.array([-ea[1], ea[0]])
    return TileFrame(origin, np.array([ea, eb]))


class _CountGrid:
    """Point counts on a grid over the frame extent, with a summed-area table
    for upper bounds of the points in a rectangle."""

    def __init__(self, ab: np.ndarray, cell: float) -> None:
        self.lo = ab.min(axis=0)
        hi = ab.max(axis=0)
        self.cell = max(cell, float(np.max(hi - self.lo)) / GRID_CELLS, 1e-9)
        self.n = np.floor((hi - self.lo) / self.cell).astype(np.int64) + 1
        counts = np.zeros(int(self.n[0] * self.n[1]), dtype=np.int64)
        for s in range(0, len(ab), CHUNK):
            ij = self._cells(ab[s : s + CHUNK])
            counts += np.bincount(ij[:, 0] * self.n[1] + ij[:, 1], minlength=len(counts))
        sat = np.zeros((self.n[0] + 1, self.n[1] + 1), dtype=np.int64)
        sat[1:, 1:] = counts.reshape(self.n).cumsum(0).cumsum(1)
        self.sat = sat
        self.hi = hi

    def _cells(self, ab: np.ndarray) -> np.ndarray:
        ij = np.floor((ab - self.lo) / self.cell).astype(np.int64)
        return np.clip(ij, 0, self.n - 1)

    def count(self, rect: tuple[float, float, float, float]) -> int:
        """At least the number of points in ``rect`` (a0, a1, b0, b1)."""
        a0, a1, b0, b1 = rect
        lo = self._cells(np.array([[max(a0, self.lo[0]), max(b0, self.lo[1])]]))[0]
        hi = self._cells(np.array([[min(a1, self.hi[0]), min(b1, self.hi[1])]]))[0] + 1
        if np.any(hi <= lo) or a1 < self.lo[0] or b1 < self.lo[1]:
            return 0
        if a0 > self.hi[0] or b0 > self.hi[1]:
            return 0
        s = self.sat
        return int(s[hi[0], hi[1]] - s[lo[0], hi[1]] - s[hi[0], lo[1]] + s[lo[0], lo[1]])


def plan_tiles(ab: np.ndarray, tile_m: float, overlap_m: float, max_points: int) -> list[Tile]:
    """Tiles over the (N, 2) frame coordinates ``ab``: equal strips of about
    ``tile_m`` along ``a``, each halved across its longer core side while it
    holds more than ``max_points`` points (counted on a grid, an upper bound)
    and its core is wider than ``overlap_m``.  The cores partition the plane."""
    if len(ab) == 0:
        return [Tile(0, (-math.inf, math.inf, -math.inf, math.inf), overlap_m)]
    grid = _CountGrid(ab, min(tile_m, max(overlap_m, 1e-3)) / 8)
    lo, hi = grid.lo, grid.hi
    n_a = max(1, math.ceil(float(hi[0] - lo[0]) / tile_m))
    cuts = [float(lo[0] + k * (hi[0] - lo[0]) / n_a) for k in range(1, n_a)]
    edges = [-math.inf, *cuts, math.inf]
    min_side = max(overlap_m, tile_m / 64)
    out: list[tuple[float, float, float, float]] = []

    def split(core: tuple[float, float, float, float], depth: int) -> None:
        a0, a1, b0, b1 = core
        outer = (a0 - overlap_m, a1 + overlap_m, b0 - overlap_m, b1 + overlap_m)
        # the core's extent over the data (its unbounded sides clipped)
        ea = (max(a0, float(lo[0])), min(a1, float(hi[0])))
        eb = (max(b0, float(lo[1])), min(b1, float(hi[1])))
        wa, wb = ea[1] - ea[0], eb[1] - eb[0]
        if grid.count(outer) <= max_points or depth > 32 or max(wa, wb) <= min_side:
            out.append(core)
            return
        if wa >= wb:
            m = 0.5 * (ea[0] + ea[1])
            split((a0, m, b0, b1), depth + 1)
            split((m, a1, b0, b1), depth + 1)
        else:
            m = 0.5 * (eb[0] + eb[1])
            split((a0, a1, b0, m), depth + 1)
            split((a0, a1, m, b1), depth + 1)

    for a0, a1 in itertools.pairwise(edges):
        split((a0, a1, -math.inf, math.inf), 0)
    return [Tile(i, c, overlap_m) for i, c in enumerate(out)]


def owning_tiles(ab: np.ndarray, tiles: list[Tile]) -> np.ndarray:
    """(N,) index of the tile whose core holds each point (−1: none, which
    cannot happen for tiles from :func:`plan_tiles`)."""
    owner = np.full(len(ab), -1, dtype=np.int32)
    for s in range(0, len(ab), CHUNK):
        part = ab[s : s + CHUNK]
        view = owner[s : s + CHUNK]
        for t in tiles:
            view[t.in_core(part)] = t.index
    return owner


def model_tile(job: TileJob) -> TileResult:
    """The task each tile is: :func:`planners.structure.pipeline.model_structure`
    on its points (never tiled again), reduced to a :class:`TileResult`."""
    from planners.structure.pipeline import model_structure

    if len(job.points) < 10:
        return TileResult(job.index, [], [], np.full(int(job.core.sum()), -1, np.int32), 0)
    model = model_structure(
        job.points,
        params=replace(job.params, tile_above_points=NO_TILING),
        classification=job.classification,
    )
    return TileResult(
        job.index,
        model.members,
        model.surfaces,
        model.labels[job.core].astype(np.int32),
        len(job.points),
        dict(model.timings_s),
    )


def _jobs(
    raw: np.ndarray,
    ab: np.ndarray,
    owner: np.ndarray,
    tiles: list[Tile],
    classification: np.ndarray | None,
    params: StructureParams,
) -> Iterator[TileJob]:
    """One :class:`TileJob` per tile, made only when the mapper asks for it."""
    for t in tiles:
        idx = np.flatnonzero(t.in_outer(ab))
        yield TileJob(
            t.index,
            raw[idx],
            owner[idx] == t.index,
            None if classification is None else classification[idx],
            params,
        )


def model_structure_tiled(
    points: np.ndarray,
    *,
    params: StructureParams | None = None,
    progress: Progress | None = None,
    classification: np.ndarray | None = None,
    mapper: Mapper | None = None,
) -> StructureModel:
    """:func:`planners.structure.model_structure` of a cloud of any size in
    overlapping tiles (module docstring), each tile's model run through
    ``mapper`` (a callable like the builtin ``map``, the default; it gets
    :func:`model_tile` and an iterator of :class:`TileJob`, and must give
    their results).  Same contract as ``model_structure``."""
    prm = params or StructureParams()
    if not isinstance(prm, StructureParams):
        raise InvalidInputError(f"params must be a StructureParams, got {type(prm).__name__}")
    raw = as_points(points, "points", dims=3)
    if len(raw) < 10:
        raise EmptyInputError(f"points has {len(raw)} rows; a structure model needs at least 10")
    if classification is not None:
        classification = np.asarray(classification).reshape(-1)
        if len(classification) != len(raw):
            raise InvalidInputError(
                f"classification has {len(classification)} entries for {len(raw)} points"
            )
    timings: dict[str, float] = {}
    clock = time.perf_counter()
    spacing = prm.spacing_m if prm.spacing_m is not None else measure_spacing(raw)
    if spacing is None or not np.isfinite(spacing) or spacing <= 0:
        raise EmptyInputError("the cloud's point spacing cannot be measured (all points coincide?)")
    resolved = prm.resolve(spacing)
    tile_params = replace(prm, spacing_m=float(spacing), tile_above_points=NO_TILING)
    frame = horizontal_frame(raw)
    ab = frame.ab(raw)
    tiles = plan_tiles(ab, prm.tile_m, prm.overlap_m, prm.max_points_per_tile)
    owner = owning_tiles(ab, tiles)
    timings["tiles_plan"] = round(time.perf_counter() - clock, 4)
    if progress is not None:
        progress(0.05, f"tiles: {len(tiles)}")

    run = map if mapper is None else mapper
    local = np.full(len(raw), -1, dtype=np.int32)
    results: dict[int, TileResult] = {}
    for res in run(model_tile, _jobs(raw, ab, owner, tiles, classification, tile_params)):
        local[owner == res.index] = res.core_labels
        res.core_labels = np.zeros(0, np.int32)
        results[res.index] = res
        for k, v in res.timings_s.items():
            timings[f"tile_{k}"] = round(timings.get(f"tile_{k}", 0.0) + v, 4)
        if progress is not None:
            progress(0.05 + 0.9 * len(results) / len(tiles), f"tile {len(results)}/{len(tiles)}")
    del ab
    if len(results) != len(tiles):
        raise InternalError(f"the mapper gave {len(results)} tile results for {len(tiles)} tiles")
    clock = time.perf_counter()
    merged = merge_tiles(tiles, frame, [results[t.index] for t in tiles], float(spacing), prm)
    labels = np.full(len(raw), -1, dtype=np.int64)
    for t, lut in zip(tiles, merged.luts, strict=True):
        idx = np.flatnonzero(owner == t.index)
        labels[idx] = lut[local[idx]]  # −1 indexes the last slot, which is −1
    counts = np.bincount(labels[labels >= 0], minlength=len(merged.members))
    for m in merged.members:
        m.n_points = int(counts[m.id])
    refit_extents(raw, labels, merged.members, merged.joined)
    joints, graph = joints_and_graph(merged.members, float(spacing), merged.joined)
    timings["tiles_merge"] = round(time.perf_counter() - clock, 4)
    if progress is not None:
        progress(1.0, "tiles merged")
    used: dict[str, float] = dict(resolved.as_dict())
    used["n_tiles"] = float(len(tiles))
    return StructureModel(
        merged.members,
        joints,
        graph,
        labels,
        float(spacing),
        timings,
        used,
        merged.surfaces,
    )


# --------------------------------------------------------------------------- merge


@dataclass
class _Item:
    """A tile's member in the merge: ``axis`` clipped to the tile's core,
    ``cut`` whether each end was (it lies on a core side)."""

    tile: int
    member: Member
    axis: np.ndarray
    cut: tuple[bool, bool]


@dataclass
class MergedTiles:
    """:func:`merge_tiles`' result: members, surfaces, per tile the map from
    its member ids (and −1, the last slot) to merged ids, and the ids of the
    members joined from pieces of several tiles."""

    members: list[Member]
    surfaces: list[PlanarSurface]
    luts: list[np.ndarray]
    joined: list[int]


def _section_radius(m: Member, spacing: float) -> float:
    """A member's envelope radius from its section (as the model's refit pads it)."""
    from planners.structure.pipeline import ENVELOPE_CAP_M, NOISE_M, RADIUS_PAD_SPACINGS

    half = 0.5 * float(np.hypot(m.depth_m, m.width_m))
    return max(half + min(RADIUS_PAD_SPACINGS * spacing, ENVELOPE_CAP_M) + NOISE_M, spacing)


def _halfspaces(tile: Tile, frame: TileFrame) -> list[tuple[np.ndarray, float]]:
    """The tile core's finite sides as 3D half-spaces ``p @ w + c ≥ 0``."""
    a0, a1, b0, b1 = tile.core
    out = []
    for k, v, sign in ((0, a0, 1.0), (0, a1, -1.0), (1, b0, 1.0), (1, b1, -1.0)):
        if math.isfinite(v):
            e = frame.axes[k]
            w = sign * np.array([e[0], e[1], 0.0])
            out.append((w, sign * (-float(frame.origin @ e) - v)))
    return out


def clip_segment(seg: np.ndarray, planes: list[tuple[np.ndarray, float]]) -> np.ndarray | None:
    """The part of segment ``seg`` (2, D) inside every half-space ``p @ w + c ≥ 0``
    (Liang–Barsky), or ``None`` when it is empty."""
    t0, t1 = 0.0, 1.0
    d = seg[1] - seg[0]
    for w, c in planes:
        f0 = float(seg[0] @ w + c)
        df = float(d @ w)
        if abs(df) < 1e-15:
            if f0 < 0:
                return None
            continue
        t = -f0 / df
        if df > 0:
            t0 = max(t0, t)
        else:
            t1 = min(t1, t)
        if t1 - t0 <= 1e-9:
            return None
    return np.array([seg[0] + t0 * d, seg[0] + t1 * d])


def clip_polygon(poly: np.ndarray, planes: list[tuple[np.ndarray, float]]) -> np.ndarray:
    """Polygon ``poly`` (K, D) clipped to every half-space ``p @ w + c ≥ 0``
    (Sutherland–Hodgman); fewer than 3 vertices when nothing is left."""
    out = np.asarray(poly, float)
    for w, c in planes:
        if len(out) == 0:
            break
        f = out @ w + c
        if np.all(f >= 0):
            continue
        nxt: list[np.ndarray] = []
        for i in range(len(out)):
            p, q, fp, fq = out[i], out[(i + 1) % len(out)], f[i], f[(i + 1) % len(out)]
            if fp >= 0:
                nxt.append(p)
            if (fp >= 0) != (fq >= 0):
                nxt.append(p + (fp / (fp - fq)) * (q - p))
        out = np.array(nxt).reshape(-1, poly.shape[1])
    return out


def _area3(poly: np.ndarray) -> float:
    """Area of a planar polygon (K, 3)."""
    if len(poly) < 3:
        return 0.0
    return 0.5 * float(np.linalg.norm(np.cross(poly, np.roll(poly, -1, axis=0)).sum(axis=0)))


def _clip_face(f: Face, planes: list[tuple[np.ndarray, float]]) -> Face | None:
    """Face ``f`` with its outline clipped to ``planes`` (area and points pro rata)."""
    if not planes or len(f.boundary) < 3:
        return f
    world = f.outline()
    clipped = clip_polygon(world, planes)
    if len(clipped) < 3:
        return None
    before = _area3(world)
    share = _area3(clipped) / before if before > 0 else 1.0
    if share <= 1e-6:
        return None
    rel = clipped - f.origin
    uv = np.column_stack([rel @ f.x_axis, rel @ f.y_axis])
    return replace(
        f,
        boundary=uv,
        area_m2=float(f.area_m2 * share),
        n_points=round(f.n_points * share),
    )


def _items(tiles: list[Tile], frame: TileFrame, results: list[TileResult]) -> list[_Item]:
    """Each tile's members with their axes clipped to the tile's core (those
    outside it are left out: their labels map to −1)."""
    items: list[_Item] = []
    for t, res in zip(tiles, results, strict=True):
        planes = _halfspaces(t, frame)
        for m in res.members:
            clipped = clip_segment(m.axis, planes)
            if clipped is None:
                continue
            cut = (
                not np.array_equal(clipped[0], m.axis[0]),
                not np.array_equal(clipped[1], m.axis[1]),
            )
            items.append(_Item(t.index, m, clipped, cut))
    return items


def _join_gap(x: _Item, y: _Item, prm: StructureParams, spacing: float) -> float | None:
    """The gap between two items of different tiles that may be one member:
    collinear (``merge_angle_deg``; the shorter's ends within a section of the
    longer's line), of a similar section, with facing ends within
    ``max(0.1 m, 4 spacings)`` of which one at least was cut at a core side;
    ``None`` when they may not."""
    if x.tile == y.tile:
        return None
    dx, dy = x.axis[1] - x.axis[0], y.axis[1] - y.axis[0]
    lx, ly = float(np.linalg.norm(dx)), float(np.linalg.norm(dy))
    if lx < 1e-12 or ly < 1e-12:
        return None
    ux, uy = dx / lx, dy / ly
    if abs(float(ux @ uy)) < math.cos(math.radians(prm.merge_angle_deg)):
        return None
    mx, my = x.member, y.member
    deep = max(mx.depth_m, my.depth_m)
    off_tol = max(0.05, 3 * spacing, 0.25 * deep)
    base, other, u = (x, y, ux) if lx >= ly else (y, x, uy)
    rel = other.axis - base.axis[0]
    off = rel - np.outer(rel @ u, u)
    if float(np.max(np.linalg.norm(off, axis=1))) > off_tol:
        return None
    known = mx.profile != "unknown" and my.profile != "unknown"
    if (
        known
        and min(mx.depth_m, my.depth_m) > 0
        and abs(mx.depth_m - my.depth_m) > max(0.5 * deep, 4 * spacing, 0.05)
    ):
        return None
    gaps = np.linalg.norm(x.axis[:, None, :] - y.axis[None, :, :], axis=2)
    i, j = np.unravel_index(int(np.argmin(gaps)), gaps.shape)
    if not (x.cut[i] or y.cut[j]):
        return None
    gap = float(gaps[i, j])
    return gap if gap <= max(0.1, 4 * spacing) else None


def _groups(items: list[_Item], prm: StructureParams, spacing: float) -> list[list[int]]:
    """Union–find of joinable items, the nearest pairs first, a group holding
    at most one item of each tile (a tile's model already told its members
    apart); candidate pairs from a KD-tree of axis ends."""
    parent = list(range(len(items)))
    tiles_of: dict[int, set[int]] = {i: {it.tile} for i, it in enumerate(items)}

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    if len(items) > 1:
        ends = np.vstack([it.axis for it in items])
        own = np.repeat(np.arange(len(items)), 2)
        pairs = cKDTree(ends).query_pairs(max(0.1, 4 * spacing), output_type="ndarray")
        cand = np.unique(np.sort(own[pairs], axis=1), axis=0) if len(pairs) else np.zeros((0, 2))
        found: list[tuple[float, int, int]] = []
        for i, j in cand.astype(np.int64):
            gap = _join_gap(items[i], items[j], prm, spacing) if i != j else None
            if gap is not None:
                found.append((gap, int(i), int(j)))
        for _, i, j in sorted(found):
            ri, rj = find(i), find(j)
            if ri == rj or tiles_of[ri] & tiles_of[rj]:
                continue
            keep, gone = min(ri, rj), max(ri, rj)
            parent[gone] = keep
            tiles_of[keep] |= tiles_of.pop(gone)
    groups: dict[int, list[int]] = {}
    for i in range(len(items)):
        groups.setdefault(find(i), []).append(i)
    return [groups[k] for k in sorted(groups)]


def _fit_axis(parts: list[np.ndarray]) -> np.ndarray:
    """One axis through several collinear axes (2, 3): the principal line of
    samples along them (so each weighs by its length), spanning all their ends,
    directed as the longest."""
    samples = []
    for ax in parts:
        n = max(2, math.ceil(float(np.linalg.norm(ax[1] - ax[0])) * FIT_SAMPLES_PER_M) + 1)
        samples.append(ax[0] + np.outer(np.linspace(0, 1, n), ax[1] - ax[0]))
    pts = np.vstack(samples)
    c = pts.mean(axis=0)
    _, vec = np.linalg.eigh(np.cov((pts - c).T))
    d = vec[:, -1]
    longest = max(parts, key=lambda ax: float(np.linalg.norm(ax[1] - ax[0])))
    if float(d @ (longest[1] - longest[0])) < 0:
        d = -d
    t = np.concatenate([(ax - c) @ d for ax in parts])
    return np.array([c + float(t.min()) * d, c + float(t.max()) * d])


def _merge_surfaces(
    tiles: list[Tile], frame: TileFrame, results: list[TileResult]
) -> list[PlanarSurface]:
    """Surfaces clipped to their tile's core; coplanar ones of one kind whose
    outlines come within ``SURFACE_OFFSET_M`` joined (convex hull)."""
    clipped: list[PlanarSurface] = []
    for t, res in zip(tiles, results, strict=True):
        planes = _halfspaces(t, frame)
        for s in res.surfaces:
            poly = clip_polygon(s.outline, planes)
            before = _area3(s.outline)
            if len(poly) < 3:
                continue
            share = _area3(poly) / before if before > 0 else 1.0
            clipped.append(
                replace(
                    s,
                    outline=poly,
                    n_points=round(s.n_points * share),
                    area_m2=float(s.area_m2 * share),
                )
            )
    cos_tol = math.cos(math.radians(SURFACE_DEG))
    parent = list(range(len(clipped)))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i, si in enumerate(clipped):
        for j in range(i + 1, len(clipped)):
            sj = clipped[j]
            if si.kind != sj.kind or float(si.normal @ sj.normal) < cos_tol:
                continue
            if abs(si.offset - sj.offset) > SURFACE_OFFSET_M:
                continue
            lo_i, hi_i = si.outline.min(0), si.outline.max(0)
            lo_j, hi_j = sj.outline.min(0), sj.outline.max(0)
            if np.all(lo_i <= hi_j + SURFACE_OFFSET_M) and np.all(lo_j <= hi_i + SURFACE_OFFSET_M):
                ri, rj = find(i), find(j)
                parent[max(ri, rj)] = min(ri, rj)
    groups: dict[int, list[int]] = {}
    for i in range(len(clipped)):
        groups.setdefault(find(i), []).append(i)
    out: list[PlanarSurface] = []
    for key in sorted(groups):
        g = [clipped[i] for i in groups[key]]
        s = g[0]
        if len(g) > 1:
            pts = np.vstack([x.outline for x in g])
            n = s.normal
            ex = np.cross(n, [0.0, 0.0, 1.0] if abs(n[2]) < 0.9 else [1.0, 0.0, 0.0])
            ex /= np.linalg.norm(ex)
            ey = np.cross(n, ex)
            uv = np.column_stack([pts @ ex, pts @ ey])
            try:
                hull = pts[ConvexHull(uv).vertices]
            except Exception:  # degenerate (collinear) outlines: keep the first
                hull = s.outline
            s = replace(
                s,
                outline=hull,
                n_points=sum(x.n_points for x in g),
                area_m2=float(sum(x.area_m2 for x in g)),
            )
        out.append(replace(s, id=len(out)))
    return out


def merge_tiles(
    tiles: list[Tile],
    frame: TileFrame,
    results: list[TileResult],
    spacing: float,
    prm: StructureParams,
) -> MergedTiles:
    """The tiles' members merged into one model (module docstring, step 4)."""
    items = _items(tiles, frame, results)
    groups = _groups(items, prm, spacing)
    luts = [np.full(len(r.members) + 1, -1, dtype=np.int64) for r in results]
    pos = {t.index: k for k, t in enumerate(tiles)}
    min_len = float(prm.resolve(spacing).min_member_length_m or 0.0)
    members: list[Member] = []
    joined: list[int] = []
    face_id = 0
    for g in groups:
        parts = [items[i] for i in g]
        axis = parts[0].axis.copy() if len(parts) == 1 else _fit_axis([it.axis for it in parts])
        cut = any(any(it.cut) for it in parts)
        # a sliver of a member the next tile holds, that joined nothing
        if cut and float(np.linalg.norm(axis[1] - axis[0])) < min_len:
            continue
        new_id = len(members)
        if len(parts) > 1:
            joined.append(new_id)
        for it in parts:
            luts[pos[it.tile]][it.member.id] = new_id
        best = max(parts, key=lambda it: (float(np.linalg.norm(it.axis[1] - it.axis[0])), -it.tile))
        faces: list[Face] = []
        for it in parts:
            planes = _halfspaces(tiles[pos[it.tile]], frame) if any(it.cut) else []
            for f in it.member.faces:
                cf = _clip_face(f, planes)
                if cf is not None:
                    faces.append(replace(cf, id=face_id, member=new_id))
                    face_id += 1
        members.append(
            Member(
                new_id,
                axis,
                best.member.profile,
                best.member.depth_m,
                best.member.width_m,
                faces,
                n_points=0,
                fragments=max(it.member.fragments for it in parts),
            )
        )
    return MergedTiles(members, _merge_surfaces(tiles, frame, results), luts, joined)


def refit_extents(
    points: np.ndarray, labels: np.ndarray, members: list[Member], ids: list[int]
) -> None:
    """The extent of each member in ``ids`` (joined across tiles) along its
    axis, in place: the 0.5 and 99.5 percentiles of its points' positions
    along it, as the model's refit sets a member's ends (a piece's ends
    trimmed a tile's share of its points, not the member's)."""
    if not ids:
        return
    ids = sorted(ids)
    want = np.zeros(len(members) + 1, dtype=bool)
    want[ids] = True
    idx = np.flatnonzero(want[labels])  # −1 indexes the last slot, False
    idx = idx[np.argsort(labels[idx], kind="stable")]
    bounds = np.searchsorted(labels[idx], [*ids, len(members)])
    for k, mid in enumerate(ids):
        own = idx[bounds[k] : bounds[k + 1]]
        if len(own) < 2:
            continue
        m = members[mid]
        d = m.direction
        t = (points[own] - m.axis[0]) @ d
        lo, hi = np.percentile(t, [0.5, 99.5])
        m.axis = np.array([m.axis[0] + lo * d, m.axis[0] + hi * d])


def joints_and_graph(
    members: list[Member], spacing: float, extend: list[int]
) -> tuple[list, nx.MultiGraph]:
    """Joints and member graph of the merged members (:func:`.joints.find_joints`,
    radii from each section); the members in ``extend`` lengthened to the
    joints beyond their ends (:func:`.joints.extend_to_joints`), as the
    model does; the others were already."""
    if not members:
        return [], nx.MultiGraph()
    from planners.structure.pipeline import _joint_reach

    radii = np.array([_section_radius(m, spacing) for m in members])
    joints = find_joints(members, radii, reach=_joint_reach(spacing), side_tol=3 * spacing)
    if extend:
        extend_to_joints([members[i] for i in extend], joints)
    graph = member_graph(members, joints, end_tol=float(radii.max()))
    return joints, graph
