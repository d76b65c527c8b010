"""The structure model chain: field scan → members, faces, joints, graph.

Stages (each timed in ``StructureModel.timings_s``):

1. spacing — measured (:func:`planners.pointcloud.spacing.measure_spacing`);
   every default length derives from it (:class:`.params.StructureParams`);
   surfaces — large planes that are not members (deck soffits, slabs,
   walls, ground: :mod:`.surfaces`) are found, and their points left out
   of every later stage (labelled −1);
2. features — multi-scale linearity on a voxel pyramid (:mod:`.features`);
3. lines — region growing of linear voxels, PCA lines, occlusion fragments
   and parallel faces joined (:mod:`.lines`);
4. assign — a member label per point by its nearest axis within the
   member's envelope (:mod:`.assign`); each member's axis is then refitted
   through the centre of its cross-section box (the mean of the visible
   surface is biased towards the scanner, the box centre much less), along
   the direction in which its points collapse onto the fewest section cells
   (:mod:`.direction`: a least-squares line follows where the points are);
   a member whose points hold another's steel in a few stretches (a coarse
   scan's crossing girder) is refitted once more from its own points
   (:mod:`.crowding`);
5. faces — planar faces by RANSAC in each cross-section, the profile from
   which box sides carry faces (:mod:`.faces`); points inside two envelopes
   (joint zones) go to the member one of whose faces they lie on;
6. joints and graph (:mod:`.joints`); members meeting nothing and shorter
   than ``min_free_length_m``, and members stubbier than
   ``STUBBY_SLENDERNESS`` section depths meeting fewer than two joints, are
   clutter and are dropped; on a coarse scan, deep members seen as points
   scattered over their whole section along a tube that members cross are
   added (:mod:`.scattered`, RANSAC); rows of a few points left unlabelled
   that span between two kept members are added (:mod:`.bridges`);
   members seen as collinear pieces across occlusion shadows longer than
   the refit rounds bridge are joined into one (:mod:`.chains`);
7. sections — the kept members' faces and profiles fitted again at the
   tolerance their own surface noise allows (``_fit_sections``): the
   reported section, not the one that found the member.

What is not a member (ground, slabs, vegetation, people) stays labelled −1:
it is not linear at any scale, or too short and alone.
"""

from __future__ import annotations

import hashlib
import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import networkx as nx
import numpy as np
from scipy.spatial import cKDTree

from planners.errors import EmptyInputError, InvalidInputError
from planners.pointcloud._validate import as_points
from planners.pointcloud.spacing import measure_spacing
from planners.structure.assign import assign_points, gap_filled, grow_end, relabel_by_faces
from planners.structure.bridges import (
    BRIDGE_MAX_ATTEMPTS,
    BRIDGE_MIN_FREE,
    BRIDGE_ROW_LENGTHS,
    bridging_rows,
    seed_points,
)
from planners.structure.chains import collinear_chains
from planners.structure.clutter import parallel_rows, plane_continuation
from planners.structure.crowding import uncrowded_points
from planners.structure.direction import compact_direction, hull_direction
from planners.structure.faces import (
    CrossSection,
    classify_profile,
    cross_section,
    member_faces,
    persistent_section,
    ransac_lines,
    section_box,
    surface_noise,
)
from planners.structure.features import line_features
from planners.structure.indices import points_by_label
from planners.structure.joints import extend_to_joints, find_joints, member_graph
from planners.structure.lines import (
    LineCandidate,
    candidates_from_regions,
    grow_regions,
    join_fragments,
    join_groups,
)
from planners.structure.model import Face, Member, StructureModel
from planners.structure.params import StructureParams
from planners.structure.scattered import coarse_scan, scattered_lines, tube_radius
from planners.structure.sparse import sparse_rows, walk_rows
from planners.structure.surfaces import LAS_GROUND, PlanarSurface, find_surfaces

