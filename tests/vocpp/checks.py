"""Route validity checks shared by the VOCPP tests (independent of planners.postman)."""

from __future__ import annotations

import math
from collections import Counter

import networkx as nx


def edge_id(graph: nx.Graph, a, b, k):
    """An orientation-free identity for the edge ``(a, b, k)`` (key ignored for a Graph)."""
    return (frozenset((a, b)), k if graph.is_multigraph() else 0)


def edge_weight(graph: nx.Graph, a, b, k, weight: str | None = "weight") -> float:
    data = graph[a][b][k] if graph.is_multigraph() else graph[a][b]
    return 1.0 if weight is None else float(data[weight])


def assert_valid_route(graph: nx.Graph, route, start, end, weight: str | None = "weight") -> None:
    """The walk is connected, uses real edges, covers each edge, and its numbers add up."""
    assert route.vertices[0] == start
    assert route.vertices[-1] == end
    assert route.start == start and route.end == end
    assert len(route.vertices) == len(route.edges) + 1
    driven = Counter()
    total = []
    for i, (a, b, k) in enumerate(route.edges):
        assert route.vertices[i] == a, (i, route.vertices[i], a)
        assert route.vertices[i + 1] == b
        if graph.is_multigraph():
            assert graph.has_edge(a, b, k), (a, b, k)
        else:
            assert k == 0 and graph.has_edge(a, b), (a, b, k)
        driven[edge_id(graph, a, b, k)] += 1
        total.append(edge_weight(graph, a, b, k, weight))
    every = Counter(
        edge_id(graph, a, b, k)
        for a, b, k in (
            graph.edges(keys=True)
            if graph.is_multigraph()
            else ((a, b, 0) for a, b in graph.edges())
        )
    )
    extra = Counter(edge_id(graph, a, b, k) for a, b, k in route.added_edges)
    # Each edge is driven once plus once per repetition in added_edges - no more, no less.
    assert driven == every + extra
    lower = math.fsum(edge_weight(graph, *e, weight) for e in _all_edges(graph))
    assert math.isclose(route.lower_bound, lower, rel_tol=1e-12, abs_tol=1e-12)
    assert route.length == route.lower_bound + route.deadhead
    assert math.isclose(route.length, math.fsum(total), rel_tol=1e-12, abs_tol=1e-12)
    dead = math.fsum(edge_weight(graph, *e, weight) for e in route.added_edges)
    assert math.isclose(route.deadhead, dead, rel_tol=1e-12, abs_tol=1e-12)


def _all_edges(graph: nx.Graph):
    if graph.is_multigraph():
        return list(graph.edges(keys=True))
    return [(a, b, 0) for a, b in graph.edges()]
