"""The ARA inspection route over a 3D structure model.

:func:`plan_inspection` chains:

1. validation of the :class:`~planners.structure.model.StructureModel`;
2. gaps (:mod:`.gaps`): the pieces of a disconnected member graph, the
   minimum spanning tree of their span-to-span distances, and jump edges
   across the gaps within the jump reach;
3. routing weights: span length + the jump-cost estimate of
   :mod:`.transitions` (jump edges: gap width + one jump cost);
4. per piece still disconnected, the exact VOCPP route
   (:func:`planners.vocpp.plan_route`, the seed's Alg. 5 solved exactly as a
   minimum T-join + Euler trail) between two far-apart free ends unless the
   caller fixes ``start``/``end``;
5. the transitions along every route (:mod:`.transitions`: seed §3.1,
   Eq. 3.1–3.4, the mode and S_pa/S_am/S_hc at each vertex).
"""

from __future__ import annotations

import math
import time
from collections.abc import Hashable
from dataclasses import dataclass, field, replace

import networkx as nx
import numpy as np

from planners.errors import (
    DisconnectedGraphError,
    EmptyInputError,
    InvalidInputError,
    InvalidWeightError,
    UnknownVertexError,
)
from planners.inspection.close import close_route
from planners.inspection.faces import placeable
from planners.inspection.gaps import Gap, component_gaps, join_gaps
from planners.inspection.params import InspectionParams
from planners.inspection.route_repair import repair_route, transition_cost
from planners.inspection.transitions import Transition, TransitionContext
from planners.structure.model import Member, StructureModel
from planners.vocpp import Route, plan_route

__all__ = ["InspectionPlan", "plan_inspection", "reachable_members"]


@dataclass
class InspectionPlan:
    """Result of :func:`plan_inspection`.

    - ``route``: the main route, ``routes[0]`` — the piece holding ``start``
      / ``end`` when given, else the piece with the most steel.  Its edges
      are ``(u, v, key)`` of ``graph``; ``length``, ``deadhead`` and
      ``lower_bound`` are metres of steel (jump edges count 0), while
      ``optimality_gap`` refers to the routing weights (steel + jump cost
      estimate) it was optimised for.
    - ``routes``: one route per piece left disconnected after joining the
      gaps, main first, the rest by decreasing steel; the robot has to be
      carried between them.
    - ``transitions``: every transition along every route, in order.
    - ``gaps``: the k − 1 gaps of the minimum spanning tree between the k
      pieces of the model graph (empty when connected).
    - ``components``: member ids of each piece of the *model* graph, most
      steel first; ``Gap.component_a``/``_b`` index this list.
    - ``jumps``: inch-worm transitions over all routes; ``length_m``: steel
      driven over all routes; ``lower_bound_m``: the sum of all span
      lengths (every span once).
    - ``covered_members``: members the main route drives;
      ``uncovered_members``: every other member of the model (driven only by
      another route, or without any span in the graph).
    - ``unreachable_members``: members the main route drives that the ARA
      cannot get onto from the route's first member by any chain of
      feasible transitions at the vertices of the routing graph
      (:func:`reachable_members`): no route could inspect them, wherever it
      went; ``blocked``: the failing transitions onto them from members it
      can reach.  (The route itself is chosen without the feasibility —
      :mod:`.transitions` explains why no edge weight can carry it — so it
      may still pass a transition that fails between two reachable members;
      ``transitions_feasible`` names those.)
    - ``graph``: the routing graph — the model graph plus ``"split"``
      vertices and ``kind="jump"`` edges; ``timings_s``: seconds per stage.
    """

    route: Route
    routes: list[Route]
    transitions: list[Transition]
    gaps: list[Gap]
    components: list[tuple[int, ...]]
    jumps: int
    length_m: float
    lower_bound_m: float
    covered_members: list[int]
    uncovered_members: list[int]
    graph: nx.MultiGraph
    params: InspectionParams
    timings_s: dict[str, float] = field(default_factory=dict)
    unreachable_members: list[int] = field(default_factory=list)
    blocked: list[Transition] = field(default_factory=list)

    @property
    def infeasible(self) -> list[Transition]:
        """Transitions whose availability checks fail (Eq. 3.1 false for the mode)."""
        return [t for t in self.transitions if not t.feasible]


