"""Where the ARA drives and stands along an inspection route: the geometry
the robot program is built from (seed 000 §3.1–3.2).

The route (:mod:`.plan`) says which member spans are driven and where the
robot changes member (:mod:`.transitions`).  This module turns it into poses:

* every member's **driving line**: the centre line of its driving face
  (:func:`.faces.driving_face`), along the member, with the interval of foot
  centres at which the l × w foot lies on the face with ``edge_margin_m`` to
  spare (S_am of seed Alg. 2 in exact form, as :func:`.faces.foot_centres`,
  for the one heading the robot drives with);
* **stretches**: the runs of the route driven on wheels between two inch-worm
  jumps (mobile transitions, Eq. 3.1 true, join spans into one stretch).  A
  stretch starts at a base pose (the route's start, or where the jump before
  it landed foot 2) and is a list of way-points on the driving lines, in a
  2D frame on the face (x along the heading at the start): the drive is a
  differential drive's turn-in-place / straight-line sequence through them;
* **jump sites**: per inch-worm transition (a member change that is not
  mobile, or a jump across a gap), the standing pose of foot 2 (the robot's
  base, front foot) on the current driving line nearest the vertex, and the
  landing pose of foot 1 on the landing member's driving line nearest the
  landing vertex, its x axis along the direction the robot drives next, so
  that foot 2, landing one foot spacing further along x (the mobile
  configuration, seed §3.2 "reform mobile configuration"), is ahead of it.

Conventions of the ARA (robots/ara/params.toml, passed in as numbers): the
base frame is foot 2's sole centre, x forward, z out of the steel; in the
mobile configuration foot 1 is ``foot_spacing_m`` behind along −x.  Poses
here are 4×4 in the model's (cloud's) frame; the robot's heading in a
stretch is chosen so that it reaches the stretch's final jump vertex
driving forwards (foot 2 first): on the last member of a stretch ending in
a jump, along the last span's direction of travel; elsewhere the line
direction closest to the previous heading (at most a 90° turn in place, the
rest driven backwards, as ``ara.navigate`` does).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable
from dataclasses import dataclass, field

import networkx as nx
import numpy as np
import shapely
from scipy.spatial import cKDTree
from shapely.geometry import Polygon
from shapely.geometry.base import BaseGeometry

from planners.inspection.faces import FaceGeom, driving_face
from planners.inspection.plan import InspectionPlan
from planners.inspection.transitions import Transition
from planners.structure.model import Member, StructureModel

__all__ = [
    "DriveLine",
    "JumpSite",
    "LayoutParams",
    "ProgramLayout",
    "Reach",
    "Stretch",
    "drive_line",
    "layout_program",
    "next_placement",
    "pose_from",
]


@dataclass(frozen=True)
class LayoutParams:
    """Robot numbers and tunables of the layout, units in the names.

    ``foot_length_m`` × ``foot_width_m``: the sole (ARA [foot]);
    ``foot_spacing_m``: sole centre to sole centre in the mobile
    configuration (ARA [arm] foot_spacing_m); ``edge_margin_m``: the foot
    keeps this from a face's outline; ``line_step_m``: the spacing of the
    foot centres tried along a driving line; ``capture_every_m``: a sensor
    frame every this many metres driven; ``snap_m``: a foot that cannot stand
    at its vertex stands a whole number of these from it (see :func:`_snaps`),
    the first where the box over the robot's feet (pad ``clear_pad_m``, from
    ``clear_above_m`` to ``clear_height_m`` over the sole) holds no obstacle
    point (the other members at the joint).

    Reachable placements (used when :func:`layout_program` gets a ``reach``
    test): the standing foot may also stand ``across_offsets_m`` to either
    side of its line (a flange wider than the foot) and up to
    ``back_steps`` snaps further back; the landing foot may land
    ``landing_along_m`` along its line and ``across_offsets_m`` across; the
    combinations are tried cheapest first (displacement from the nearest
    placement, m), at most ``max_reach_tries`` per site.  A site whose
    planned jump comes closer to the scene than the clearance margin moves
    on to its next reachable placement, at most ``clearance_relayouts``
    times (:func:`next_placement`)."""

    foot_length_m: float = 0.18
    foot_width_m: float = 0.12
    foot_spacing_m: float = 0.50
    edge_margin_m: float = 0.01
    line_step_m: float = 0.01
    capture_every_m: float = 0.5
    snap_m: float = 0.05
    clear_pad_m: float = 0.02
    clear_above_m: float = 0.02
    clear_height_m: float = 0.15
    across_offsets_m: tuple[float, ...] = (0.04, 0.08)
    back_steps: int = 2
    landing_along_m: tuple[float, ...] = (-0.05, 0.05, 0.1)
    max_reach_tries: int = 24
    clearance_relayouts: int = 2


#: ``reach(standing, landing, joint) -> bool``: can the robot standing at
#: ``standing`` (4×4, foot 2) land foot 1 at ``landing`` (4×4) at the joint
#: ``joint`` (3,)?  (:func:`planners.inspection.program_plan.reach_test`.)
Reach = Callable[[np.ndarray, np.ndarray, np.ndarray], bool]


def _snaps(s0: float, away: float, lo: float, hi: float, step: float) -> list[float]:
    """The points ``s0 + away · k · step`` (k = 0, 1, …) inside [lo, hi], in
    order — a foot placed a whole number of steps from its vertex, so that
    joints of one geometry get the same placements whatever the scan noise
    on the face's outline; ``[clip(s0)]`` when none is inside."""
    out: list[float] = []
    k = 0 if lo <= s0 <= hi else math.ceil(((lo - s0) if away > 0 else (s0 - hi)) / step - 1e-9)
    k = max(k, 0)
    while True:
        s = s0 + away * k * step
        if not (lo - 1e-9 <= s <= hi + 1e-9):
            break
        out.append(float(s))
        k += 1
    return out or [float(np.clip(s0, lo, hi))]


