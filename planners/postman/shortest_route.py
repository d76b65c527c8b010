"""Shortest route between two vertices of a small embedded graph (the
``demo.route`` kind; entry point :func:`plan_demo_route`): edge weights are
the Euclidean lengths between the vertex positions and the route is
Dijkstra's shortest path (networkx).  No seed equation: this is the
product's smallest end-to-end planner.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Hashable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import networkx as nx
import numpy as np

from planners.errors import InfeasibleError, InvalidInputError, UnknownVertexError
from planners.result import Check, PlanResult, check_le

# vertex id → position; Any keys because Mapping is invariant in its key type, so a
# dict[str, ...] would not be a Mapping[Hashable, ...]
Positions = Mapping[Any, Sequence[float]]


@dataclass(frozen=True)
class ShortestRoute:
    """The route's vertices, their positions (K,3) and its length (m)."""

    path: list[Hashable]
    xyz: np.ndarray
    length_m: float
    segment_m: np.ndarray
    graph_edges: int


def build_graph(nodes: Positions, edges: Sequence[tuple[Hashable, Hashable]]) -> nx.Graph:
    """The graph with Euclidean edge weights; an edge naming a vertex with no
    position raises :class:`planners.errors.UnknownVertexError`."""
    g: nx.Graph[Hashable] = nx.Graph()
    for node, pos in nodes.items():
        g.add_node(node, pos=tuple(pos))
    for u, v in edges:
        for w in (u, v):
            if w not in nodes:
                raise UnknownVertexError(
                    f"edge ({u}, {v}) names vertex {w!r}, which has no position"
                )
        g.add_edge(u, v, weight=float(np.linalg.norm(np.subtract(nodes[u], nodes[v]))))
    return g


def check_endpoints(g: nx.Graph, start: Hashable, end: Hashable) -> None:
    """Raise :class:`planners.errors.UnknownVertexError` unless both are vertices."""
    for role, v in (("start", start), ("end", end)):
        if v not in g:
            known = ", ".join(sorted(str(n) for n in g.nodes)[:10])
            raise UnknownVertexError(f"{role} vertex {v!r} is not in the graph (vertices: {known})")


def unit_grid_edges(nodes: Positions) -> list[tuple[Hashable, Hashable]]:
    """Every pair of vertices exactly 1 m apart (a unit grid's edges)."""
    keys = list(nodes)
    return [
        (u, v)
        for u in keys
        for v in keys
        if str(u) < str(v) and np.isclose(np.linalg.norm(np.subtract(nodes[u], nodes[v])), 1.0)
    ]


def shortest_route(
    nodes: Positions,
    edges: Sequence[tuple[Hashable, Hashable]],
    start: Hashable,
    end: Hashable,
) -> ShortestRoute:
    """Dijkstra's shortest path from ``start`` to ``end``; raises
    :class:`planners.errors.InfeasibleError` when they are not connected."""
    g = build_graph(nodes, edges)
    check_endpoints(g, start, end)
    try:
        path = nx.dijkstra_path(g, start, end, weight="weight")
    except nx.NetworkXNoPath:
        raise InfeasibleError(
            f"no path from {start!r} to {end!r}: they lie in different components"
        ) from None
    xyz = np.array([nodes[v] for v in path], dtype=float).reshape(-1, 3)
    seg = np.linalg.norm(np.diff(xyz, axis=0), axis=1)
    length = float(seg.sum())
    if not np.isfinite(length):
        raise InvalidInputError("route length is not finite; check the vertex positions")
    return ShortestRoute(path, xyz, length, seg, g.number_of_edges())


def plan_demo_route(
    nodes: Positions,
    edges: Sequence[tuple[Hashable, Hashable]],
    start: Hashable,
    end: Hashable,
    *,
    max_length_m: float,
    step_delay_s: float = 0.0,
    progress: Callable[[float, str], None] | None = None,
) -> PlanResult:
    """The ``demo.route`` plan: Dijkstra's shortest route (:func:`shortest_route`)
    in the stored form.

    Summary: ``nodes`` (id → [x, y, z]), ``edges`` ([u, v] lists) and
    ``path`` (vertex ids).  Array: ``path_xyz`` (K,3).  Checks: ``route_found``
    (the walk runs from ``start`` to ``end``) and ``route_length`` (≤
    ``max_length_m``).  Metrics: route_length_m, route_vertices, graph_edges,
    planning_time_s.  The route is reported step by step to ``progress``,
    pausing ``step_delay_s`` before each step so that progress and
    cancellation are visible in demos (``progress`` may raise
    :class:`planners.errors.CancelledError`).
    """
    t0 = time.perf_counter()

    def prog(f: float, stage: str) -> None:
        if progress is not None:
            progress(f, stage)

    prog(0.05, "graph")
    check_endpoints(build_graph(nodes, edges), start, end)
    prog(0.2, "shortest path")
    route = shortest_route(nodes, edges, start, end)
    path, length = route.path, route.length_m
    n = len(route.segment_m)
    for i in range(n):
        if step_delay_s:
            time.sleep(step_delay_s)
        prog(0.2 + 0.75 * (i + 1) / max(n, 1), f"step {i + 1}/{n}")
    checks = [
        Check(
            name="route_found",
            passed=bool(path[0] == start and path[-1] == end),
            value=f"{path[0]}→{path[-1]}",
            limit=f"{start}→{end}",
            message=f"route runs from {path[0]} to {path[-1]}",
        ),
        check_le("route_length", length, max_length_m, "route length", " m"),
    ]
    summary: dict[str, Any] = {
        "nodes": {str(k): [float(c) for c in pos] for k, pos in nodes.items()},
        "edges": [list(e) for e in edges],
        "path": path,
    }
    metrics = {
        "route_length_m": length,
        "route_vertices": float(len(path)),
        "graph_edges": float(route.graph_edges),
        "planning_time_s": time.perf_counter() - t0,
    }
    return PlanResult(summary, {"path_xyz": route.xyz}, checks, metrics)