def plan_inspection(
    model: StructureModel,
    *,
    start: Hashable | None = None,
    end: Hashable | None = None,
    params: InspectionParams | None = None,
) -> InspectionPlan:
    """Inspection route over every member span of ``model`` with the ARA's
    mobile / inch-worm transitions (seed §3.1 Eq. 3.1–3.4, Alg. 2, Alg. 5).

    ``start``/``end``: vertices of ``model.graph``; ``None`` picks, in each
    piece, the two ``"end"`` vertices furthest apart (any two vertices
    furthest apart when a piece has fewer than two free ends); one given, the
    other is the free end furthest from it.  A start picked so lies on a
    member with a face the foot fits across, where the piece has one among
    those vertices (the crew sets the robot down there; every later member
    is landed on by a checked transition).

    Raises (``planners.errors``, all ``ValueError``): ``InvalidInputError``
    (not a StructureModel / InspectionParams, a directed graph, a vertex
    without a finite (3,) ``pos``, a span whose ``member`` is not a member
    id), ``InvalidWeightError`` (a span ``weight`` missing, negative or not
    finite), ``EmptyInputError`` (no member spans), ``UnknownVertexError``
    (``start``/``end`` not a vertex), ``DisconnectedGraphError`` (``start``
    and ``end`` in pieces no jump joins, or on a vertex without spans).
    Structures themselves — disconnected, faceless members, unreachable
    landings — never raise: they are reported in the plan.
    """
    t0 = time.perf_counter()
    timings: dict[str, float] = {}
    if params is None:
        params = InspectionParams()
    if not isinstance(params, InspectionParams):
        raise InvalidInputError(f"params must be an InspectionParams, got {type(params).__name__}")
    members = _validate(model)
    for name, v in (("start", start), ("end", end)):
        if v is not None and not _has_node(model.graph, v):
            raise UnknownVertexError(f"{name} vertex {v!r} is not a vertex of the model graph")
    graph = _routing_graph(model.graph)
    timings["validate"] = time.perf_counter() - t0

    t = time.perf_counter()
    pieces = _pieces(graph)
    components = [
        tuple(sorted({int(d["member"]) for _, _, d in graph.subgraph(p).edges(data=True)}))
        for p in pieces
    ]
    gaps = _gaps(graph, pieces, params)  # splits spans and adds jump edges in ``graph``
    timings["gaps"] = time.perf_counter() - t

    t = time.perf_counter()
    # outlines are drawn through the outermost points: each may stop a spacing short
    spacing = float(model.spacing_m)
    slack = 2.0 * spacing if math.isfinite(spacing) and spacing > 0 else 0.0
    ctx = TransitionContext(members, graph, params, outline_slack_m=slack)
    half = params.jump_cost_m / 2
    for u, v, d in graph.edges(data=True):
        if d["kind"] == "jump":
            d["route_weight"] = float(d["weight"]) + params.jump_cost_m
        else:
            m = int(d["member"])
            forced = int(ctx.forced_jump(u, m)) + int(ctx.forced_jump(v, m))
            d["route_weight"] = float(d["steel_m"]) + half * forced
    timings["weights"] = time.perf_counter() - t

    t = time.perf_counter()
    parts = _pieces(graph)  # after joining
    can_start = frozenset(m.id for m in model.members if placeable(m, params.foot_width_m))
    fixed = [x for x in (start, end) if x is not None]
    homes = {i for i, p in enumerate(parts) for x in fixed if x in p}
    if fixed and len(homes) != 1:
        raise DisconnectedGraphError(
            f"start {start!r} and end {end!r} are not on spans of one piece of the structure "
            "(pieces no jump within reach joins, or a vertex without spans); "
            "give vertices of one piece or None"
        )
    steel = [
        math.fsum(float(d["steel_m"]) for _, _, d in graph.subgraph(p).edges(data=True))
        for p in parts
    ]
    order = sorted(range(len(parts)), key=lambda i: (-steel[i], _min_member(graph, parts[i])))
    if fixed:
        main = homes.pop()
        order.remove(main)
        order.insert(0, main)
    routes: list[Route] = []
    if params.close_member is not None:
        order = order[:1]  # one route: the piece holding start (or the largest)
    for rank, i in enumerate(order):
        sub: nx.MultiGraph = nx.MultiGraph(graph.subgraph(parts[i]))
        s, e = _ends(sub, start if rank == 0 else None, end if rank == 0 else None, can_start)
        if params.close_member is not None:
            r = close_route(sub, s, params.close_member, weight="route_weight")
            need = math.fsum(
                float(graph.edges[x]["steel_m"])
                for x in r.edges
                if graph.edges[x].get("kind") == "span"
                and int(graph.edges[x]["member"]) == params.close_member
            )
        else:
            free_start = start is None and end is None if rank == 0 else True
            r = _best_route(ctx, sub, s, e, rank, can_start if free_start else None)
            need = steel[i]
        driven = math.fsum(float(graph.edges[x]["steel_m"]) for x in r.edges)
        routes.append(replace(r, length=driven, deadhead=driven - need, lower_bound=need))
    timings["route"] = time.perf_counter() - t

    t = time.perf_counter()
    # The walk's passes through each joint re-paired so that its member changes
    # are ones the robot can make where the same coverage allows it.
    transitions = []
    for i, r in enumerate(routes):
        routes[i], got = repair_route(ctx, r, i)
        transitions += got
    timings["transitions"] = time.perf_counter() - t

    covered = sorted(
        {int(graph.edges[x]["member"]) for x in routes[0].edges if graph.edges[x]["kind"] == "span"}
    )
    t = time.perf_counter()
    first = next(
        (
            int(graph.edges[x]["member"])
            for x in routes[0].edges
            if graph.edges[x]["kind"] == "span"
        ),
        None,
    )
    reach, blocked = reachable_members(ctx, first) if first is not None else (set(), [])
    unreachable = sorted(set(covered) - reach)
    blocked = [b for b in blocked if b.to_member in set(unreachable)]
    timings["reach"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - t0
    return InspectionPlan(
        route=routes[0],
        routes=routes,
        transitions=transitions,
        gaps=gaps,
        components=components,
        jumps=sum(tr.mode == "inchworm" for tr in transitions),
        length_m=math.fsum(r.length for r in routes),
        lower_bound_m=math.fsum(float(d["weight"]) for _, _, d in model.graph.edges(data=True)),
        covered_members=covered,
        uncovered_members=sorted(set(members) - set(covered)),
        graph=graph,
        params=params,
        timings_s=timings,
        unreachable_members=unreachable,
        blocked=blocked,
    )


def reachable_members(ctx: TransitionContext, first: int) -> tuple[set[int], list[Transition]]:
    """Members the ARA can get onto from ``first`` by feasible transitions,
    and the failing transitions from those members onto the others.

    The robot drives all along a member (its spans, mobile), so from a
    member it can try every member change at every vertex the member's spans
    meet: each ordered pair of distinct members with spans at a vertex is a
    transition (:meth:`TransitionContext.transition`, the same checks the
    route's transitions get), and each jump edge across a gap one either
    way.  A breadth-first search over the feasible ones.  Costs one
    transition per ordered pair at each vertex (the faces and foot
    placements are cached per member and vertex)."""
    g = ctx.graph
    out: dict[int, list[tuple[Hashable, Hashable, str, int]]] = {}
    for v in g.nodes:
        ms = sorted(
            {int(d["member"]) for _, _, d in g.edges(v, data=True) if d.get("kind") == "span"}
        )
        for a in ms:
            out.setdefault(a, []).extend((v, v, "member", b) for b in ms if b != a)
    for u, v, d in g.edges(data=True):
        if d.get("kind") == "jump":
            ends = d["ends"]
            a, b = int(ends[u]), int(ends[v])
            out.setdefault(a, []).append((u, v, "gap", b))
            out.setdefault(b, []).append((v, u, "gap", a))
    seen, todo, failed = {first}, [first], []
    while todo:
        a = todo.pop()
        for v, landing, kind, b in out.get(a, []):
            if b in seen:
                continue
            t = ctx.transition(0, 0, v, landing, kind, a, b)
            if t.feasible:
                seen.add(b)
                todo.append(b)
            else:
                failed.append(t)
    return seen, [t for t in failed if t.to_member not in seen]


#: Start vertices a route is tried from when the request names none.
MAX_START_CANDIDATES = 12


def _best_route(
    ctx: TransitionContext,
    sub: nx.MultiGraph,
    s: Hashable,
    e: Hashable,
    rank: int,
    placeable: frozenset[int] | None,
) -> Route:
    """The piece's covering walk (Alg. 5) from ``s`` to ``e``; when the start
    is free (``placeable`` given), also from up to
    :data:`MAX_START_CANDIDATES` other vertices where the robot can be set
    down (free ends first; each to the free end farthest from it), keeping the walk with the
    fewest infeasible transitions after :func:`repair_route`, then the
    fewest jumps, then the shortest; ties keep the far-apart default."""
    best = plan_route(sub, s, e, weight="route_weight")
    if placeable is None:
        return best
    key = transition_cost(repair_route(ctx, best, rank)[1])
    if key[0] == 0:
        return best
    # Free ends first (where a crew sets a robot down), then joints; far from
    # the default start first.  Only vertices on a member the foot fits across.
    here = np.asarray(sub.nodes[s]["pos"], float)
    order = sorted(
        (n for n in sub.nodes if n != s and sub.degree(n) > 0),
        key=lambda n: (
            sub.nodes[n].get("kind") != "end",
            -float(np.linalg.norm(np.asarray(sub.nodes[n]["pos"], float) - here)),
            repr(n),
        ),
    )
    ok = [n for n in order if _on_placeable(sub, n, placeable)]
    for c in ok[: MAX_START_CANDIDATES - 1]:
        cs, ce = _ends(sub, c, None, placeable)
        r = plan_route(sub, cs, ce, weight="route_weight")
        k = transition_cost(repair_route(ctx, r, rank)[1])
        if (k, r.length) < (key, best.length):
            best, key = r, k
        if key[0] == 0:
            break
    return best


def _on_placeable(g: nx.MultiGraph, n: Hashable, placeable: frozenset[int]) -> bool:
    """Whether vertex ``n`` ends a span of a member the robot can be set down on."""
    return any(
        d.get("kind", "span") == "span" and int(d.get("member", -1)) in placeable
        for _, _, d in g.edges(n, data=True)
    )


def _has_node(g: nx.MultiGraph, v: object) -> bool:
    try:
        return v in g
    except TypeError:  # unhashable: cannot be a vertex
        return False


def _validate(model: StructureModel) -> dict[int, Member]:
    """Check the model against the StructureModel contract; members by id."""
    if not isinstance(model, StructureModel):
        raise InvalidInputError(f"model must be a StructureModel, got {type(model).__name__}")
    g = model.graph
    if not isinstance(g, nx.Graph) or g.is_directed():
        raise InvalidInputError("model.graph must be an undirected networkx (Multi)Graph")
    if g.number_of_edges() == 0:
        raise EmptyInputError("the model has no member spans to inspect (model.graph has no edges)")
    members = {int(m.id): m for m in model.members}
    for n, d in g.nodes(data=True):
        pos = np.asarray(d.get("pos", np.full(3, np.nan)), float)
        if pos.shape != (3,) or not np.isfinite(pos).all():
            raise InvalidInputError(f"vertex {n!r} needs a finite (3,) pos, got {d.get('pos')!r}")
    for u, v, d in g.edges(data=True):
        if d.get("member") not in members:
            raise InvalidInputError(
                f"span {u!r}–{v!r} has member {d.get('member')!r}, not one of the model's member ids"
            )
        w = d.get("weight")
        if not (isinstance(w, int | float | np.floating) and math.isfinite(w) and w >= 0):
            raise InvalidWeightError(f"span {u!r}–{v!r} needs a finite weight ≥ 0 m, got {w!r}")
    return members


def _routing_graph(g: nx.Graph) -> nx.MultiGraph:
    """A MultiGraph copy (new attribute dicts; a MultiGraph keeps its keys, a
    Graph's edges get key 0) whose spans carry ``kind="span"`` and ``steel_m``."""
    out: nx.MultiGraph = nx.MultiGraph(g)
    for _, _, d in out.edges(data=True):
        d.update(kind="span", steel_m=float(d["weight"]), member=int(d["member"]))
    return out


def _pieces(g: nx.MultiGraph) -> list[set[Hashable]]:
    """Connected components of the spans (isolated vertices left out)."""
    with_edges = g.edge_subgraph(list(g.edges(keys=True)))
    comps = [set(c) for c in nx.connected_components(with_edges)]
    steel = [
        math.fsum(float(d["steel_m"]) for _, _, d in g.subgraph(c).edges(data=True)) for c in comps
    ]
    order = sorted(range(len(comps)), key=lambda i: (-steel[i], _min_member(g, comps[i])))
    return [comps[i] for i in order]


def _min_member(g: nx.MultiGraph, nodes: set[Hashable]) -> int:
    ids = [
        int(d["member"])
        for _, _, d in g.subgraph(nodes).edges(data=True)
        if d["member"] is not None
    ]
    return min(ids, default=-1)


def _gaps(g: nx.MultiGraph, pieces: list[set[Hashable]], params: InspectionParams) -> list[Gap]:
    """MST gaps between the pieces; the ones within reach joined in ``g``."""
    if len(pieces) <= 1:
        return []
    where = {n: i for i, p in enumerate(pieces) for n in p}
    spans = list(g.edges(keys=True))
    p0 = np.array([g.nodes[u]["pos"] for u, _, _ in spans], float)
    p1 = np.array([g.nodes[v]["pos"] for _, v, _ in spans], float)
    comp = np.array([where[u] for u, _, _ in spans])
    found = component_gaps(p0, p1, comp, len(pieces))
    gaps, at = [], []
    for d, i, j, s, t in found:
        ca, cb = int(comp[i]), int(comp[j])
        if ca > cb:  # report the larger piece (lower index) first
            ca, cb, i, j, s, t = cb, ca, j, i, t, s
        gaps.append(
            Gap(
                component_a=ca,
                component_b=cb,
                point_a=p0[i] + s * (p1[i] - p0[i]),
                point_b=p0[j] + t * (p1[j] - p0[j]),
                width_m=d,
                joined=d <= params.jump_reach_m,
                member_a=int(g.edges[spans[i]]["member"]),
                member_b=int(g.edges[spans[j]]["member"]),
            )
        )
        at.append((i, s, j, t))
    _, joined = join_gaps(g, spans, gaps, at)
    return joined


def _ends(
    g: nx.MultiGraph,
    start: Hashable | None,
    end: Hashable | None,
    placeable: frozenset[int] = frozenset(),
) -> tuple[Hashable, Hashable]:
    """Start and end of a piece's route: the given ones, else far-apart free
    ends, the start on a span of a ``placeable`` member where one is in the
    pool (the crew sets the ARA down on the start member: it needs a face
    the foot fits across; every later member is landed on by a transition,
    whose checks look at that)."""
    if start is not None and end is not None:
        return start, end
    nodes = [n for n in g.nodes if g.degree(n) > 0]
    free = [n for n in nodes if g.nodes[n].get("kind") == "end"]
    fixed = start if start is not None else end
    pool = free if len(free) >= (1 if fixed is not None else 2) else nodes
    pos = np.array([g.nodes[n]["pos"] for n in pool], float)
    if start is not None:
        others = [i for i, n in enumerate(pool) if n != start]
        if not others:
            return start, start
        dist = np.linalg.norm(pos[others] - np.asarray(g.nodes[start]["pos"], float), axis=1)
        return start, pool[others[int(np.argmax(dist))]]
    ok = np.array([_on_placeable(g, n, placeable) for n in pool], dtype=bool)
    if end is not None:
        others = [i for i, n in enumerate(pool) if n != end]
        if not others:
            return end, end
        if ok[others].any():
            others = [i for i in others if ok[i]]
        dist = np.linalg.norm(pos[others] - np.asarray(g.nodes[end]["pos"], float), axis=1)
        return pool[others[int(np.argmax(dist))]], end
    if len(pool) < 2:
        return pool[0], pool[0]
    starts = np.flatnonzero(ok) if ok.any() else np.arange(len(pool))
    best, pair = -1.0, (0, 1)
    for i in starts:  # O(n) memory: one row of distances at a time
        dist = np.linalg.norm(pos - pos[i], axis=1)
        dist[i] = -1.0
        j = int(np.argmax(dist))
        if float(dist[j]) > best:
            best, pair = float(dist[j]), (int(i), j)
    return pool[pair[0]], pool[pair[1]]