def _clear(
    T: np.ndarray,
    tree: cKDTree | None,
    pts: np.ndarray,
    x_range: tuple[float, float],
    p: LayoutParams,
) -> bool:
    """Is the box over the sole plane of pose ``T`` — ``x_range`` along x
    (grown by ``clear_pad_m``), the foot width + pad across, from
    ``clear_above_m`` to ``clear_height_m`` above the sole — free of
    obstacle points (other members, gussets at the joint)?"""
    if tree is None:
        return True
    x0, x1 = x_range[0] - p.clear_pad_m, x_range[1] + p.clear_pad_m
    hw = p.foot_width_m / 2 + p.clear_pad_m
    local = np.array([0.5 * (x0 + x1), 0.0, 0.5 * (p.clear_above_m + p.clear_height_m)])
    centre = T[:3, :3] @ local + T[:3, 3]
    r = float(np.linalg.norm([0.5 * (x1 - x0), hw, 0.5 * (p.clear_height_m - p.clear_above_m)]))
    idx = tree.query_ball_point(centre, r)
    if not idx:
        return True
    q = (pts[np.asarray(idx)] - T[:3, 3]) @ T[:3, :3]
    inside = (
        (q[:, 0] >= x0)
        & (q[:, 0] <= x1)
        & (np.abs(q[:, 1]) <= hw)
        & (q[:, 2] >= p.clear_above_m)
        & (q[:, 2] <= p.clear_height_m)
    )
    return not bool(inside.any())


def _place(
    line: DriveLine,
    s0: float,
    away: float,
    heading: float,
    lo: float,
    hi: float,
    x_range: tuple[float, float],
    tree: cKDTree | None,
    pts: np.ndarray,
    p: LayoutParams,
) -> tuple[np.ndarray, bool]:
    """The first snapped placement (:func:`_snaps`) whose robot box is clear
    (:func:`_clear`); (pose, clear) — the nearest one, not clear, if none."""
    poses = [
        pose_from(line.point(s), heading * line.direction, line.normal)
        for s in _snaps(s0, away, lo, hi, p.snap_m)
    ]
    for T in poses:
        if _clear(T, tree, pts, x_range, p):
            return T, True
    return poses[0], False