#: fewest points a member keeps after assignment
MIN_MEMBER_POINTS = 8
#: range noise allowed around a section (m): TLS noise is 2–5 mm, photogrammetry more
NOISE_M = 0.01
#: and this many spacings (a sparse scan underestimates a section)
RADIUS_PAD_SPACINGS = 1.0
#: the slack of an envelope (that pad, and the assignment margin of 1.5
#: spacings) is at most this (m): at 10 cm spacing 2.5 spacings a round let a
#: chord's envelope grow by 25 cm, over its neighbours, and swallow them
#: (Warren at 10 cm, 10 seeds: recall / precision 0.48 / 0.62 uncapped, 0.70 /
#: 0.84 capped).  Scans finer than 3.3 cm are not affected.
ENVELOPE_CAP_M = 0.05
#: percent of a member cut off at each end before fitting its direction
MIDDLE_TRIM = 5.0
#: a core with fewer points takes its direction from all its member's
#: points, the ones shared with neighbours too (0: always from the core)
SHORT_CORE_POINTS = 12
#: a core of fewer than ``RESOLVED_POINTS`` (and at least ``HULL_MIN_POINTS``
#: to search with) takes the direction across which its middle's convex hull
#: is smallest (:func:`.direction.hull_direction`): over 20 seeds a type at
#: 10 cm, recall +0.003…+0.007 and precision +0.010…+0.032.
#: ``HULL_MIDDLE`` False searches with the ends too (Pratt precision 0.946:
#: the ends sit in joints, as for the least-squares line)
HULL_DIRECTION = True
HULL_MIN_POINTS = 8
HULL_MIDDLE = True
#: percent of a member cut off at each end before measuring its section box,
#: when at least ``SECTION_TRIM_POINTS`` points remain: the ends sit in joints,
#: where gussets and the neighbours' steel widen the box; the envelope grown
#: from a widened box takes in more of them each refit round and walks off
#: the member (a 2 m UPE 200 post at 2 cm: radius 0.11 → 0.28 m in five
#: rounds, axis 12 cm aside).  10 seeds, recall / precision before → after:
#: Pratt 2 cm 0.965 / 0.944 → 0.983 / 0.960, Warren 0.969 / 0.956 → 0.981 /
#: 0.980; Pratt 10 cm 0.517 / 0.766 → 0.572 / 0.855.  Sparse members keep the
#: whole section (trimmed, frame and grillage precision at 10 cm fell by
#: 0.05).  Measured and not kept: the direction through the trimmed halves
#: too (it finds that post at 5 mm as well, but loses 2 m UPN 300 cross
#: girders and a 9.6 m girder of the grillage at 5 mm: recall 0.873 → 0.810).
SECTION_TRIM = 15.0
SECTION_TRIM_POINTS = 150
#: a member needs this many points, and a section this many spacings deep,
#: before its faces say whether it is steel (a 10 cm scan of an 8 cm angle
#: is a row of single points)
RESOLVED_POINTS = 60
RESOLVED_SPACINGS = 4.0
#: a candidate whose largest face's plane covers this fraction of the cells
#: beside it or more is a piece of a larger surface
CONTINUATION_MAX = 0.55
#: a candidate with this fraction of the lanes beside it (in a band twice
#: the continuation's) holding plane points along ``PARALLEL_ALONG`` of its
#: length or more lies among the parallel rows of a larger surface: a
#: coarse scan's ground (:func:`~planners.structure.clutter.parallel_rows`)
PARALLEL_MAX = 0.45
PARALLEL_ALONG = 0.6
#: steel members crossing a candidate at more than this angle are not its
#: plane going on (the diagonals beside a chord, :func:`_truss_planes`)
CROSSING_DEG = 20.0
#: a candidate with fewer of its points on its faces is not steel (vegetation, rubble)
FACE_FRACTION_MIN = 0.8
#: section lines that share is counted on again when a member's faces hold
#: less: a 5 mm scan of an I-girder seen from all round has its web, flange
#: faces and edges on up to eight lines; the four faces of the grillage's
#: main and cross girders held 0.66–0.78 of their points, and they were
#: dropped as vegetation
FACE_FRACTION_LINES = 8
#: ... and only when two of those lines meet square (|cos| of their normals
#: at most this: within 20° of a right angle), as a web and its flanges or
#: an angle's legs do: a strip of rough ground is parallel lines a noise
#: apart (a 30 m strip at 5 mm held 0.91 of its points on six of them)
FACE_SQUARE_COS = 0.34
#: how far past a member's last point (beyond the neighbour's section) a joint
#: is looked for: this (m) or this many spacings, whichever is more.  0.4 m
#: made the grillage samples' person-sized boxes (0.8 m under a main girder)
#: posts of it (20 seeds at 2 cm, 0.4 m → these: Pratt precision 0.965 →
#: 0.977, grillage 0.904 → 0.933 at a recall 0.910 → 0.903; 10 cm within
#: ±0.01).  The test bridges the reach twice (the axis is extended by it,
#: then the distance allowed includes it), so a box 0.75 m under a 0.5 m
#: deep girder is still joined (a hand-built case): a per-axis test (only
#: the reach left along the extended axis) dropped grillage recall to 0.890
#: and was not kept.
JOINT_REACH_M = 0.25
JOINT_REACH_SPACINGS = 4.0
#: direction through the two halves' section centres (else least squares)
DIRECTION_FROM_HALVES = True
#: then the direction along which the member's points collapse most
#: (:mod:`.direction`), with section cells this many spacings wide
COMPACT_DIRECTION = True
COMPACT_CELL_SPACINGS = 2.0
#: and only for a section at least this many cells across
COMPACT_MIN_CELLS = 2.0
#: the section box from the cells seen along at least this share of the
#: member's stretches (each this many spacings long): diagonals' stubs are
#: seen only at the joints (:func:`.faces.persistent_section`); 0: every cell
PERSISTENT_SHARE = 0.3
PERSISTENT_BIN_SPACINGS = 5.0
#: only for members with at most this many points a stretch on average
PERSISTENT_MAX_POINTS = 20.0
#: and only when the persistent cells hold at least this share of the
#: member's points: stubs are a few percent (1–4 % of a 10 cm chord), while a
#: girder seen whole near the scanners and by one flange far from them kept
#: 30 % (an 18 m HEB 400 at 2 cm: its box shrank to the flange and the axis
#: moved 0.24 m).  20 seeds, grillage 2 cm: visible recall / precision 0.925
#: / 0.956 → 0.933 / 0.961; other types and 10 cm within ±0.01
PERSISTENT_MIN_KEPT = 0.5
#: assign → refit rounds before the final assignment: at least, at most
MIN_REFITS = 2
MAX_REFITS = 5
#: after each refit a member's ends walk over the unlabelled points that
#: continue its axis, with steps of at most this many spacings, up to
#: ``max_gap_m`` (:func:`.assign.grow_end`)
GROW_ENDS = True
GROW_STEP_SPACINGS = 3.0
#: collinear pieces up to this many ``max_gap_m`` apart are one member when
#: the stretch between them is filled (:func:`.assign.gap_filled`); 0: never
BRIDGE_GAPS = 4
#: look for sparse rows among the points no candidate explains (:mod:`.sparse`)
SPARSE_ROWS = True
#: after the last assignment, refit each member whose points hold
#: another member's steel in a few stretches from its own points
#: (:mod:`.crowding`).  20 seeds at 10 cm, visible members missed:
#: grillage 20 → 15 (rows of cross girders joined across main girders,
#: leaned by the mains' flange points), Warren 14 → 13, Pratt 8 → 6,
#: frame 7 → 6.  Only on a coarse scan, as the scattered lines (the
#: largest section's radius at most ``SCATTER_MAX_SPACINGS`` spacings): run
#: at 2 cm (margin one spacing) it lost one of the grillage's 244 visible
#: members and found none more
CROWDED_REFIT = True
#: add the rows of a few unlabelled points that span between two kept
#: members (:mod:`.bridges`).  20 seeds at 10 cm, visible recall /
#: precision: grillage 0.866 / 0.934 → 0.896 / 0.940, Pratt 0.963 / 0.963
#: → 0.977 / 0.964, Warren 0.963 / 0.967 → 0.968 / 0.962, frame unchanged;
#: at 2 cm no row changes
BRIDGE_ROWS = True
#: join the members seen as collinear pieces across occlusion shadows
#: longer than the refit rounds bridge (:mod:`.chains`), once the members
#: are all found.  20 seeds a type, visible recall / precision: grillage
#: at 10 cm 0.928 / 0.955 → 0.934 / 0.953 (a 13 m HEB 400 seen as 2.7 m
#: and 5.9 m pieces 4.2 m apart), at 2 cm 0.976 / 0.960 → 0.978 / 0.960;
#: Warren, Pratt and the frame at 10 cm and 2 cm unchanged.  Run before
#: the scattered lines and bridging rows as well, it joined nothing more
CHAIN_PIECES = True
#: add the members seen as points scattered along a section-wide tube, on
#: coarse scans (:mod:`.scattered`).  20 seeds at 10 cm: grillage visible
#: recall 0.896 → 0.899 (seed 14's inner main girder), the other types and
#: precision the same; it does not run at 2 cm or 5 mm
SCATTERED_LINES = True
#: a member stubbier than this many section depths (its length over the
#: larger of depth and width) that meets fewer than ``STUBBY_JOINTS``
#: joints is not a member between others: a person-sized box standing
#: beside the structure, or a blob of vegetation touching it, which
#: ``min_slenderness`` (2.5) lets through at 3–4.  20 seeds a type at
#: 10 cm, precision: grillage 0.857 → 0.902, frame 0.936 → 0.953, Pratt
#: 0.941 → 0.953, Warren 0.948 → 0.956; 2 cm: grillage 0.947 → 0.953,
#: Pratt 0.964 → 0.967; recall unchanged.  Dropping every stubby member
#: (no joint exemption) gained 0.006–0.021 more precision at 10 cm but
#: lost a true frame member (a short deep member between two others, as a
#: diaphragm between girders is).  0: off
STUBBY_SLENDERNESS = 3.5
STUBBY_JOINTS = 2
#: fit the kept members' faces and profile again at their own noise (``_fit_sections``)
SECTION_PASS = True
#: that tolerance in noise σ (±1.75 σ holds 92 % of a face's points)
SECTION_NOISE_TOLS = 1.75
#: find the large planes that are not members (deck soffits, slabs, walls,
#: ground: :mod:`.surfaces`) first and leave their points out of the
#: member search; False: the whole cloud is searched (the baseline)
SEPARATE_SURFACES = True
#: a member whose axis lies in a surface's plane (within this angle) with
#: this share of its points within this many of the surface's point
#: tolerances of it is a piece of the surface (:func:`_on_surface`)
ON_SURFACE_DEG = 10.0
ON_SURFACE_SHARE = 0.5
ON_SURFACE_TOLS = 2.0

