"""Large planar surfaces that are not members: deck soffits, slabs, walls, ground.

A concrete deck on its girders is the biggest plane in every scan from
below, and a frame's floor slabs and the ground are most of its points.
Left in, their pieces become members (a strip of soffit between two
girders is a line at a metre's scale) or are glued to them (a column's
foot takes the ground round it).  :func:`find_surfaces` finds them before
the members are looked for, and says which points lie on them.

A surface is a plane on which a square larger than the deepest section
expected (``max_section_m`` and two grid cells) fits inside the occupied
area: the in-plane occupancy of the plane's inliers is *opened* by that
square (:func:`scipy.ndimage.binary_opening`).  A member's faces are
strips at most ``max_section_m`` wide, so none of them survives; a truss's
plane or a grillage's flange plane is a lattice of such strips with
metres of air between them, and no square fits either.  A slab or a
deck's soffit is filled, apart from the shadows of the members under it.

Search (vectorised, bounded):

1. the cloud is voxelised (cell ``max(2.5 s, 0.08 m)``, grown until at most
   ``MAX_VOXELS`` cells) and each cell's normal and planarity taken from
   its ``K_NEIGHBOURS`` nearest cells (one batched eigen-decomposition);
2. up to ``MAX_ROUNDS`` rounds of RANSAC over the planar cells: each of
   ``HYPOTHESES`` seeded hypotheses (a planar cell's centroid and normal)
   counts the planar cells on it (within the cell tolerance and
   ``NORMAL_DEG``); the best is refitted twice through its inliers; its
   occupancy on an in-plane grid (edge ``GRID_SECTION_SHARE`` ×
   ``max_section_m``, at least a cell) is closed by one cell and opened by
   the square.  A plane with no patch (a truss's plane) leaves the pool;
3. the points within the point tolerance of the plane over its patches
   and their continuation (a level plane ``LEVEL_REACH`` × ``max_section_m``
   past them: a deck's overhang; a wall ``max_section_m``, over its planar
   cells only) are *on* it; then the band behind it (:func:`_behind`): up
   to ``SLAB_THICKNESS_M`` behind a deck or slab (its edge faces, strips a
   slab's thickness wide that would otherwise be members), up to
   ``max_section_m`` behind a wall (a pier's end and top faces).

Kinds: ``"ground"`` — the lowest level surface with next to nothing
below it and every level surface within ``GROUND_SAME_M`` of its plane,
or, when the caller passes a LAS ``classification``, one whose points
are mostly class 2; ``"wall"`` — a vertical one; ``"deck/slab"`` — any
other.  The ground's own points are not returned as on a surface unless
``GROUND_OUT`` (class 2 points always are).

Deterministic: every draw comes from ``numpy.random.default_rng([seed, 7919])``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.spatial import ConvexHull, QhullError, cKDTree

from planners.structure.features import QUERY_WORKERS, voxelise

#: the kinds a surface can have
SURFACE_KINDS: tuple[str, ...] = ("deck/slab", "ground", "wall")
#: voxel edge: this many spacings, at least ``MIN_CELL_M``
CELL_SPACINGS = 2.5
MIN_CELL_M = 0.08
#: cells at most (the edge grows until the cloud fits)
MAX_VOXELS = 200_000
#: neighbour cells of a cell's plane fit
K_NEIGHBOURS = 12
#: a cell is planar when (λ2 − λ3)/λ1 is at least this and its thickness
#: √λ3 at most ``THICK_CELLS`` cells
PLANARITY_MIN = 0.5
THICK_CELLS = 0.25
#: RANSAC: hypotheses a round, rounds at most, cells scored a round at most
HYPOTHESES = 128
MAX_ROUNDS = 24
SCORE_CELLS = 40_000
#: a planar cell agrees with a plane when its normal lies within this
NORMAL_DEG = 15.0
#: the square that must fit in a surface: ``max_section_m`` × this, plus a cell
SIDE_FACTOR = 1.0
#: a plane is horizontal (deck, slab, ground) / vertical (wall) within this
LEVEL_DEG = 12.0
#: a level plane goes on this many ``max_section_m`` past its patches (a
#: wall as far as one, over its planar cells only): a deck's overhang past
#: its outer girder lies beyond the girder's shadow on the soffit
LEVEL_REACH = 2.5
#: the in-plane grid of a plane's occupancy: its edge is this share of
#: ``max_section_m`` (at least the voxel's): a coarse scan's soffit far
#: from the scanners is rows with gaps, which one cell of closing fills
GRID_SECTION_SHARE = 0.2
#: concrete behind a deck's or slab's face taken with it (m): its edge faces
SLAB_THICKNESS_M = 0.4
#: a wall's: as thick as a section (thicker, its end is a surface itself)
#: — set from ``max_section_m``
#: behind a surface is the side covering at most this share of the other's
#: cells just beyond it (over its inner cells), or both when neither covers
#: more than ``BEHIND_EMPTY`` of them
BEHIND_RATIO = 0.25
BEHIND_EMPTY = 0.03
#: the lowest horizontal surface is ground when at most this share of the
#: other points over it lies below it
GROUND_BELOW_MAX = 0.02
#: horizontal surfaces within this of the ground's plane are ground (m)
GROUND_SAME_M = 0.3
#: the ground's points are left out of the member search too; False: the
#: ground is reported but searched as before (the clutter stage has always
#: dropped its pieces: its plane goes on beside them).  Left out, 16 of
#: tests/structure's pinned seeds moved (10 cm girders seen in pieces,
#: 2 cm tee diagonals): the whole cloud's sparse rows and random streams
#: change with it
GROUND_OUT = False
#: LAS classification code of ground
LAS_GROUND = 2


@dataclass
class PlanarSurface:
    """A large plane that is not a member.

    The plane is ``normal · x = offset`` (unit ``normal``; for a horizontal
    surface it points up), ``outline`` the (K, 3) convex outline of its
    points in the plane, ``kind`` one of :data:`SURFACE_KINDS`, ``n_points``
    how many points are on it (the slab's edge faces included), ``area_m2``
    the area of its occupied cells.
    """

    id: int
    kind: str
    normal: np.ndarray
    offset: float
    outline: np.ndarray
    n_points: int
    area_m2: float


def _cell_planes(centres: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit normal, planarity (λ2 − λ3)/λ1 and thickness √λ3 of each cell's
    ``k`` nearest cells (chunked batched covariances)."""
    n = len(centres)
    kk = min(k, n)
    tree = cKDTree(centres)
    normals = np.zeros((n, 3))
    planarity = np.zeros(n)
    thick = np.full(n, np.inf)
    step = 32_768
    for a in range(0, n, step):
        q = centres[a : a + step]
        _, idx = tree.query(q, k=kk, workers=QUERY_WORKERS)
        nb = centres[np.asarray(idx).reshape(len(q), kk)]
        nb = nb - nb.mean(axis=1, keepdims=True)
        cov = np.einsum("nki,nkj->nij", nb, nb) / kk
        ev, evec = np.linalg.eigh(cov)
        l1 = np.maximum(ev[:, 2], 1e-300)
        planarity[a : a + len(q)] = (ev[:, 1] - ev[:, 0]) / l1
        thick[a : a + len(q)] = np.sqrt(np.maximum(ev[:, 0], 0.0))
        normals[a : a + len(q)] = evec[:, :, 0]
    return normals, planarity, thick


def _plane_fit(p: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares plane (unit normal, offset) through points ``p``."""
    c = p.mean(axis=0)
    _, _, vt = np.linalg.svd(p - c, full_matrices=False)
    n = vt[2]
    return n, float(n @ c)


def _in_plane_axes(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors spanning the plane of normal ``n``."""
    ref = np.array([0.0, 0.0, 1.0]) if abs(n[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    e1 = np.cross(n, ref)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(n, e1)


def _oriented(n: np.ndarray, d: float) -> tuple[np.ndarray, float]:
    """The plane with its normal pointing up (or, vertical, towards +x, then +y)."""
    key = n[2] if abs(n[2]) > 1e-6 else (n[0] if abs(n[0]) > 1e-6 else n[1])
    return (n, d) if key >= 0 else (-n, -d)


@dataclass
class _Patch:
    """One surface as found: plane, in-plane grid and the points on it."""

    normal: np.ndarray
    offset: float
    e1: np.ndarray
    e2: np.ndarray
    lo: np.ndarray  # (2,) in-plane corner of the grid
    img: np.ndarray  # (H, W) bool: the patch's cells
    on: np.ndarray  # (N,) bool: the points on its face
    cell: float  # grid edge (m)
    #: the cells over which what is behind it is its own (a level plane's
    #: reach round its patches: a deck's edge past a patchy overhang)
    rim: np.ndarray

    def cells(self, p: np.ndarray) -> np.ndarray:
        """(M, 2) grid cell of points ``p`` (−1 outside the grid)."""
        return _cells_of(p, self.e1, self.e2, self.lo, self.cell, self.img.shape)


def _cells_of(
    p: np.ndarray,
    e1: np.ndarray,
    e2: np.ndarray,
    lo: np.ndarray,
    cell: float,
    shape: tuple[int, ...],
) -> np.ndarray:
    ij = np.floor((np.column_stack([p @ e1, p @ e2]) - lo) / cell).astype(np.int64)
    bad = (ij[:, 0] < 0) | (ij[:, 1] < 0) | (ij[:, 0] >= shape[0]) | (ij[:, 1] >= shape[1])
    ij[bad] = -1
    return ij


def _over(patch: _Patch, img: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Whether each point of ``p`` projects into a cell set in ``img``."""
    ij = patch.cells(p)
    out = ij[:, 0] >= 0
    out[out] = img[ij[out, 0], ij[out, 1]]
    return out


def _occupancy(
    pts_plane: np.ndarray, n: np.ndarray, cell: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """In-plane axes, grid corner and closed occupancy image of a plane's
    inlier cells ``pts_plane`` on a grid of edge ``cell``."""
    e1, e2 = _in_plane_axes(n)
    uv = np.column_stack([pts_plane @ e1, pts_plane @ e2])
    pad = 2 + int(np.ceil(max(SLAB_THICKNESS_M, 1.0) / cell)) * 3
    lo = uv.min(axis=0) - pad * cell
    ij = np.floor((uv - lo) / cell).astype(np.int64)
    shape = ij.max(axis=0) + pad + 1
    img = np.zeros(tuple(int(x) for x in shape), bool)
    img[ij[:, 0], ij[:, 1]] = True
    img = ndimage.binary_closing(img, structure=np.ones((3, 3), bool))
    return e1, e2, lo, img


def _outline(p: np.ndarray, n: np.ndarray, d: float) -> np.ndarray:
    """(K, 3) convex outline of points ``p`` projected into the plane (n, d)."""
    e1, e2 = _in_plane_axes(n)
    uv = np.column_stack([p @ e1, p @ e2])
    try:
        ring = uv[ConvexHull(uv).vertices]
    except (QhullError, ValueError):
        lo, hi = uv.min(axis=0), uv.max(axis=0)
        ring = np.array([lo, [hi[0], lo[1]], hi, [lo[0], hi[1]]])
    return ring[:, :1] * e1 + ring[:, 1:2] * e2 + d * n


def _behind(
    pts: np.ndarray,
    free: np.ndarray,
    patch: _Patch,
    tol: float,
    thickness: float,
    both: bool = True,
) -> np.ndarray:
    """The points behind a surface, up to ``thickness``, over its cells
    (which reach a cell past its points): a slab's or a wall's edge faces
    (strips the solid's thickness wide, which would otherwise be members),
    which stand on its rim.  Behind is
    the side with fewer of the ``free`` points (on no surface) just beyond
    the face over its inner cells (counted as cells covered): the concrete
    hides what is in it; both sides when neither covers more than a few
    cells (a column through a slab) and ``both``, none when both cover
    many.  A wall takes both then over its rim only (the cells two from
    its edge): a column a metre in front of its middle covers a few of its
    cells too."""
    s = pts @ patch.normal - patch.offset
    band = np.flatnonzero((np.abs(s) > tol) & (np.abs(s) <= thickness))
    inner = ndimage.binary_erosion(patch.img, structure=np.ones((3, 3), bool), iterations=2)
    n_inner = max(int(inner.sum()), 1)
    over_in = _over(patch, inner, pts[band]) & free[band]
    side = s[band]
    ij = patch.cells(pts[band[over_in]])
    flat = ij[:, 0] * patch.img.shape[1] + ij[:, 1]
    # the area each side covers (cells), not its points: a column through
    # a slab is a few cells on both sides, the beams under it many
    up = len(np.unique(flat[side[over_in] > 0]))
    down = len(np.unique(flat[side[over_in] < 0]))
    if max(up, down) <= BEHIND_EMPTY * n_inner:
        keep = np.ones(len(band), bool)
        if not both:
            # a wall: only over its rim, where its solid's end and top
            # faces stand (a pier's), not over its middle
            rim = patch.rim & ~ndimage.binary_erosion(
                patch.img, structure=np.ones((3, 3), bool), iterations=2
            )
            keep = _over(patch, rim, pts[band])
    elif min(up, down) <= BEHIND_RATIO * max(up, down):
        keep = side > 0 if up <= down else side < 0
    else:
        keep = np.zeros(len(band), bool)
    sel = band[keep & _over(patch, patch.rim, pts[band])]
    out = np.zeros(len(pts), bool)
    out[sel] = True
    return out


def find_surfaces(
    pts: np.ndarray,
    spacing: float,
    max_section_m: float,
    *,
    seed: int = 0,
    classification: np.ndarray | None = None,
) -> tuple[list[PlanarSurface], np.ndarray]:
    """The large planar surfaces of a cloud and which points lie on them.

    ``pts`` (N, 3) metres (relative coordinates: survey frames lose
    precision in the plane fits), ``spacing`` its point spacing (m),
    ``max_section_m`` the deepest member section expected: a surface holds
    a square larger than that everywhere.  ``classification`` (N,) LAS
    codes, optional: points of class 2 (ground) are on no member, and a
    surface whose points are mostly class 2 is ground.  Returns the
    surfaces (offsets in the frame of ``pts``) and a mask (N,) of the
    points to leave out of the member search: on a deck, slab or wall or
    in the band behind one, on the ground only with ``GROUND_OUT``, and
    every class 2 point.
    """
    n_pts = len(pts)
    ground_cls = None
    if classification is not None:
        ground_cls = np.asarray(classification).reshape(-1) == LAS_GROUND
    none = np.zeros(n_pts, bool) if ground_cls is None else ground_cls.copy()
    if n_pts < 100:
        return [], none
    cell = max(CELL_SPACINGS * spacing, MIN_CELL_M)
    grid = voxelise(pts, cell)
    while len(grid.centres) > MAX_VOXELS:
        cell *= 1.5
        grid = voxelise(pts, cell)
    centres = grid.centres
    if len(centres) < K_NEIGHBOURS:
        return [], none
    normals, planarity, thick = _cell_planes(centres, K_NEIGHBOURS)
    # a plane's tolerance: a cell's centroid lies on it within the noise;
    # points within a spacing and a half (at least 3 cm)
    tol_cell = max(0.35 * cell, 0.03)
    tol_pt = max(1.5 * spacing, 0.03)
    planar = (planarity >= PLANARITY_MIN) & (thick <= THICK_CELLS * cell + 0.5 * tol_cell)
    gcell = max(cell, GRID_SECTION_SHARE * max_section_m)
    k_side = int(np.ceil(SIDE_FACTOR * max_section_m / gcell)) + 2
    k_grow = int(np.ceil(max_section_m / gcell))
    min_cells = int(np.ceil(SIDE_FACTOR * max_section_m / cell)) ** 2
    cos_n = float(np.cos(np.radians(NORMAL_DEG)))
    rng = np.random.default_rng([int(seed), 7919])
    pool = planar.copy()
    found: list[_Patch] = []
    for _ in range(MAX_ROUNDS):
        idx = np.flatnonzero(pool)
        if len(idx) < min_cells:
            break
        scored = idx if len(idx) <= SCORE_CELLS else np.sort(rng.choice(idx, SCORE_CELLS, False))
        hyp = rng.choice(idx, min(HYPOTHESES, len(idx)), replace=False)
        hn = normals[hyp]
        hd = np.einsum("ij,ij->i", hn, centres[hyp])
        score = np.zeros(len(hyp), np.int64)
        for a in range(0, len(hyp), 16):
            dist = np.abs(centres[scored] @ hn[a : a + 16].T - hd[a : a + 16])
            agree = np.abs(normals[scored] @ hn[a : a + 16].T) >= cos_n
            score[a : a + 16] = ((dist <= tol_cell) & agree).sum(axis=0)
        best = int(np.argmax(score))  # the first of equals: deterministic
        if score[best] * (len(idx) / len(scored)) < min_cells:
            break
        n, d = hn[best], float(hd[best])
        inl = idx[(np.abs(centres[idx] @ n - d) <= tol_cell) & (np.abs(normals[idx] @ n) >= cos_n)]
        for _ in range(2):  # refit through the inliers
            if len(inl) < 3:
                break
            n, d = _plane_fit(centres[inl])
            inl = idx[
                (np.abs(centres[idx] @ n - d) <= tol_cell) & (np.abs(normals[idx] @ n) >= cos_n)
            ]
        # the hypothesis leaves the pool whatever it turns out to be
        pool[inl] = False
        pool[hyp[best]] = False
        if len(inl) < min_cells:
            continue
        n, d = _oriented(n, d)
        e1, e2, lo, img = _occupancy(centres[inl], n, gcell)
        opened = ndimage.binary_opening(img, structure=np.ones((k_side, k_side), bool))
        if not opened.any():
            continue
        # the plane goes on round its patches as far as a section: a
        # deck's overhang past its outer girder, a column's foot on the ground
        # (a level plane's points beyond its planar cells too: a deck's
        # overhang seen at a grazing angle is rows; a wall's only over its
        # planar cells: the girders crossing a pier's plane above it are not it)
        level = abs(n[2]) >= float(np.cos(np.radians(LEVEL_DEG)))
        region = ndimage.binary_dilation(
            opened,
            structure=np.ones((3, 3), bool),
            iterations=int(np.ceil(LEVEL_REACH * k_grow)) if level else k_grow,
        )
        if not level:
            region &= img
        region = ndimage.binary_dilation(region, structure=np.ones((3, 3), bool))
        near = np.flatnonzero(np.abs(pts @ n - d) <= tol_pt)
        ij = _cells_of(pts[near], e1, e2, lo, gcell, img.shape)
        ok = ij[:, 0] >= 0
        ok[ok] = region[ij[ok, 0], ij[ok, 1]]
        if int(ok.sum()) < min_cells:
            continue
        mask = np.zeros(n_pts, bool)
        mask[near[ok]] = True
        # the surface's cells: those its points fall in (holes closed)
        cells = np.zeros_like(img)
        cells[ij[ok, 0], ij[ok, 1]] = True
        cells = ndimage.binary_closing(cells, structure=np.ones((3, 3), bool))
        found.append(_Patch(n, d, e1, e2, lo, cells, mask, gcell, cells))
        # every cell of the plane is done, inlier or not
        pool[np.abs(centres @ n - d) <= tol_cell] = False
    if not found:
        return [], none
    return _classified(pts, found, tol_pt, ground_cls, max_section_m)


def _classified(
    pts: np.ndarray,
    found: list[_Patch],
    tol: float,
    ground_cls: np.ndarray | None,
    max_section_m: float,
) -> tuple[list[PlanarSurface], np.ndarray]:
    """Name each surface (ground, deck/slab, wall), add the band behind a
    deck's, slab's or wall's face, and collect the points on any surface."""
    cos_level = float(np.cos(np.radians(LEVEL_DEG)))
    sin_level = float(np.sin(np.radians(LEVEL_DEG)))
    on_face = np.zeros(len(pts), bool)
    for f in found:
        on_face |= f.on
    flat = [i for i, f in enumerate(found) if abs(f.normal[2]) >= cos_level]
    ground_z = None
    if ground_cls is None and flat:
        i = min(flat, key=lambda j: (found[j].offset, j))
        f = found[i]
        other = np.flatnonzero(~on_face)
        over = other[_over(f, f.img, pts[other])]
        below = pts[over] @ f.normal - f.offset < -2 * tol
        if len(over) == 0 or float(below.mean()) <= GROUND_BELOW_MAX:
            ground_z = f.offset
    kinds = []
    for i, f in enumerate(found):
        if ground_cls is not None:
            kind = "ground" if float(ground_cls[f.on].mean()) > 0.5 else ""
        else:
            # the ground's pieces (split by a pier's shadow) are ground too
            same = ground_z is not None and abs(f.offset - ground_z) <= GROUND_SAME_M
            kind = "ground" if i in flat and same else ""
        if not kind:
            kind = "wall" if abs(f.normal[2]) <= sin_level else "deck/slab"
        kinds.append(kind)
    on = np.zeros(len(pts), bool)
    for f, kind in zip(found, kinds, strict=True):
        if kind != "ground" or GROUND_OUT:
            on |= f.on
        if kind != "ground":
            thick = SLAB_THICKNESS_M if kind == "deck/slab" else max_section_m
            on |= _behind(pts, ~on_face, f, tol, thick, both=kind == "deck/slab")
    surfaces: list[PlanarSurface] = []
    for i, (f, kind) in enumerate(zip(found, kinds, strict=True)):
        surfaces.append(
            PlanarSurface(
                id=i,
                kind=kind,
                normal=f.normal.copy(),
                offset=float(f.offset),
                outline=_outline(pts[f.on], f.normal, f.offset),
                n_points=int(f.on.sum()),
                area_m2=float(f.img.sum()) * f.cell * f.cell,
            )
        )
    if ground_cls is not None:
        on |= ground_cls
    return surfaces, on