@dataclass(frozen=True)
class DriveLine:
    """The line the feet follow along ``member``'s driving face ``face``:
    points ``origin + s · direction`` (unit, along the member, in the face's
    plane), ``normal`` the face's outward normal; foot centres with ``s`` in
    [``lo``, ``hi``] lie on the face with the margin (the longest such run).
    ``polygon`` is the face outline in (s, t) coordinates (t along
    ``normal × direction``), ``origin`` at (0, 0)."""

    member: int
    face: int
    origin: np.ndarray
    direction: np.ndarray
    normal: np.ndarray
    lo: float
    hi: float
    polygon: BaseGeometry

    @property
    def across(self) -> np.ndarray:
        return np.cross(self.normal, self.direction)

    def point(self, s: float) -> np.ndarray:
        return self.origin + float(s) * self.direction

    def s_of(self, p: np.ndarray) -> float:
        return float((np.asarray(p, float) - self.origin) @ self.direction)

    def base_range(self, sign: float, spacing: float) -> tuple[float, float]:
        """Where the base (foot 2, front) may be with the robot heading
        ``sign`` · direction and foot 1 ``spacing`` behind, both feet on the
        line's interval (collapsed to its middle when the face is shorter
        than the robot)."""
        lo, hi = (self.lo + spacing, self.hi) if sign > 0 else (self.lo, self.hi - spacing)
        if lo > hi:
            mid = 0.5 * (self.lo + self.hi) + 0.5 * sign * spacing
            return mid, mid
        return lo, hi


def drive_line(member: Member, params: LayoutParams) -> DriveLine | None:
    """The driving line of ``member`` (``None``: no driving face, or no
    foot placement with the margin on it).

    The face outline is expressed in (s, t): s along the member axis
    projected into the face, t across.  The line runs at the middle of the
    outline's t extent; foot rectangles (l + 2·margin) × (w + 2·margin),
    aligned with the line, are tested for containment every
    ``line_step_m`` (one vectorised shapely call), and the longest run of
    contained centres is the interval."""
    face = driving_face(member, params.foot_width_m)
    if face is None:
        return None
    g = FaceGeom.of(face)
    d = np.asarray(member.direction, float)
    d = d - (d @ g.normal) * g.normal
    if float(np.linalg.norm(d)) < 1e-9:
        d = g.x_axis
    d = d / float(np.linalg.norm(d))
    e = np.cross(g.normal, d)
    ring = g.to_world(np.asarray(face.boundary, float).reshape(-1, 2))
    if len(ring) < 3:
        return None
    st = np.column_stack([(ring - g.origin) @ d, (ring - g.origin) @ e])
    poly = shapely.make_valid(Polygon(st))
    if poly.is_empty or poly.area <= 0:
        return None
    s0, t0, s1, t1 = poly.bounds
    tc = 0.5 * (t0 + t1)
    hl = params.foot_length_m / 2 + params.edge_margin_m
    hw = params.foot_width_m / 2 + params.edge_margin_m
    s = np.arange(s0 + hl, s1 - hl + 1e-9, params.line_step_m)
    if len(s) == 0:
        return None
    boxes = shapely.box(s - hl, np.full_like(s, tc - hw), s + hl, np.full_like(s, tc + hw))
    ok = shapely.contains(poly, boxes)
    if not ok.any():
        return None
    # longest run of consecutive contained centres
    edges = np.flatnonzero(np.diff(np.r_[0, ok.astype(int), 0]))
    starts, stops = edges[::2], edges[1::2]
    k = int(np.argmax(stops - starts))
    origin = g.origin + tc * e
    moved = _shift(poly, -tc)
    return DriveLine(
        member=member.id,
        face=face.id,
        origin=origin,
        direction=d,
        normal=np.asarray(g.normal, float),
        lo=float(s[starts[k]]),
        hi=float(s[stops[k] - 1]),
        polygon=moved,
    )


def _shift(poly: BaseGeometry, dt: float) -> BaseGeometry:
    return shapely.transform(poly, lambda xy: xy + np.array([0.0, dt]))