Progress = Callable[[float, str], None]


def _face_kinds(profile: str, faces: list[Face], depth_axis: np.ndarray) -> None:
    """Name each face: a face whose normal lies along the depth axis is a flange
    (I, channel, tee), otherwise a web; box and tube faces are sides, a plate's is a plate."""
    for f in faces:
        if profile == "plate":
            f.kind = "plate"
        elif profile in ("I", "channel", "tee"):
            f.kind = "flange" if abs(float(f.normal @ depth_axis)) > 0.7 else "web"
        else:
            f.kind = "side"


def _direction_from_halves(cs: CrossSection, c: np.ndarray, d: np.ndarray) -> np.ndarray:
    """The direction through the section-box centres of the two halves of a
    member: a least-squares line follows where the points are (one flange
    seen at one end, the web at the other) and tilts by degrees on a short
    member; the box centres follow the section."""
    med = float(np.median(cs.t))
    halves = [cs.t < med, cs.t >= med]
    if min(int(h.sum()) for h in halves) < MIN_MEMBER_POINTS:
        return d
    vt, _, _ = section_box(cs.uv)
    ends = []
    for h in halves:
        q = cs.uv[h] @ vt.T
        lo, hi = np.percentile(q, [1, 99], axis=0)
        mid = (0.5 * (lo + hi)) @ vt
        ends.append(c + float(np.median(cs.t[h])) * d + mid[0] * cs.u + mid[1] * cs.v)
    step = ends[1] - ends[0]
    n = float(np.linalg.norm(step))
    if n < 1e-9:
        return d
    new = step / n
    # keep the sign convention of fit_line
    return new if float(new @ d) >= 0 else -new


def _inner(t: np.ndarray) -> np.ndarray | None:
    """The points of a member away from its ends (``SECTION_TRIM``), or ``None``
    when too few would remain (``SECTION_TRIM_POINTS``)."""
    if SECTION_TRIM <= 0:
        return None
    lo, hi = np.percentile(t, [SECTION_TRIM, 100 - SECTION_TRIM])
    inner = (t >= lo) & (t <= hi)
    return inner if int(inner.sum()) >= SECTION_TRIM_POINTS else None


def _persistent(uv: np.ndarray, t: np.ndarray, cell: float, spacing: float) -> np.ndarray:
    """Mask of the section points in persistent cells (all when ``PERSISTENT_SHARE`` is 0)."""
    if PERSISTENT_SHARE <= 0:
        return np.ones(len(uv), bool)
    stretch = PERSISTENT_BIN_SPACINGS * max(spacing, NOISE_M)
    return persistent_section(
        uv, t, cell, stretch, PERSISTENT_SHARE, PERSISTENT_MAX_POINTS, PERSISTENT_MIN_KEPT
    )


