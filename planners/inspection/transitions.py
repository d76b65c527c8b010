"""Mobile / inch-worm transitions along an inspection route (seed §3.1, Eq. 3.1–3.4).

At every vertex the route passes, the ARA either keeps driving (mobile) or
jumps (inch-worm).  The switching function of the seed is
``S = S_pa ∧ S_am ∧ S_hc`` (Eq. 3.1): mobile when true, inch-worm otherwise.
Here the surfaces are the members' driving faces (:mod:`.faces`) rather than
a camera's RANSAC planes, and each check reads:

* S_pa (Eq. 3.2): the landing member has a driving face (``P_cl ≠ ∅``);
* S_am (Alg. 2, exact form): the l × w foot fits on the landing face within
  the jump reach of the vertex (:func:`.faces.foot_centres`);
* S_hc, mobile (Eq. 3.4 as printed): the landing face continues the current
  one — its plane at the base height at the vertex, normals within
  ``coplanar_angle_deg``, outlines touching (:func:`.faces.face_continuity`).
  This decides the mode.
* S_hc, inch-worm (adapted): the seed compares the target plane's centroid
  height with the base (Eq. 3.3 puts it in the base frame); for a jump what
  matters is that the landing lies within the arm's reach, and the ARA's arm
  gives an exact bound for that: joint 2 sits ``wrist_standing_m`` along the
  standing foot's normal above its sole, joint 5 ``wrist_landing_m`` along
  the landing foot's normal off its sole, and between them the arm is three
  straight links, ``arm_length_m`` long at most
  (:func:`planners.switching.jump.wrist_distance`, ``arm_length``).  So the
  check is "some standing placement on the current face near the vertex and
  some landing placement on the landing face have their wrist points at most
  ``arm_length_m`` apart" (:func:`nearest_wrists`), over the same foot
  placements S_am enumerates (:func:`.faces.foot_centres`; at most
  ``reach_candidates`` per face, those nearest the vertex).  It is a
  necessary condition: a pair within it may still find no collision-free
  configuration (the program planner's job, :mod:`.jumps`), a pair beyond
  it is out of reach for every joint value.

``feasible = plane ∧ area ∧ height`` for either mode: a mobile transition
with ``feasible`` true is exactly the seed's ``S = true``.

Jump-cost weighting (for :func:`planners.vocpp.plan_route`).  The exact
problem — a covering walk minimising length + jump cost, where the cost at a
vertex depends on which two edges the walk pairs there — is a Chinese postman
problem with turn penalties, NP-hard in general, and cannot be written as
edge weights; expanding each joint into a gadget of turn edges turns it into a
rural postman problem (the gadget edges need not be covered), also NP-hard.
So the weights carry an estimate that plain edge weights *can* express: an
edge-end at a vertex ``v`` is charged ``jump_cost_m / 2`` when every way
through ``v`` from that edge is a jump — ``v`` is not a free end (where the
robot reverses on its member), its member does not continue through ``v``,
and no other member's driving face continues it there.  Each pass through
such a vertex pairs two edge-ends, so two charged ends cost one jump.  The
estimate never charges an avoidable jump (it is a lower estimate); it misses
jumps the walk takes by pairing chargeable-free ends badly, and charges a
turnaround onto the same edge.  The jumps actually taken are counted from the
transitions of the route found, never from the weights.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Mapping
from dataclasses import dataclass, field

import networkx as nx
import numpy as np
from scipy.spatial import cKDTree

from planners.inspection.faces import (
    Continuity,
    FaceGeom,
    driving_face,
    face_continuity,
    foot_centres,
)
from planners.inspection.params import InspectionParams
from planners.structure.model import Member
from planners.vocpp import Route

__all__ = ["MODES", "Transition", "TransitionContext", "nearest_wrists", "route_transitions"]

#: Modes a transition can have.
MODES: tuple[str, ...] = ("mobile", "inchworm")


@dataclass(frozen=True)
class Transition:
    """What the robot does where the route goes from one edge to the next.

    - ``route``: index into ``InspectionPlan.routes``;
    - ``vertex``: where the robot stands; ``index_in_route``: its index in
      ``route.vertices`` (between ``edges[index-1]`` and ``edges[index]``;
      for a gap jump, the index of the jump edge's first vertex);
    - ``landing_vertex``: where the moving foot lands (``vertex`` except for
      a jump across a gap, whose other end it is);
    - ``kind``: ``"continue"`` (on along the same member), ``"turnaround"``
      (back along the same member), ``"member"`` (onto another member at a
      joint), ``"gap"`` (an inch-worm jump across a gap between components);
    - ``from_member`` / ``to_member``: member ids (``from_member`` is ``None``
      when the route starts with a gap jump); ``from_face`` / ``to_face``:
      their driving face ids or ``None``;
    - ``mode``: ``"mobile"`` or ``"inchworm"``; ``angle_deg``: between the two
      driving faces' normals (``None`` when either is missing);
    - ``availability``: ``plane`` / ``area`` / ``height`` (the three checks,
      see the module docstring) and the values behind them:
      ``footholds`` (foot placements found on the landing face),
      ``step_m`` and ``outline_gap_m`` (continuity measures, ``None`` where not
      measured); inch-worm only: ``wrist_distance_m`` (the nearest wrist
      points of a standing and a landing placement) against
      ``arm_length_m``, and ``reach_distance_m`` (sole centre to sole centre
      of that pair) against ``reach_limit_m`` (``jump_reach_m``, shown only);
    - ``feasible``: all three checks pass; ``reason``: a sentence why.
    """

    route: int
    vertex: Hashable
    index_in_route: int
    landing_vertex: Hashable
    kind: str
    from_member: int | None
    to_member: int | None
    mode: str
    angle_deg: float | None
    from_face: int | None
    to_face: int | None
    availability: dict[str, bool | float | int | None]
    feasible: bool
    reason: str


@dataclass
class TransitionContext:
    """Members, routing graph and parameters, with per-(face, vertex) caches so
    repeated passes through a vertex cost one evaluation (the caches hold
    O(number of spans) entries)."""

    members: Mapping[int, Member]
    graph: nx.MultiGraph
    params: InspectionParams
    #: how far apart the outlines of two flush faces may be drawn (m): two point spacings
    outline_slack_m: float = 0.0
    _geom: dict[int, FaceGeom | None] = field(default_factory=dict)
    _cont: dict[tuple[Hashable, int, int], Continuity] = field(default_factory=dict)
    _feet: dict[tuple[Hashable, int], np.ndarray] = field(default_factory=dict)

    def face(self, member: int) -> FaceGeom | None:
        """The driving face of ``member`` with its frame (cached)."""
        if member not in self._geom:
            f = driving_face(self.members[member], self.params.foot_width_m)
            self._geom[member] = FaceGeom.of(f) if f is not None else None
        return self._geom[member]

    def pos(self, v: Hashable) -> np.ndarray:
        return np.asarray(self.graph.nodes[v]["pos"], float)

    def continuity(self, v: Hashable, a: int, b: int) -> Continuity | None:
        """Continuity of ``b``'s driving face after ``a``'s at ``v`` (cached);
        ``None`` when either has no face."""
        fa, fb = self.face(a), self.face(b)
        if fa is None or fb is None:
            return None
        key = (v, a, b)
        if key not in self._cont:
            self._cont[key] = face_continuity(
                fa, fb, self.pos(v), self.params, self.outline_slack_m
            )
        return self._cont[key]

    def feet(self, v: Hashable, member: int) -> np.ndarray:
        """Foot placements on ``member``'s driving face near ``v`` (cached)."""
        key = (v, member)
        if key not in self._feet:
            g = self.face(member)
            self._feet[key] = (
                np.zeros((0, 3))
                if g is None
                else foot_centres(g, self.pos(v), self.members[member].direction, self.params)
            )
        return self._feet[key]

    def standings(self, v: Hashable, member: int | None) -> tuple[np.ndarray, np.ndarray | None]:
        """Where the standing foot may be at ``v`` and its face's normal: every
        foot placement on the current face near the vertex; the vertex
        projected on the face when none fits; the vertex itself, normal
        ``None``, without a face."""
        p = self.pos(v)
        g = self.face(member) if member is not None else None
        if member is None or g is None:
            return p[None], None
        feet = self.feet(v, member)
        if len(feet):
            return feet, g.normal
        return (p - ((p - g.origin) @ g.normal) * g.normal)[None], g.normal

    def forced_jump(self, v: Hashable, member: int) -> bool:
        """Is every way through ``v`` from a span of ``member`` a jump?  (The
        edge-end charge of the module docstring.)"""
        spans = [
            int(d["member"])
            for _, _, d in self.graph.edges(v, data=True)
            if d.get("kind", "span") == "span"
        ]
        if len(spans) <= 1 or spans.count(member) >= 2:
            return False  # a free end (reverse on the member) or the member runs on
        for other in sorted(set(spans) - {member}):
            c = self.continuity(v, member, other)
            if c is not None and c.continues:
                return False
        return True

    def transition(
        self,
        route: int,
        index: int,
        v: Hashable,
        landing: Hashable,
        kind: str,
        a: int | None,
        b: int,
    ) -> Transition:
        """Mode and availability of going from member ``a`` at ``v`` onto
        member ``b`` at ``landing`` (Eq. 3.1: feasible = S_pa ∧ S_am ∧ S_hc)."""
        p = self.params
        fa = self.face(a) if a is not None else None
        fb = self.face(b)
        avail: dict[str, bool | float | int | None] = {
            "plane": fb is not None,
            "area": False,
            "height": False,
            "footholds": 0,
            "step_m": None,
            "outline_gap_m": None,
            "wrist_distance_m": None,
            "arm_length_m": p.arm_length_m,
            "reach_distance_m": None,
            "reach_limit_m": p.jump_reach_m,
        }
        angle = (
            math.degrees(math.acos(float(np.clip(fa.normal @ fb.normal, -1.0, 1.0))))
            if fa is not None and fb is not None
            else None
        )

        def make(mode: str, reason: str) -> Transition:
            feasible = bool(avail["plane"] and avail["area"] and avail["height"])
            return Transition(
                route=route,
                vertex=v,
                index_in_route=index,
                landing_vertex=landing,
                kind=kind,
                from_member=a,
                to_member=b,
                mode=mode,
                angle_deg=angle,
                from_face=fa.face.id if fa is not None else None,
                to_face=fb.face.id if fb is not None else None,
                availability=avail,
                feasible=feasible,
                reason=reason,
            )

        if fb is None:
            return make(
                "inchworm",
                f"member {b} has no faces: no surface to drive or land on (S_pa false, Eq. 3.2)",
            )
        feet = self.feet(landing, b)
        avail["footholds"] = len(feet)
        avail["area"] = len(feet) > 0
        no_room = (
            f"the {p.foot_length_m:.2f} × {p.foot_width_m:.2f} m foot fits nowhere on member "
            f"{b}'s face {fb.face.id} within {p.jump_reach_m:.2f} m of the vertex (S_am false)"
        )
        if kind in ("continue", "turnaround"):
            avail["step_m"], avail["outline_gap_m"], avail["height"] = 0.0, 0.0, True
            what = "drives on along" if kind == "continue" else "reverses on"
            return make(
                "mobile", f"{what} member {b}'s face {fb.face.id}" if feet.size else no_room
            )
        cont = self.continuity(v, a, b) if kind == "member" and a is not None else None
        if cont is not None:
            avail["step_m"] = cont.step_m
            avail["outline_gap_m"] = (
                cont.outline_gap_m if math.isfinite(cont.outline_gap_m) else None
            )
        if cont is not None and cont.continues:
            avail["height"] = True  # Eq. 3.4: the next plane is at the base height
            assert fa is not None  # continuity is only measured between two faces
            why = (
                f"face {fb.face.id} continues face {fa.face.id} "
                f"({cont.angle_deg:.1f}° ≤ {p.coplanar_angle_deg:g}°, step {cont.step_m * 1000:.0f} mm)"
            )
            return make("mobile", why if feet.size else no_room)
        # Inch-worm: S_hc, the arm's exact reach bound between the wrist points.
        if feet.size:
            stands, n_stand = self.standings(v, a)
            pv, pl = self.pos(v), self.pos(landing)
            stands = _nearest_first(stands, pv, p.reach_candidates)
            lands = _nearest_first(feet, pl, p.reach_candidates)
            wrist, i, j = nearest_wrists(stands, n_stand, lands, fb.normal, p)
            avail["wrist_distance_m"] = wrist
            avail["reach_distance_m"] = float(np.linalg.norm(lands[j] - stands[i]))
            avail["height"] = wrist <= p.arm_length_m + 1e-9
        if kind == "gap":
            why = f"jump across the gap onto member {b}"
        elif fa is None:
            why = f"member {a} has no faces to drive on: jump onto member {b}"
        else:
            assert cont is not None  # both faces exist on a member change
            fails = []
            if cont.angle_deg > p.coplanar_angle_deg:
                fails.append(f"normals {cont.angle_deg:.1f}° apart > {p.coplanar_angle_deg:g}°")
            if p.contact_tolerance_m < cont.step_m < math.inf:
                fails.append(f"step {cont.step_m * 1000:.0f} mm at the vertex")
            if cont.outline_gap_m > p.contact_tolerance_m + self.outline_slack_m and not fails:
                fails.append(f"outlines {cont.outline_gap_m * 1000:.0f} mm apart near the vertex")
            why = f"face {fb.face.id} does not continue face {fa.face.id} ({', '.join(fails)})"
        if not feet.size:
            return make("inchworm", f"{why}; {no_room}")
        if not avail["height"]:
            return make(
                "inchworm",
                f"{why}; out of the arm's reach: the nearest wrist points of a standing and a "
                f"landing placement are {avail['wrist_distance_m']:.3f} m apart > the "
                f"{p.arm_length_m:.2f} m arm (S_hc false)",
            )
        return make(
            "inchworm",
            f"{why}; wrist points {avail['wrist_distance_m']:.3f} m apart ≤ the "
            f"{p.arm_length_m:.2f} m arm (soles {avail['reach_distance_m']:.2f} m apart)",
        )


def _nearest_first(feet: np.ndarray, p: np.ndarray, cap: int) -> np.ndarray:
    """At most ``cap`` rows of ``feet``: all of them, or the ``cap`` nearest ``p``."""
    if len(feet) <= cap:
        return feet
    d = np.linalg.norm(feet - p, axis=1)
    return feet[np.argpartition(d, cap - 1)[:cap]]


def nearest_wrists(
    standing: np.ndarray,
    standing_normal: np.ndarray | None,
    landing: np.ndarray,
    landing_normal: np.ndarray,
    params: InspectionParams,
) -> tuple[float, int, int]:
    """The nearest wrist points of a standing and a landing foot placement:
    ``(distance m, index into standing, index into landing)``.

    ``standing`` (S, 3) and ``landing`` (L, 3) are sole centres on faces with
    the outward unit normals ``standing_normal`` and ``landing_normal``; a
    wrist point is the sole centre moved ``wrist_standing_m`` /
    ``wrist_landing_m`` along its normal.  ``standing_normal=None`` (the
    standing member has no face): the standing wrist may lie anywhere
    ``wrist_standing_m`` from the standing point, so the distance is the
    smallest over those, ``max(|w_l − s| − wrist_standing_m, 0)``.  One
    KD-tree query, O((S + L) log L); the callers cap S and L
    (``reach_candidates``).  Empty input: ``(inf, -1, -1)``."""
    s = np.asarray(standing, float).reshape(-1, 3)
    land = np.asarray(landing, float).reshape(-1, 3)
    if len(s) == 0 or len(land) == 0:
        return math.inf, -1, -1
    wl = land + params.wrist_landing_m * np.asarray(landing_normal, float)
    if standing_normal is None:
        ws = s
        slack = params.wrist_standing_m
    else:
        ws = s + params.wrist_standing_m * np.asarray(standing_normal, float)
        slack = 0.0
    d, j = cKDTree(wl).query(ws, k=1)
    dist, nearest = np.atleast_1d(np.asarray(d, float)), np.atleast_1d(np.asarray(j))
    i = int(np.argmin(dist))
    return max(float(dist[i]) - slack, 0.0), i, int(nearest[i])


def route_transitions(ctx: TransitionContext, route: Route, route_index: int) -> list[Transition]:
    """Every transition of ``route``, in driving order.

    Between two span edges ``edges[k-1]``, ``edges[k]`` at ``vertices[k]``:
    one transition (same member: continue or turnaround; else a member
    change).  A gap-jump edge ``edges[k]`` is one inch-worm transition at
    ``vertices[k]`` landing at ``vertices[k+1]``, from the member the robot
    was on (``edges[k-1]``'s, else the gap's own end member) onto the member
    it drives next (``edges[k+1]``'s, else the gap's end member); the pair
    (jump, next span) is its landing, not a second transition.
    """
    g = ctx.graph
    out: list[Transition] = []
    edges = route.edges
    data = [g.edges[e] for e in edges]
    for k, (e, d) in enumerate(zip(edges, data, strict=True)):
        if d.get("kind") == "jump":
            prev = data[k - 1] if k > 0 else None
            nxt = data[k + 1] if k + 1 < len(edges) else None
            ends: dict[Hashable, int] = d["ends"]
            a = prev["member"] if prev is not None and prev.get("kind") != "jump" else ends[e[0]]
            b = nxt["member"] if nxt is not None and nxt.get("kind") != "jump" else ends[e[1]]
            out.append(ctx.transition(route_index, k, e[0], e[1], "gap", a, b))
            continue
        if k == 0 or data[k - 1].get("kind") == "jump":
            continue
        prev_e, prev_d = edges[k - 1], data[k - 1]
        v = route.vertices[k]
        a, b = int(prev_d["member"]), int(d["member"])
        # Spans of one straight member: back where it came from, or on.
        kind = ("turnaround" if prev_e[0] == e[1] else "continue") if a == b else "member"
        out.append(ctx.transition(route_index, k, v, v, kind, a, b))
    return out
