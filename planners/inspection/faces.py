"""Face geometry for the inspection route: the driving face of a member, whether
two driving faces continue across a vertex, and where the ARA foot fits.

* driving face: the face the robot drives on along a member (below);
* continuity: the robot stays in mobile mode across a vertex when the next
  driving face is the current one continued — the literal reading of seed
  Eq. 3.4 (the next plane's height equals the base height) plus the normals
  agreeing within an angle and the outlines touching near the vertex;
* foot placements: S_am (seed §3.1, area availability) in exact form — the
  l × w foot rectangle lies inside the face polygon — tried on a grid of
  centres and headings within the jump reach of the vertex.  The seed's
  Alg. 2 approximates the same containment from boundary *points*; here the
  polygon itself is known, so the exact test (the cross-check that
  :func:`planners.switching.availability.area_check` runs against its own
  verdicts) is used directly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely
from shapely.geometry import Point, Polygon
from shapely.geometry.base import BaseGeometry

from planners.inspection.params import InspectionParams
from planners.structure.model import Face, Member

__all__ = ["FaceGeom", "driving_face", "face_continuity", "foot_centres"]


#: faces at least this share of the largest one's area are equals when choosing
NEAR_AREA = 0.8


def driving_face(member: Member, foot_width_m: float | None = None) -> Face | None:
    """The face the robot drives on along ``member``, or ``None`` without faces.

    With ``foot_width_m``, faces at least that wide across (the outline's
    extent across the member) come first: an IPE 200's 100 mm flanges take
    no 120 mm foot, its 200 mm web does (the ARA holds on by magnets, so a
    web is a surface to drive on as a flange is).  Among the candidates
    flanges are preferred (the outer flange of an I, channel or tee is where
    the ARA's feet sit); among those the largest by area wins, and faces
    within 20 % of the largest count as equal (an I's two flanges, measured
    on a scan that sees one better than the other), of which the one whose
    normal points most upwards (+z) is taken — the top flange — then the
    lowest face id, so the choice is deterministic.
    """
    if not member.faces:
        return None
    pool = list(member.faces)
    if foot_width_m is not None:
        wide = [f for f in pool if _across(f) >= foot_width_m]
        pool = wide or pool
    flanges = [f for f in pool if f.kind == "flange"]
    pool = flanges or pool
    top = max(float(f.area_m2) for f in pool)
    near = [f for f in pool if float(f.area_m2) >= NEAR_AREA * top]

    def upness(f: Face) -> float:
        n = np.asarray(f.normal, float)
        norm = float(np.linalg.norm(n))
        return float(n[2]) / norm if norm > 0 else -math.inf

    return max(near, key=lambda f: (upness(f), -f.id))


def placeable(member: Member, foot_width_m: float) -> bool:
    """Whether a face of ``member`` is at least ``foot_width_m`` across it:
    a face the robot can be set down on (and driven along)."""
    return any(_across(f) >= foot_width_m for f in member.faces)


def _across(face: Face) -> float:
    """A face's extent across its member: its outline's in-plane ``y`` span
    (``x`` runs along the member)."""
    b = np.asarray(face.boundary, float)
    return float(np.ptp(b[:, 1])) if len(b) else 0.0


@dataclass(frozen=True)
class FaceGeom:
    """A face with an orthonormal frame and its outline as a valid polygon."""

    face: Face
    origin: np.ndarray
    normal: np.ndarray
    x_axis: np.ndarray
    y_axis: np.ndarray
    polygon: BaseGeometry

    @staticmethod
    def of(face: Face) -> FaceGeom:
        """Normalise the frame (``x`` made orthogonal to the normal) and repair
        the outline (``make_valid``: a self-touching scan outline is still a
        surface); a degenerate outline gives an empty polygon."""
        n = np.asarray(face.normal, float)
        n = n / max(float(np.linalg.norm(n)), 1e-300)
        x = np.asarray(face.x_axis, float)
        x = x - (x @ n) * n
        xn = float(np.linalg.norm(x))
        if xn < 1e-9:  # x axis along the normal: any in-plane axis will do
            ref = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
            x = ref - (ref @ n) * n
            xn = float(np.linalg.norm(x))
        x = x / xn
        b = np.asarray(face.boundary, float).reshape(-1, 2)
        poly: BaseGeometry = Polygon()
        if len(b) >= 3 and np.isfinite(b).all():
            poly = shapely.make_valid(Polygon(b))
        return FaceGeom(face, np.asarray(face.origin, float), n, x, np.cross(n, x), poly)

    def to_plane(self, p: np.ndarray) -> np.ndarray:
        """(…, 3) points → (…, 2) coordinates of their projection on the plane."""
        rel = np.asarray(p, float) - self.origin
        return np.stack([rel @ self.x_axis, rel @ self.y_axis], axis=-1)

    def to_world(self, uv: np.ndarray) -> np.ndarray:
        """(…, 2) plane coordinates → (…, 3) points."""
        q = np.asarray(uv, float)
        return self.origin + q[..., :1] * self.x_axis + q[..., 1:2] * self.y_axis

    def near(self, p: np.ndarray, radius_m: float) -> BaseGeometry:
        """The part of the face within ``radius_m`` of ``p``'s projection."""
        c = self.to_plane(p)
        return shapely.intersection(self.polygon, Point(float(c[0]), float(c[1])).buffer(radius_m))


@dataclass(frozen=True)
class Continuity:
    """Whether face ``b`` continues face ``a`` at a vertex, with the measures."""

    continues: bool
    angle_deg: float  # between the outward normals
    step_m: float  # distance from a's plane to b's plane at the vertex, along a's normal
    outline_gap_m: float  # distance between the outlines near the vertex, in a's plane


def face_continuity(
    a: FaceGeom, b: FaceGeom, p: np.ndarray, params: InspectionParams, outline_slack_m: float = 0.0
) -> Continuity:
    """Do the driving faces ``a`` and ``b`` form one surface at vertex ``p``?

    Yes when (1) the outward normals are within ``coplanar_angle_deg`` — the
    signed angle, so a top flange and a bottom flange facing the other way do
    not continue each other; (2) at the projection ``q`` of ``p`` on ``a``,
    plane ``b`` lies within ``contact_tolerance_m`` along ``a``'s normal (seed
    Eq. 3.4: the next plane at the base height); (3) the outlines, ``b``'s
    projected into ``a``'s plane and both clipped to the disc of radius
    ``jump_reach_m`` about ``q``, come within ``contact_tolerance_m`` plus
    ``outline_slack_m`` (touch or overlap near the vertex, not somewhere far
    along the members).  An outline is drawn through a face's outermost scan
    points, so it stops up to a point spacing short of the steel's edge on
    either face: two flush faces scanned at spacing ``s`` show outlines up to
    ``2 s`` apart, the slack :func:`planners.inspection.plan_inspection` allows.
    """
    cos = float(np.clip(a.normal @ b.normal, -1.0, 1.0))
    angle = math.degrees(math.acos(cos))
    q = p - ((p - a.origin) @ a.normal) * a.normal
    step = abs(float((q - b.origin) @ b.normal)) / cos if cos > 1e-9 else math.inf
    gap = math.inf
    if angle <= params.coplanar_angle_deg and step <= params.contact_tolerance_m:
        ring = b.to_world(np.asarray(b.face.boundary, float).reshape(-1, 2))
        near_a = a.near(q, params.jump_reach_m)
        if len(ring) >= 3 and not near_a.is_empty:
            b_in_a = shapely.make_valid(Polygon(a.to_plane(ring)))
            c = a.to_plane(q)
            near_b = shapely.intersection(
                b_in_a, Point(float(c[0]), float(c[1])).buffer(params.jump_reach_m)
            )
            if not near_b.is_empty:
                gap = float(shapely.distance(near_a, near_b))
    ok = angle <= params.coplanar_angle_deg and step <= params.contact_tolerance_m
    return Continuity(ok and gap <= params.contact_tolerance_m + outline_slack_m, angle, step, gap)


def foot_centres(
    g: FaceGeom, p: np.ndarray, heading: np.ndarray | None, params: InspectionParams
) -> np.ndarray:
    """(k, 3) centres of foot rectangles lying wholly on face ``g`` within
    ``jump_reach_m`` of vertex ``p`` (S_am, exact): centres on a
    ``placement_spacing_m`` grid, ``placement_headings`` headings evenly over
    180° starting along ``heading`` projected into the plane (the member axis:
    the foot is aligned with the member it drives along), a centre kept when
    any heading fits.

    Containment by erosion rather than one polygon per rectangle: for a
    heading θ with foot rectangle K (symmetric about its centre), ``c + K``
    lies inside the region P iff ``c ∈ P`` and ``c + K`` meets no boundary
    edge of P, i.e. ``c ∉ ∂P ⊕ K``; ``∂P ⊕ K`` is the union of the convex
    hulls of each boundary segment swept by K.  So the valid centres are
    ``P − ⋃ hull(e ⊕ K)``, tested on the grid with one vectorised call.
    Strict containment: a foot touching the face's edge does not count.  At
    most ``(2·reach/spacing + 1)²`` grid centres, so memory does not grow with
    the structure."""
    region = g.near(p, params.jump_reach_m)
    if region.is_empty or region.area <= 0:
        return np.zeros((0, 3))
    s = params.placement_spacing_m
    x0, y0, x1, y1 = region.bounds
    xs = np.arange(x0, x1 + 1e-12, s)
    ys = np.arange(y0, y1 + 1e-12, s)
    gx, gy = np.meshgrid(xs, ys)
    centres = np.column_stack([gx.ravel(), gy.ravel()])
    centres = centres[shapely.contains_xy(region, centres[:, 0], centres[:, 1])]
    if len(centres) == 0:
        return np.zeros((0, 3))
    base = 0.0
    if heading is not None:
        hu = g.to_plane(g.origin + np.asarray(heading, float))
        if float(np.hypot(hu[0], hu[1])) > 1e-9:
            base = math.atan2(float(hu[1]), float(hu[0]))
    # Boundary segments of the region (every ring of every part).
    segs = []
    for line in shapely.get_parts(shapely.boundary(region)):
        xy = shapely.get_coordinates(line)
        segs.append(np.stack([xy[:-1], xy[1:]], axis=1))
    seg = np.concatenate(segs)  # (S, 2, 2)
    hl, hw = params.foot_length_m / 2, params.foot_width_m / 2
    local = np.array([[hl, hw], [-hl, hw], [-hl, -hw], [hl, -hw]])
    fits = np.zeros(len(centres), bool)
    for k in range(params.placement_headings):
        a = base + k * math.pi / params.placement_headings
        rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
        corners = local @ rot.T  # (4, 2)
        swept = (seg[:, :, None, :] + corners[None, None]).reshape(len(seg), 8, 2)
        band = shapely.union_all(shapely.convex_hull(shapely.multipoints(swept)))
        ok = shapely.difference(region, band)
        if not ok.is_empty:
            fits |= shapely.contains_xy(ok, centres[:, 0], centres[:, 1])
    return np.asarray(g.to_world(centres[fits]))