def _refit(
    core: np.ndarray, points: np.ndarray, spacing: float
) -> tuple[np.ndarray, np.ndarray, float, float, float] | None:
    """Axis through the cross-section box centre of ``core``, extent of
    ``points``: centre, direction, t-range, radius."""
    from planners.structure.lines import fit_line

    # under a dozen core points, the shared ones too: a 10 cm scan of a
    # channel post is 17 points with 0.2 m of scatter across; its core
    # shrank to the middle 10 over 0.57 m as the chords took its ends, and
    # their line leaned 11° (Pratt seed 12), more than a joint's pull
    src = core if len(core) >= SHORT_CORE_POINTS else points
    c, d, _, _, _ = fit_line(src)
    # the direction again from the middle 90 %: the ends sit in joints, where
    # the neighbour's steel pulls a least-squares line
    t = (src - c) @ d
    lo, hi = np.percentile(t, [MIDDLE_TRIM, 100 - MIDDLE_TRIM])
    middle = src[(t >= lo) & (t <= hi)]
    if len(middle) >= MIN_MEMBER_POINTS:
        c, d, _, _, _ = fit_line(middle)
    if HULL_DIRECTION and len(core) < RESOLVED_POINTS and len(src) >= HULL_MIN_POINTS:
        hsrc = middle if HULL_MIDDLE and len(middle) >= HULL_MIN_POINTS else src
        d = hull_direction(hsrc, d)
    cs = cross_section(core, c, d)
    if len(cs.uv) < 3:
        return None
    cell = COMPACT_CELL_SPACINGS * max(spacing, NOISE_M)
    # a few dozen points (a 10 cm scan of a small section) give a surer
    # direction by least squares than through two halves' boxes
    if DIRECTION_FROM_HALVES and len(core) >= RESOLVED_POINTS:
        # the halves' boxes from the persistent section too: a column's base
        # plate at one end moved its lower box and tilted it by 6°
        keep = _persistent(cs.uv, cs.t, cell, spacing)
        half_cs = CrossSection(cs.centre, cs.direction, cs.u, cs.v, cs.t[keep], cs.uv[keep])
        d = _direction_from_halves(half_cs, c, d)
        cs = cross_section(core, c, d)
    if COMPACT_DIRECTION and len(core) >= RESOLVED_POINTS:
        inner = _inner(cs.t)
        part = cs.uv if inner is None else cs.uv[inner]
        _, _, box = section_box(part)
        # a section a few cells across cannot tell a tilt from its own shape
        if float(np.max(box[1] - box[0])) >= COMPACT_MIN_CELLS * cell:
            d2 = compact_direction(core if inner is None else core[inner], d, cell)
            if not np.array_equal(d2, d):
                d = d2
                cs = cross_section(core, c, d)
    inner = _inner(cs.t)
    uv = cs.uv if inner is None else cs.uv[inner]
    uv = uv[_persistent(uv, cs.t if inner is None else cs.t[inner], cell, spacing)]
    vt, mu, box = section_box(uv)
    mid2 = mu + (0.5 * (box[0] + box[1])) @ vt
    centre = c + mid2[0] * cs.u + mid2[1] * cs.v
    t0, t1 = np.percentile((points - centre) @ d, [0.5, 99.5])
    half_diag = 0.5 * float(np.hypot(*(box[1] - box[0])))
    pad = min(RADIUS_PAD_SPACINGS * spacing, ENVELOPE_CAP_M)
    return centre, d, float(t0), float(t1), half_diag + pad + NOISE_M