def pose_from(origin: np.ndarray, x_axis: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """4×4 pose at ``origin``: z = ``normal``, x = ``x_axis`` made orthogonal."""
    z = np.asarray(normal, float) / float(np.linalg.norm(normal))
    x = np.asarray(x_axis, float)
    x = x - (x @ z) * z
    x = x / float(np.linalg.norm(x))
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, np.cross(z, x), z, origin
    return T


@dataclass
class JumpSite:
    """One inch-worm jump of the route (seed §3.2, Fig. 3.5).

    ``transition``: index into ``InspectionPlan.transitions``; ``standing``:
    4×4 pose of foot 2 (the base) on the current driving line, heading
    towards the vertex; ``landing``: 4×4 target pose of foot 1 on the
    landing driving line, x along the next drive; ``joint``: where the
    members meet (the vertex, or the gap's mid-point); ``error``: why no
    site could be laid out (no driving line, no standing member), else
    ``None`` (then ``standing``/``landing`` are identity placeholders)."""

    transition: int
    vertex: Hashable
    landing_vertex: Hashable
    from_member: int | None
    to_member: int | None
    standing: np.ndarray
    landing: np.ndarray
    joint: np.ndarray
    landing_line: DriveLine | None
    standing_line: DriveLine | None
    error: str | None = None
    standing_clear: bool = True
    landing_clear: bool = True
    #: with a ``reach`` test: whether the placement passed it (``None``: not
    #: tested), how many placements were tested, and the chosen one's
    #: displacement (standing back, standing across, landing along, landing
    #: across; m) from the nearest placement
    reachable: bool | None = None
    reach_tries: int = 0
    offsets_m: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    #: the nearest placement (standing, landing) the reach search started
    #: from, and the standing foot's range on its line (for
    #: :func:`next_placement`); ``None`` before a reach search
    nearest: tuple[np.ndarray, np.ndarray] | None = None
    base_range: tuple[float, float] | None = None

    @property
    def relative(self) -> np.ndarray:
        """Foot 1's landing in the standing base frame (the planner's
        ``foothold``)."""
        return np.linalg.inv(self.standing) @ self.landing


@dataclass
class Stretch:
    """A run of the route driven on wheels (mobile configuration).

    ``start``: 4×4 base pose at its start (model frame); ``waypoints``:
    (K, 3) base poses (x, y, yaw) in the 2D frame of ``start`` (x along its
    heading, y = normal × x, origin at the base), the first (0, 0, 0); the
    robot turns in place and drives straight between consecutive ones;
    ``members``: the members driven; ``ends_in``: index into
    ``ProgramLayout.sites`` of the jump that ends it, or ``None`` at the
    route's end."""

    start: np.ndarray
    waypoints: np.ndarray
    members: list[int]
    ends_in: int | None
    edges: list[tuple[Hashable, Hashable, Hashable]] = field(default_factory=list)

    def to_world(self, xy: np.ndarray) -> np.ndarray:
        """(…, 2) stretch-frame positions → (…, 3) model-frame points."""
        q = np.asarray(xy, float)
        return self.start[:3, 3] + q[..., :1] * self.start[:3, 0] + q[..., 1:2] * self.start[:3, 1]

    def to_plane(self, p: np.ndarray) -> np.ndarray:
        rel = np.asarray(p, float) - self.start[:3, 3]
        return np.stack([rel @ self.start[:3, 0], rel @ self.start[:3, 1]], axis=-1)

    def pose_at(self, pose: np.ndarray) -> np.ndarray:
        """4×4 model-frame pose of the stretch-frame base pose (x, y, yaw)."""
        x, y, yaw = (float(v) for v in pose)
        T = np.eye(4)
        Rz = np.array(
            [[math.cos(yaw), -math.sin(yaw), 0], [math.sin(yaw), math.cos(yaw), 0], [0, 0, 1]]
        )
        T[:3, :3] = self.start[:3, :3] @ Rz
        T[:3, 3] = self.to_world(np.array([x, y]))
        return T


@dataclass
class ProgramLayout:
    """Stretches and jump sites of the main route, in driving order:
    ``stretches[0]``, ``sites[stretches[0].ends_in]``, ``stretches[1]``, …
    (a stretch after a site starts where that jump lands foot 2, so its
    ``start`` is filled in once the jump is planned: see
    :func:`planners.inspection.jumps.place_stretch`)."""

    lines: dict[int, DriveLine | None]
    stretches: list[Stretch]
    sites: list[JumpSite]
    params: LayoutParams


def layout_program(
    model: StructureModel,
    plan: InspectionPlan,
    params: LayoutParams | None = None,
    obstacles: np.ndarray | None = None,
    reach: Reach | None = None,
) -> ProgramLayout:
    """Stretches and jump sites of ``plan``'s main route (``routes[0]``; the
    other routes need the robot carried there and are not laid out).

    Every stretch but the first starts at a placeholder pose (identity)
    until the jump before it is planned; its way-points are then laid out
    again from the landing (:func:`relayout_stretch`).  The way-points of
    each span are the base's stop on the span's driving line nearest the
    span's end vertex, within :meth:`DriveLine.base_range`.

    ``reach``: when given, a site whose nearest placement fails it is moved
    to the cheapest reachable one (:func:`reachable_placement`)."""
    p = params or LayoutParams()
    members = {m.id: m for m in model.members}
    obstacles = np.zeros((0, 3)) if obstacles is None else np.asarray(obstacles, float)
    tree = cKDTree(obstacles) if len(obstacles) else None
    lines: dict[int, DriveLine | None] = {}

    def line(mid: int | None) -> DriveLine | None:
        if mid is None:
            return None
        if mid not in lines:
            lines[mid] = drive_line(members[mid], p)
        return lines[mid]

    g = plan.graph
    route = plan.route
    # transitions of the main route by the index of the edge they precede
    jumps_at: dict[int, tuple[int, Transition]] = {}
    for i, t in enumerate(plan.transitions):
        if t.route == 0 and t.mode == "inchworm":
            jumps_at[t.index_in_route] = (i, t)
    # Split the edges into stretches of spans; a jump transition at index k
    # ends the stretch before edge k (a gap jump: edge k is the jump edge).
    runs: list[list[int]] = [[]]
    ends: list[int | None] = []
    for k, e in enumerate(route.edges):
        if k in jumps_at:
            ends.append(k)
            runs.append([])
        if g.edges[e].get("kind") == "jump":
            continue
        runs[-1].append(k)
    ends.append(None)
    stretches: list[Stretch] = []
    n_sites = 0
    for run, end in zip(runs, ends, strict=True):
        spans = [route.edges[k] for k in run]
        mem = [int(g.edges[e]["member"]) for e in spans]
        for m in mem:
            line(m)
        stretches.append(
            Stretch(
                start=np.eye(4),
                waypoints=np.zeros((1, 3)),
                members=mem,
                ends_in=None if end is None else n_sites,
                edges=spans,
            )
        )
        n_sites += end is not None
    sites: list[JumpSite] = []
    learned: list[tuple[float, float, float, float]] = []
    failed: set[tuple[object, ...]] = set()
    for r, end in enumerate(ends):
        if end is None:
            continue
        ti, t = jumps_at[end]
        nxt = stretches[r + 1]
        line(t.from_member)
        line(t.to_member)
        sign = None
        if nxt.edges and lines.get(nxt.members[0]) is not None:
            sign = _stretch_signs(lines, g, nxt)[0]
        site = _site(ti, t, plan, lines, sign, p, tree, obstacles)
        here = stretches[r]
        la = lines.get(t.from_member) if t.from_member is not None else None
        if site.error is None and la is not None:
            # arrive forwards: along the last span's travel (or towards the vertex)
            if here.edges:
                sa = _heading_sign(la, g, here.edges[-1])
            else:
                sv = la.s_of(np.asarray(g.nodes[t.vertex]["pos"], float))
                sa = 1.0 if sv >= 0.5 * (la.lo + la.hi) else -1.0
            lo, hi = la.base_range(sa, p.foot_spacing_m)
            sv = la.s_of(np.asarray(g.nodes[t.vertex]["pos"], float))
            robot = (-p.foot_spacing_m - p.foot_length_m / 2, p.foot_length_m / 2)
            site.standing, site.standing_clear = _place(
                la, sv, -sa, sa, lo, hi, robot, tree, obstacles, p
            )
            if reach is not None and site.landing_line is not None:
                reachable_placement(
                    site,
                    la,
                    site.landing_line,
                    (lo, hi),
                    reach,
                    tree,
                    obstacles,
                    p,
                    learned,
                    failed,
                )
        sites.append(site)
    out = ProgramLayout(lines=lines, stretches=stretches, sites=sites, params=p)
    if stretches and stretches[0].edges:
        start = start_pose(out, plan, stretches[0])
        if start is not None:
            relayout_stretch(out, plan, 0, start)
    return out


def _heading_sign(ln: DriveLine, g: nx.MultiGraph, e: tuple[Hashable, Hashable, Hashable]) -> float:
    """+1 when the span ``e`` (u → v) runs along +direction of ``ln``."""
    a = ln.s_of(np.asarray(g.nodes[e[0]]["pos"], float))
    b = ln.s_of(np.asarray(g.nodes[e[1]]["pos"], float))
    return 1.0 if b >= a else -1.0


def _stretch_signs(
    lines: dict[int, DriveLine | None], g: nx.MultiGraph, st: Stretch
) -> list[float]:
    """The heading sign (along each span's driving line) per span of ``st``:
    on the last member of a stretch ending in a jump, its last span's
    direction of travel (the robot arrives forwards); elsewhere the one
    closest to the previous heading (kept on one member)."""
    n = len(st.edges)
    signs = [1.0] * n
    last_member = st.members[-1] if n else None
    tail = n
    if st.ends_in is not None:
        while tail > 0 and st.members[tail - 1] == last_member:
            tail -= 1
    prev_dir: np.ndarray | None = None
    for k, e in enumerate(st.edges):
        ln = lines.get(st.members[k])
        if ln is None:
            continue
        if k >= tail:
            signs[k] = _heading_sign(ln, g, st.edges[-1])
        elif prev_dir is not None:
            signs[k] = 1.0 if float(ln.direction @ prev_dir) >= 0 else -1.0
        else:
            signs[k] = _heading_sign(ln, g, e)
        prev_dir = signs[k] * ln.direction
    return signs


def start_pose(layout: ProgramLayout, plan: InspectionPlan, st: Stretch) -> np.ndarray | None:
    """Where the crew sets the robot down: on the first span's driving line,
    the base as near the route's start vertex as the robot fits, heading as
    :func:`_stretch_signs` chooses."""
    g = plan.graph
    ln = layout.lines.get(st.members[0])
    if ln is None:
        return None
    sign = _stretch_signs(layout.lines, g, st)[0]
    lo, hi = ln.base_range(sign, layout.params.foot_spacing_m)
    s = float(np.clip(ln.s_of(np.asarray(g.nodes[st.edges[0][0]]["pos"], float)), lo, hi))
    return pose_from(ln.point(s), sign * ln.direction, ln.normal)


def relayout_stretch(
    layout: ProgramLayout, plan: InspectionPlan, index: int, start: np.ndarray
) -> None:
    """Lay out stretch ``index`` from the base pose ``start`` (4×4, where
    the crew set the robot down or where the jump before landed foot 2):
    one way-point per span, the base's stop on the span's driving line
    nearest the span's end vertex; a stretch ending in a jump ends at the
    jump's standing pose.  Positions are projected into the plane of
    ``start`` (continuing faces are within ``coplanar_angle_deg``)."""
    st = layout.stretches[index]
    st.start = np.asarray(start, float)
    g = plan.graph
    sp = layout.params.foot_spacing_m
    way = [np.zeros(3)]
    signs = _stretch_signs(layout.lines, g, st)

    def planar(T_pos: np.ndarray, heading: np.ndarray) -> np.ndarray:
        xy = st.to_plane(T_pos)
        d2 = st.to_plane(st.start[:3, 3] + heading)
        return np.array([xy[0], xy[1], math.atan2(float(d2[1]), float(d2[0]))])

    for k, e in enumerate(st.edges):
        ln = layout.lines.get(st.members[k])
        if ln is None:
            continue
        lo, hi = ln.base_range(signs[k], sp)
        s = float(np.clip(ln.s_of(np.asarray(g.nodes[e[1]]["pos"], float)), lo, hi))
        way.append(planar(ln.point(s), signs[k] * ln.direction))
    if st.ends_in is not None and layout.sites[st.ends_in].error is None:
        S = layout.sites[st.ends_in].standing
        way.append(planar(S[:3, 3], S[:3, 0]))
    st.waypoints = _drive_poses(np.array(way))


def _drive_poses(way: np.ndarray) -> np.ndarray:
    """Differential-drive poses through the way-points (x, y, yaw): from each
    pose, turn in place to face the next position (or away from it when it
    lies behind: driven backwards, at most 90° of turn), drive there, then
    turn to the way-point's yaw."""
    out = [way[0].copy()]
    for w in way[1:]:
        x, y, th = out[-1]
        dx, dy = float(w[0] - x), float(w[1] - y)
        dist = math.hypot(dx, dy)
        if dist > 1e-6:
            face = math.atan2(dy, dx)
            turn = _wrap(face - th)
            if abs(turn) > math.pi / 2:
                face = _wrap(face + math.pi)
            if abs(_wrap(face - th)) > 1e-9:
                out.append(np.array([x, y, face]))
            out.append(np.array([float(w[0]), float(w[1]), face]))
        if abs(_wrap(float(w[2]) - out[-1][2])) > 1e-9:
            out.append(np.array([out[-1][0], out[-1][1], float(w[2])]))
    return np.array(out)


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def _site(
    ti: int,
    t: Transition,
    plan: InspectionPlan,
    lines: dict[int, DriveLine | None],
    sign: float | None,
    p: LayoutParams,
    tree: cKDTree | None,
    obstacles: np.ndarray,
) -> JumpSite:
    """The jump site of transition ``t``: the standing pose is filled in by
    :func:`relayout_stretch`; the landing pose is foot 1 on the landing
    line nearest the landing vertex, x along ``sign`` · the line (the
    heading of the stretch driven next; ``None``: away from the vertex)."""
    g = plan.graph
    a, b = t.from_member, t.to_member
    la = lines.get(a) if a is not None else None
    lb = lines.get(b) if b is not None else None
    v, w = t.vertex, t.landing_vertex
    joint = 0.5 * (np.asarray(g.nodes[v]["pos"], float) + np.asarray(g.nodes[w]["pos"], float))
    site = JumpSite(ti, v, w, a, b, np.eye(4), np.eye(4), joint, lb, la)
    if a is None:
        site.error = "the route starts with a jump: no member to stand on"
    elif la is None:
        site.error = f"member {a} has no driving line for the standing foot"
    elif lb is None:
        site.error = f"member {b} has no driving line for the landing foot"
    if site.error is not None or lb is None:
        return site
    sw = lb.s_of(np.asarray(g.nodes[w]["pos"], float))
    if sign is None:
        sign = 1.0 if sw <= 0.5 * (lb.lo + lb.hi) else -1.0
    # foot 1 is the rear foot after landing: the base range shifted back by one spacing
    lo, hi = lb.base_range(sign, p.foot_spacing_m)
    lo, hi = lo - sign * p.foot_spacing_m, hi - sign * p.foot_spacing_m
    robot = (-p.foot_length_m / 2, p.foot_spacing_m + p.foot_length_m / 2)
    site.landing, site.landing_clear = _place(
        lb, sw, sign, sign, min(lo, hi), max(lo, hi), robot, tree, obstacles, p
    )
    return site


def _on_face(line: DriveLine, T: np.ndarray, x_range: tuple[float, float], p: LayoutParams) -> bool:
    """Does the box ``x_range`` along ``T``'s x (the robot's feet, each
    ``foot_width_m`` wide) lie on ``line``'s face with ``edge_margin_m``?
    (S_am of seed Alg. 2 in exact form, for a pose off the centre line.)"""
    m = p.edge_margin_m
    hw = p.foot_width_m / 2 + m
    local = np.array([[x, y, 0.0] for x in (x_range[0] - m, x_range[1] + m) for y in (-hw, hw)])
    c = local @ T[:3, :3].T + T[:3, 3] - line.origin
    st = np.column_stack([c @ line.direction, c @ line.across])
    return bool(line.polygon.covers(Polygon(st[[0, 1, 3, 2]])))


def reachable_placement(
    site: JumpSite,
    la: DriveLine,
    lb: DriveLine,
    base_range: tuple[float, float],
    reach: Reach,
    tree: cKDTree | None,
    obstacles: np.ndarray,
    p: LayoutParams,
    learned: list[tuple[float, float, float, float]] | None = None,
    failed: set[tuple[object, ...]] | None = None,
    skip: frozenset[tuple[float, float, float, float]] = frozenset(),
) -> None:
    """Move ``site``'s feet to the cheapest placement that ``reach`` accepts
    (seed §3.2: the target pose must be one the arm can land foot 1 on).

    Candidates: the standing foot ``k`` snaps further back (k ≤
    ``back_steps``, inside ``base_range``) and ``across_offsets_m`` to either
    side; the landing foot ``landing_along_m`` along its line and
    ``across_offsets_m`` across.  A candidate must keep both feet of the
    mobile configuration on their face (:func:`_on_face`) and its robot box
    clear (:func:`_clear`); the rest are tried in order of total
    displacement (ties: standing before landing changes, then the order
    listed), at most ``max_reach_tries`` of them; the displacements that
    served earlier sites (``learned``, appended to) go first — the joints
    of a truss repeat — and a site whose nearest placement matches one that
    found nothing (``failed``: the standing → landing transform rounded to
    5 cm / 0.1 per rotation entry) is not searched again.  The first accepted one is
    kept (``reachable`` true); when none is, the nearest placement stays
    (``reachable`` false) and the planner's reason names the site.
    ``skip``: displacements not to try again (placements already planned)."""
    if site.nearest is None:
        site.nearest = (site.standing.copy(), site.landing.copy())
        site.base_range = (float(base_range[0]), float(base_range[1]))
    S0, L0 = site.nearest
    rel = np.linalg.inv(S0) @ L0
    key = (
        "failed",
        *(int(v) for v in np.round(rel[:3, 3] / 0.05)),
        *(int(v) for v in np.round(rel[:3, :3].ravel() / 0.1)),
    )
    if failed is not None and key in failed:
        site.reachable, site.reach_tries = False, 0
        return
    sp, fl = p.foot_spacing_m, p.foot_length_m
    behind = (-sp - fl / 2, fl / 2)  # foot 1 behind the standing foot 2
    ahead = (-fl / 2, sp + fl / 2)  # foot 2 ahead of the landed foot 1
    across = (0.0, *[s * a for a in p.across_offsets_m for s in (1.0, -1.0)])
    s_now = la.s_of(S0[:3, 3])
    heading = float(S0[:3, 0] @ la.direction)
    stand: list[tuple[float, float, float, np.ndarray]] = []
    for k in range(p.back_steps + 1):
        back = k * p.snap_m
        s = s_now - math.copysign(back, heading)
        if not (base_range[0] - 1e-9 <= s <= base_range[1] + 1e-9):
            continue
        for t in across:
            T = S0.copy()
            T[:3, 3] = S0[:3, 3] + (s - s_now) * la.direction + t * S0[:3, 1]
            if (k or t) and not (
                _on_face(la, T, behind, p) and _clear(T, tree, obstacles, behind, p)
            ):
                continue
            stand.append((back, t, back + abs(t), T))
    land: list[tuple[float, float, float, np.ndarray]] = []
    for a in (0.0, *p.landing_along_m):
        for t in across:
            T = L0.copy()
            T[:3, 3] = L0[:3, 3] + a * L0[:3, 0] + t * L0[:3, 1]
            if (a or t) and not (
                _on_face(lb, T, ahead, p) and _clear(T, tree, obstacles, ahead, p)
            ):
                continue
            land.append((a, t, abs(a) + abs(t), T))
    known = learned if learned is not None else []

    def rank(c: tuple[float, int, int]) -> tuple[int, float, int, int, int]:
        off = (stand[c[1]][0], stand[c[1]][1], land[c[2]][0], land[c[2]][1])
        first = known.index(off) if off in known else len(known)
        return (first, round(c[0], 6), c[1] + c[2], c[1], c[2])

    pairs = sorted(
        (
            (sc + lc, i, j)
            for i, (*_, sc, _) in enumerate(stand)
            for j, (*_, lc, _) in enumerate(land)
        ),
        key=rank,
    )
    pairs = [
        c
        for c in pairs
        if (stand[c[1]][0], stand[c[1]][1], land[c[2]][0], land[c[2]][1]) not in skip
    ]
    tries = 0
    for _, i, j in pairs[: p.max_reach_tries]:
        tries += 1
        S, L = stand[i][3], land[j][3]
        if reach(S, L, site.joint):
            site.standing, site.landing = S, L
            site.reachable, site.reach_tries = True, tries
            site.offsets_m = (stand[i][0], stand[i][1], land[j][0], land[j][1])
            if site.offsets_m not in known:
                known.append(site.offsets_m)
            return
    site.reachable, site.reach_tries = False, tries
    if failed is not None:
        failed.add(key)


def next_placement(
    site: JumpSite,
    reach: Reach,
    tree: cKDTree | None,
    obstacles: np.ndarray,
    p: LayoutParams,
    skip: frozenset[tuple[float, float, float, float]],
) -> bool:
    """Move ``site`` to its cheapest reachable placement whose displacement
    is not in ``skip`` (:func:`reachable_placement` again, from the nearest
    placement, without the shared ``learned``/``failed`` memory): the next
    candidate when the planned jump at the current one came closer to the
    scene than the clearance margin (seed §3.2).  True when one is found;
    otherwise the site keeps its current placement."""
    if site.nearest is None or site.base_range is None or site.standing_line is None:
        return False
    if site.landing_line is None:
        return False
    keep = (site.standing, site.landing, site.reachable, site.reach_tries, site.offsets_m)
    reachable_placement(
        site,
        site.standing_line,
        site.landing_line,
        site.base_range,
        reach,
        tree,
        obstacles,
        p,
        skip=skip,
    )
    if site.reachable:
        return True
    site.standing, site.landing, site.reachable, site.reach_tries, site.offsets_m = keep
    return False