def model_structure(
    points: np.ndarray,
    *,
    params: StructureParams | None = None,
    progress: Progress | None = None,
    classification: np.ndarray | None = None,
    mapper: Callable[..., Any] | None = None,
) -> StructureModel:
    """Members, faces, joints and member graph of a scanned steel structure.

    ``points`` (N, 3), any frame, metres (convert millimetre scans first).
    ``classification`` (N,), optional: the scan's LAS classification codes;
    class 2 (ground) points are on no member and name a ground surface.
    Raises :class:`planners.errors.InvalidInputError` for a malformed cloud
    and :class:`planners.errors.EmptyInputError` for one too small to measure.
    A cloud with no member in it gives a model with no members (not an error).

    A cloud of more than ``params.tile_above_points`` points is modelled in
    overlapping tiles (:func:`planners.structure.tiles.model_structure_tiled`),
    each tile's model run through ``mapper`` (a callable like the builtin
    ``map``, the default: a process pool's or a Dask cluster's map runs the
    tiles in parallel).  Smaller clouds are modelled whole and ``mapper`` is
    not used.
    """
    prm = params or StructureParams()
    if not isinstance(prm, StructureParams):
        raise InvalidInputError(f"params must be a StructureParams, got {type(prm).__name__}")
    raw = as_points(points, "points", dims=3)
    if len(raw) < 10:
        raise EmptyInputError(f"points has {len(raw)} rows; a structure model needs at least 10")
    if len(raw) > prm.tile_above_points:
        from planners.structure.tiles import model_structure_tiled

        return model_structure_tiled(
            raw, params=prm, progress=progress, classification=classification, mapper=mapper
        )
    timings: dict[str, float] = {}
    clock = time.perf_counter()

    def stage(name: str, fraction: float) -> None:
        nonlocal clock
        now = time.perf_counter()
        timings[name] = round(now - clock, 4)
        clock = now
        if progress is not None:
            progress(fraction, name)

    # survey coordinates (1e5–1e6 m) lose precision in squared sums: work relative
    origin = raw.min(axis=0)
    pts = raw - origin
    spacing = prm.spacing_m if prm.spacing_m is not None else measure_spacing(pts)
    if spacing is None or not np.isfinite(spacing) or spacing <= 0:
        raise EmptyInputError("the cloud's point spacing cannot be measured (all points coincide?)")
    prm = prm.resolve(spacing)
    assert prm.scales_m is not None and prm.min_member_length_m is not None
    stage("spacing", 0.05)

    if classification is not None:
        classification = np.asarray(classification).reshape(-1)
        if len(classification) != len(raw):
            raise InvalidInputError(
                f"classification has {len(classification)} entries for {len(raw)} points"
            )
    surfaces: list[PlanarSurface] = []
    n_all = len(pts)
    kept = np.arange(n_all)
    on: np.ndarray | None = None
    if SEPARATE_SURFACES:
        surfaces, on = find_surfaces(
            pts, spacing, prm.max_section_m, seed=prm.seed, classification=classification
        )
    elif classification is not None:
        on = np.asarray(classification == LAS_GROUND, dtype=bool)
    if on is not None:
        kept = np.flatnonzero(~on)
        pts = pts[kept]
    stage("surfaces", 0.1)
    if len(pts) < 10:
        return StructureModel(
            [],
            [],
            nx.MultiGraph(),
            np.full(n_all, -1, dtype=np.int64),
            float(spacing),
            timings,
            prm.as_dict(),
            _to_frame(surfaces, origin),
        )

    feat = line_features(pts, spacing, prm.scales_m, prm.k_neighbours, prm.max_voxels)
    stage("features", 0.35)

    region = grow_regions(
        feat,
        prm.linearity_min,
        prm.link_angle_deg,
        np.ones(len(feat.linearity), bool),
        spacing,
    )
    cands = candidates_from_regions(
        feat, region, prm.min_member_length_m, prm.link_angle_deg, prm.seed
    )
    cands = join_fragments(
        cands, feat, prm.merge_angle_deg, prm.max_gap_m, prm.max_section_m, prm.link_angle_deg
    )
    stage("lines", 0.5)

    tree = cKDTree(pts)
    if SPARSE_ROWS:
        # rows the features could not see, among the points no candidate's
        # envelope holds; they are refitted and joined with the rest
        free = np.ones(len(pts), bool)
        if cands:
            lines = [replace(c, radius=max(c.radius, spacing)) for c in cands]
            margin = min(1.5 * spacing, ENVELOPE_CAP_M)
            free = assign_points(pts, *_arrays(lines), margin, tree)[0] < 0
        cands = cands + sparse_rows(pts, free, spacing, prm.min_member_length_m)
    labels, shared, members, radii = _assign_and_refit(pts, cands, spacing, prm, tree)
    stage("assign", 0.7)

    rng = np.random.default_rng(prm.seed)
    tol = max(1.5 * spacing, 0.004)
    _fit_faces(pts, labels, members, spacing, tol, rng)
    # joint zones: a point inside two envelopes belongs to the member it lies
    # on a face of; the members' sections are then measured again without
    # the points they had borrowed
    faces = [f for m in members for f in m.faces]
    # a face runs the member's whole length, but its points stop where the
    # joint's points were given to the neighbour: lengthen it by the section
    reach = np.array([radii[f.member] for f in faces]) if faces else None
    # a member with no face (a 10 cm scan of an angle: a row of single
    # points) keeps the joint points it was assigned: given to the chord
    # whose face they are near (within 2 × 1.5 spacings), a 1.7 m diagonal
    # lost 10 of its 17 points and was dropped
    faceless = np.array([not m.faces for m in members] + [False])
    movable = shared & ~faceless[labels]  # −1 indexes the last slot
    relabelled = relabel_by_faces(pts, labels, movable, faces, 2 * tol, reach)
    if np.any(relabelled != labels):
        labels = relabelled
        _fit_faces(pts, labels, members, spacing, tol, rng)
    stage("faces", 0.85)

    # pieces of larger planes (ground, slabs, walls) and of things that are
    # not a few planes (vegetation) are not members
    not_clutter: list[Member] = []
    plane_like: list[tuple[Member, Face, float, float]] = []
    for m in members:
        if m.n_points < MIN_MEMBER_POINTS:  # its points all went to neighbours
            continue
        big = max(m.faces, key=lambda f: f.n_points, default=None)
        band = max(1.0, 2.0 * m.width_m, 10 * spacing)
        cell = max(3.0 * spacing, band / 6.0)
        on_faces = sum(f.n_points for f in m.faces) / max(m.n_points, 1)
        resolved = m.n_points >= RESOLVED_POINTS and m.depth_m >= RESOLVED_SPACINGS * spacing
        # steel is a few planes (or a tube); vegetation and rubble are not
        if (
            resolved
            and m.profile != "tube"
            and on_faces < FACE_FRACTION_MIN
            and _planar_share(pts[labels == m.id], m, tol, prm.seed) < FACE_FRACTION_MIN
        ):
            continue
        if m.length_m < prm.min_slenderness * max(m.depth_m, m.width_m):
            continue
        if big is None:
            not_clutter.append(m)
            continue
        own = labels == m.id
        if not _surface(tree, pts, big, band, 2 * tol, cell, own):
            not_clutter.append(m)
        else:
            plane_like.append((m, big, band, cell))
    not_clutter += _truss_planes(tree, pts, labels, members, not_clutter, plane_like, 2 * tol)
    not_clutter = [
        m for m in not_clutter if not _on_surface(pts[labels == m.id], m, surfaces, spacing)
    ]
    not_clutter.sort(key=lambda m: m.id)
    if len(not_clutter) < len(members):
        labels, members, radii, _ = _renumber(labels, members, radii, not_clutter, spacing)
    stage("clutter", 0.9)

    joints = find_joints(
        members,
        radii,
        reach=_joint_reach(spacing),
        side_tol=3 * spacing,
    )
    n_joints = np.bincount(
        np.array([mid for j in joints for mid in j.members], dtype=np.int64), minlength=len(members)
    )
    free_length = float(prm.min_free_length_m or 0.0)
    keep = [
        m
        for m in members
        if (n_joints[m.id] > 0 or m.length_m >= free_length or len(members) == 1)
        and not (
            STUBBY_SLENDERNESS
            and m.length_m < STUBBY_SLENDERNESS * max(m.depth_m, m.width_m)
            and n_joints[m.id] < STUBBY_JOINTS
        )
    ]
    if len(keep) < len(members):
        labels, members, radii, joints = _renumber(labels, members, radii, keep, spacing)
    labels, members, radii, joints = _add_members(pts, labels, members, radii, joints, spacing, prm)
    chained = _join_chains(pts, labels, members, radii, spacing, prm) if CHAIN_PIECES else None
    if chained is not None:
        labels, members, radii, joints = chained
    extend_to_joints(members, joints)
    graph = member_graph(members, joints, end_tol=float(radii.max()) if len(radii) else 0.0)
    stage("graph", 0.95)
    if SECTION_PASS:
        _fit_sections(pts, labels, members, spacing, tol, prm.seed)
    stage("sections", 1.0)

    for m in members:
        m.axis = m.axis + origin
        for f in m.faces:
            f.origin = f.origin + origin
    for j in joints:
        j.pos = j.pos + origin
    for _, data in graph.nodes(data=True):
        data["pos"] = data["pos"] + origin
    used = prm.as_dict()
    if len(kept) < n_all:
        full = np.full(n_all, -1, dtype=np.int64)
        full[kept] = labels
        labels = full
    return StructureModel(
        members,
        joints,
        graph,
        labels,
        float(spacing),
        timings,
        used,
        _to_frame(surfaces, origin),
    )


def _to_frame(surfaces: list[PlanarSurface], origin: np.ndarray) -> list[PlanarSurface]:
    """The surfaces moved from the working frame (relative to ``origin``) to the input's."""
    for f in surfaces:
        f.offset = float(f.offset + f.normal @ origin)
        f.outline = f.outline + origin
    return surfaces


def _on_surface(mp: np.ndarray, m: Member, surfaces: list[PlanarSurface], spacing: float) -> bool:
    """Whether member ``m`` (points ``mp``) is a piece of a surface's plane
    that the surface search left (rows of ground far from the scanners, a
    strip of soffit in a girder's shadow): its axis lies in the plane
    (``ON_SURFACE_DEG``) and ``ON_SURFACE_SHARE`` of its points within
    ``ON_SURFACE_TOLS`` of the surface's point tolerance of it.  A beam
    under a slab has only its top flange's edges there."""
    if not surfaces or len(mp) == 0:
        return False
    tol = ON_SURFACE_TOLS * max(1.5 * spacing, 0.03)
    sin_in = float(np.sin(np.radians(ON_SURFACE_DEG)))
    for f in surfaces:
        if abs(float(m.direction @ f.normal)) > sin_in:
            continue
        if float(np.mean(np.abs(mp @ f.normal - f.offset) <= tol)) >= ON_SURFACE_SHARE:
            return True
    return False


def _truss_planes(
    tree: cKDTree,
    pts: np.ndarray,
    labels: np.ndarray,
    members: list[Member],
    steel: list[Member],
    plane_like: list[tuple[Member, Face, float, float]],
    tol: float,
) -> list[Member]:
    """The plane-like candidates whose plane is made of steel members
    crossing them: a chord's face lies in its truss's plane, and at coarse
    spacing the diagonals (one a metre) fill the cells beside it, or the
    lanes beside it in pieces a cell apart (Warren and Pratt at 10 cm lost
    both chords so).  Both tests of :func:`_surface` are measured again
    without the points of the members kept as steel that cross it at more
    than ``CROSSING_DEG``; pieces of ground cross each other too, but none
    of them was kept, so their plane still goes on."""
    if not plane_like or not steel:
        return []
    dirs = np.array([m.direction for m in members])
    is_steel = np.zeros(len(members) + 1, bool)  # the last slot answers label −1
    is_steel[[m.id for m in steel]] = True
    cos_cross = float(np.cos(np.radians(CROSSING_DEG)))
    out = []
    for m, face, band, cell in plane_like:
        crossing = np.append(np.abs(dirs @ m.direction) < cos_cross, False) & is_steel
        own = (labels == m.id) | crossing[labels]
        if not _surface(tree, pts, face, band, tol, cell, own):
            out.append(m)
    return out


def _surface(
    tree: cKDTree,
    pts: np.ndarray,
    face: Face,
    band: float,
    tol: float,
    cell: float,
    own: np.ndarray,
) -> bool:
    """Whether ``face``'s plane goes on beside it, not counting ``own``:
    cells covered beside it (ground, slabs) or parallel rows in a band
    twice as wide (a coarse scan's ground)."""
    if plane_continuation(tree, pts, face, band, tol, cell, own) >= CONTINUATION_MAX:
        return True
    rows = parallel_rows(tree, pts, face, 2 * band, tol, cell, own, PARALLEL_ALONG)
    return rows >= PARALLEL_MAX


def _assign_and_refit(
    pts: np.ndarray,
    cands: list[LineCandidate],
    spacing: float,
    prm: StructureParams,
    tree: cKDTree,
) -> tuple[np.ndarray, np.ndarray, list[Member], np.ndarray]:
    """Labels per point and the members with refitted axes.

    ``MIN_REFITS`` to ``MAX_REFITS`` rounds of: assign the points, refit every axis from its
    points, join refitted lines that are collinear across a gap or side by
    side (short candidates' directions are too uncertain for the first join
    to catch every occlusion fragment), then a final assignment."""
    none = np.full(len(pts), -1, dtype=np.int64)
    if not cands:
        return none, np.zeros(len(pts), bool), [], np.zeros(0)
    lines = [
        LineCandidate(
            np.zeros(0, np.int64),
            c.centre,
            c.direction,
            c.t0,
            c.t1,
            max(c.radius, spacing),
            c.fragments,
        )
        for c in cands
    ]
    min_len = float(prm.min_member_length_m or 0.0)
    margin = min(1.5 * spacing, ENVELOPE_CAP_M)
    shared = np.zeros(len(pts), bool)
    for round_ in range(MAX_REFITS):
        before = _arrays(lines)[4]
        labels, shared = assign_points(pts, *_arrays(lines), margin, tree)
        unlabelled = labels < 0

        def bridge(
            a: LineCandidate,
            b: LineCandidate,
            t_from: float,
            t_to: float,
            unlabelled: np.ndarray = unlabelled,
        ) -> bool:
            radius = max(a.radius, b.radius)
            return gap_filled(
                pts, tree, unlabelled, a.centre, a.direction, t_from, t_to, radius, prm.max_gap_m
            )

        groups = join_groups(
            lines,
            prm.merge_angle_deg,
            prm.max_gap_m,
            prm.max_section_m,
            prm.link_angle_deg,
            bridge if BRIDGE_GAPS else None,
            BRIDGE_GAPS * prm.max_gap_m,
        )
        refitted: list[LineCandidate] = []
        by_label = points_by_label(labels, len(lines))
        for group in groups:
            mine = np.sort(np.concatenate([by_label[g] for g in group]))
            core = mine[~shared[mine]]
            # the section from the points no other member competes for; the
            # extent from all, so that members reach into their joints
            if len(core) < MIN_MEMBER_POINTS:
                continue
            fit = _refit(pts[core], pts[mine], spacing)
            if fit is None or fit[3] - fit[2] < min_len:
                continue
            c, d, t0, t1, rad = fit
            if GROW_ENDS:
                free = unlabelled.copy()
                free[mine] = True
                step = GROW_STEP_SPACINGS * spacing
                t1 += grow_end(pts, tree, free, c, d, t1, 1.0, rad, step, prm.max_gap_m)
                t0 -= grow_end(pts, tree, free, c, d, t0, -1.0, rad, step, prm.max_gap_m)
            frags = sum(lines[i].fragments for i in group)
            refitted.append(
                LineCandidate(
                    np.zeros(0, np.int64), c, d, t0, t1, min(rad, prm.max_section_m), frags
                )
            )
        lines = refitted
        if not lines:
            return none, shared, [], np.zeros(0)
        # a candidate's first radius is that of the voxels that looked linear
        # (often one face or edge); each round widens it towards the whole
        # section: stop once the envelopes hold still
        after = _arrays(lines)[4]
        if (
            round_ + 1 >= MIN_REFITS
            and len(after) == len(before)
            and np.all(np.abs(after - before) <= 0.1 * before)
        ):
            break
    labels, shared = assign_points(pts, *_arrays(lines), margin, tree)
    coarse = coarse_scan(spacing, prm.max_section_m)
    if CROWDED_REFIT and coarse and _refit_uncrowded(pts, labels, shared, lines, spacing):
        labels, shared = assign_points(pts, *_arrays(lines), margin, tree)
    members = [
        Member(
            id=i,
            axis=ln.ends,
            profile="unknown",
            depth_m=0.0,
            width_m=0.0,
            n_points=int((labels == i).sum()),
            fragments=ln.fragments,
        )
        for i, ln in enumerate(lines)
    ]
    return labels, shared, members, np.array([ln.radius for ln in lines])


def _refit_uncrowded(
    pts: np.ndarray,
    labels: np.ndarray,
    shared: np.ndarray,
    lines: list[LineCandidate],
    spacing: float,
) -> bool:
    """Refit, in place, each line whose points hold crowded stretches
    (:func:`.crowding.uncrowded_points`) from its own points only, keeping
    its radius; whether any line changed."""
    changed = False
    for i, ln in enumerate(lines):
        mine = labels == i
        idx = np.flatnonzero(mine & ~shared)
        keep = uncrowded_points(pts[idx], spacing)
        if keep is None:
            continue
        fit = _refit(pts[idx[keep]], pts[mine], spacing)
        if fit is None:
            continue
        c, d, t0, t1, _ = fit
        lines[i] = LineCandidate(np.zeros(0, np.int64), c, d, t0, t1, ln.radius, ln.fragments)
        changed = True
    return changed


def _joint_reach(spacing: float) -> float:
    """How far past a member's last point its joints are looked for."""
    return max(JOINT_REACH_SPACINGS * spacing, JOINT_REACH_M)


def _add_members(
    pts: np.ndarray,
    labels: np.ndarray,
    members: list[Member],
    radii: np.ndarray,
    joints: list,
    spacing: float,
    prm: StructureParams,
) -> tuple[np.ndarray, list[Member], np.ndarray, list]:
    """The members the line features missed added, and the joints found
    again once if any was: on a coarse scan those seen as points scattered along a
    section-wide tube (:mod:`.scattered`), then those seen as a few
    unlabelled points between two members (:mod:`.bridges`)."""
    reach = _joint_reach(spacing)
    added = False
    if SCATTERED_LINES:
        found = scattered_lines(
            pts,
            labels < 0,
            members,
            radii,
            spacing,
            prm.max_section_m,
            prm.max_gap_m,
            reach,
            prm.seed,
        )
        new = [(line.axis, line.points, line.radius) for line in found]
        labels, radii = _with_members(labels, members, radii, new)
        added = bool(new)
    if BRIDGE_ROWS:
        new = _bridge_rows(pts, labels, members, radii, spacing, prm, reach)
        labels, radii = _with_members(labels, members, radii, new)
        added = added or bool(new)
    if added:
        # once, for the members as they end up: the rows do not use joints
        joints = find_joints(members, radii, reach=reach, side_tol=3 * spacing)
    return labels, members, radii, joints


def _join_chains(
    pts: np.ndarray,
    labels: np.ndarray,
    members: list[Member],
    radii: np.ndarray,
    spacing: float,
    prm: StructureParams,
) -> tuple[np.ndarray, list[Member], np.ndarray, list] | None:
    """Members seen in collinear pieces across occlusion shadows joined
    into one (:mod:`.chains`): labels, members, radii and joints found
    again, or ``None`` when no pieces are joined."""
    chains = collinear_chains(pts, labels, members, radii, prm.merge_angle_deg, prm.max_gap_m)
    if not chains:
        return None
    radii = radii.copy()
    # the last slot answers label −1
    into = np.append(np.arange(len(members), dtype=np.int64), -1)
    for group, axis in chains:
        first = members[group[0]]
        into[group] = first.id
        first.axis = axis
        first.fragments = sum(members[j].fragments for j in group)
        radii[first.id] = max(float(radii[j]) for j in group)
    labels = into[labels]
    counts = np.bincount(labels[labels >= 0], minlength=len(members))
    for group, _ in chains:
        members[group[0]].n_points = int(counts[group[0]])
    keep = [m for m in members if into[m.id] == m.id]
    return _renumber(labels, members, radii, keep, spacing)


def _bridge_rows(
    pts: np.ndarray,
    labels: np.ndarray,
    members: list[Member],
    radii: np.ndarray,
    spacing: float,
    prm: StructureParams,
    reach: float,
) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """The rows of a few unlabelled points between two members
    (:mod:`.bridges`): axis, point indices and radius of each."""
    free = labels < 0
    min_len = float(prm.min_member_length_m or 0.0)
    # the points left free now, walked again: the first walk saw other free
    # points (before the refits, joins and clutter tests).  On a coarse scan
    # a row need not be a member's length: a member there can be seen as a
    # handful of points over part of it, it runs between its supports, and
    # that span is what is held to the shortest member's length.  On a finer
    # one a member is hundreds of points, and a short row a fragment of
    # anything (20 seeds at 2 cm: grillage precision 0.960 → 0.946 with
    # short rows there too, recall the same)
    coarse = coarse_scan(spacing, prm.max_section_m)
    rows = walk_rows(
        pts,
        free,
        spacing,
        (BRIDGE_ROW_LENGTHS if coarse else 1.0) * min_len,
        BRIDGE_MIN_FREE,
        BRIDGE_MAX_ATTEMPTS,
        seeds=seed_points(pts, free, spacing),
    )
    bridges = bridging_rows(
        pts,
        free,
        rows,
        members,
        radii,
        spacing,
        min_len,
        reach,
        # a girder seen by one flange measures that flange's radius, not its
        # section's: the rows' ends are let come as near as the largest
        # section expected (20 seeds at 10 cm: grillage visible recall
        # 0.899 → 0.904, the other types and precision the same)
        min_radius=tube_radius(prm.max_section_m),
        # on a coarse scan, a cross girder seen only by the half near one
        # girder, the rest in its shadow, reaches the other as far as a
        # shadow the model bridges along a member.  On a finer one such a
        # member is found by its line features, and what is left in rows is
        # not one (20 seeds at 5 mm: a 60-point row of grillage seed 0
        # reached a girder 2 m away, a false member)
        gap_reach=prm.max_gap_m if coarse else 0.0,
        held=labels,
    )
    # a handful of points: the sections stage calls them ``unknown``
    return [(b.axis, b.points, b.radius) for b in bridges]


def _with_members(
    labels: np.ndarray,
    members: list[Member],
    radii: np.ndarray,
    new: list[tuple[np.ndarray, np.ndarray, float]],
) -> tuple[np.ndarray, np.ndarray]:
    """``new`` members (axis, point indices, radius) appended to ``members``
    (in place): the labels and radii with them.  Their sections are fitted
    in the sections stage."""
    if not new:
        return labels, radii
    labels = labels.copy()
    for axis, points, _ in new:
        labels[points] = len(members)
        members.append(Member(len(members), axis, "unknown", 0.0, 0.0, n_points=len(points)))
    return labels, np.concatenate([radii, [r for _, _, r in new]])


def _arrays(
    lines: list[LineCandidate],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    return (
        np.array([ln.centre for ln in lines]),
        np.array([ln.direction for ln in lines]),
        np.array([ln.t0 for ln in lines]),
        np.array([ln.t1 for ln in lines]),
        np.array([ln.radius for ln in lines]),
    )


def _fit_faces(
    pts: np.ndarray,
    labels: np.ndarray,
    members: list[Member],
    spacing: float,
    tol: float,
    rng: np.random.Generator,
) -> None:
    """Faces, profile, depth and width of every member from its labelled points."""
    face_id = 0
    for m in members:
        mp = pts[labels == m.id]
        m.n_points = len(mp)
        face_id += _fit_section(m, mp, face_id, spacing, tol, rng, band=None)


def _fit_section(
    m: Member,
    mp: np.ndarray,
    first_face_id: int,
    spacing: float,
    tol: float,
    rng: np.random.Generator,
    band: float | None,
) -> int:
    """Set ``m``'s faces (RANSAC at ``tol``), profile, depth and width from
    its points ``mp``; ``band`` as :func:`.faces.classify_profile` takes it
    (a measured band also leaves a tube without faces).  Returns the number
    of faces."""
    cs = cross_section(mp, m.axis[0], m.direction)
    faces = member_faces(cs, m.id, first_face_id, tol, _min_face_inliers(len(mp)), rng)
    profile, depth, width, axis2 = classify_profile(cs.uv, faces, cs, spacing, band=band)
    if band is not None and profile == "tube":
        # lines RANSAC finds on an arc are chords, not surfaces a foot or a
        # blast disc can use
        faces = []
    _face_kinds(profile, faces, axis2[0] * cs.u + axis2[1] * cs.v)
    m.profile, m.depth_m, m.width_m, m.faces = profile, depth, width, faces
    return len(faces)


def _min_face_inliers(n: int) -> int:
    """Inliers a face of a member of ``n`` points needs at least."""
    return max(12, n // 20)


def _planar_share(mp: np.ndarray, m: Member, tol: float, seed: int) -> float:
    """Share of a member's points ``mp`` on up to ``FACE_FRACTION_LINES``
    RANSAC lines of its cross-section (:func:`.faces.ransac_lines` at
    ``tol``, the inlier floor of its faces' fit), or 0 when no two of them
    meet square (``FACE_SQUARE_COS``).  Its own random stream (seeded by
    ``seed`` and its points), so no other member moves it."""
    if len(mp) == 0:
        return 0.0
    cs = cross_section(mp, m.axis[0], m.direction)
    rng = np.random.default_rng([seed, _points_key(mp)])
    lines = ransac_lines(cs.uv, tol, _min_face_inliers(len(mp)), FACE_FRACTION_LINES, rng)
    if len(lines) < 2:
        return 0.0
    normals = np.array([n for n, _, _ in lines])
    if float(np.abs(normals @ normals.T).min()) > FACE_SQUARE_COS:
        return 0.0
    on = np.zeros(len(mp), bool)
    for _, _, inl in lines:
        on |= inl
    return float(on.mean())


def _fit_sections(
    pts: np.ndarray,
    labels: np.ndarray,
    members: list[Member],
    spacing: float,
    tol: float,
    seed: int,
) -> None:
    """The reported faces and profile of every kept member, fitted again
    with a tolerance from its own surface noise (``SECTION_NOISE_TOLS`` ×
    :func:`.faces.surface_noise`, between 4 mm and the first passes'
    ``tol``).  The first passes' tolerance of 1.5 spacings is what finding
    and keeping members needs (a face must hold its points at any spacing);
    at 2 cm it is a band 6 cm wide, across which one line takes both legs of
    an angle (a 146 mm "face" on an L 100: the ARA's 120 mm foot was found
    to fit) and a tube's arc.  A tube keeps no faces: the chords RANSAC
    finds on its arc are no surface to stand on or blast.  Each member
    draws from its own random stream, seeded by ``seed`` and its own
    points, so no other member (nor the member ids) moves its fit."""
    face_id = 0
    for m in members:
        mp = pts[labels == m.id]
        noise = surface_noise(mp)
        t = (
            tol
            if not np.isfinite(noise)
            else float(np.clip(SECTION_NOISE_TOLS * noise, 0.004, tol))
        )
        rng = np.random.default_rng([seed, _points_key(mp)])
        face_id += _fit_section(m, mp, face_id, spacing, t, rng, band=t)


def _points_key(points: np.ndarray) -> int:
    """A 64-bit key of a point array's bytes (a random stream's seed)."""
    return int.from_bytes(
        hashlib.blake2b(np.ascontiguousarray(points).tobytes(), digest_size=8).digest(), "little"
    )


def _renumber(
    labels: np.ndarray, members: list[Member], radii: np.ndarray, keep: list[Member], spacing: float
) -> tuple[np.ndarray, list[Member], np.ndarray, list]:
    old = np.array([m.id for m in keep], dtype=np.int64)  # int even when nothing is kept
    remap = np.full(len(members) + 1, -1, dtype=np.int64)
    remap[old] = np.arange(len(keep))
    new_labels = remap[labels]  # −1 indexes the last slot, which is −1
    new_radii = radii[old]
    face_id = 0
    for i, m in enumerate(keep):
        m.id = i
        for f in m.faces:
            f.member, f.id = i, face_id
            face_id += 1
    joints = find_joints(
        keep,
        new_radii,
        reach=_joint_reach(spacing),
        side_tol=3 * spacing,
    )
    return new_labels, keep, new_radii, joints
