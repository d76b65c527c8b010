"""planners.postman.shortest_route against brute force over all simple paths."""

from __future__ import annotations

import itertools

import networkx as nx
import numpy as np
import pytest

from planners.errors import InfeasibleError, UnknownVertexError
from planners.postman.shortest_route import shortest_route, unit_grid_edges


def _brute(nodes: dict[str, list[float]], edges: list[tuple[str, str]], s: str, t: str) -> float:
    g = nx.Graph(edges)
    best = np.inf
    for path in nx.all_simple_paths(g, s, t):
        xyz = np.array([nodes[v] for v in path])
        best = min(best, float(np.linalg.norm(np.diff(xyz, axis=0), axis=1).sum()))
    return best


def test_random_geometric_graphs_match_brute_force() -> None:
    rng = np.random.default_rng(4)
    for trial in range(10):
        nodes = {f"v{i}": rng.uniform(0, 3, size=3).tolist() for i in range(7)}
        pairs = list(itertools.combinations(nodes, 2))
        edges = [pairs[i] for i in rng.choice(len(pairs), size=12, replace=False)]
        g = nx.Graph(edges)
        if "v0" not in g or "v6" not in g or not nx.has_path(g, "v0", "v6"):
            continue
        r = shortest_route(nodes, edges, "v0", "v6")
        assert r.length_m == pytest.approx(_brute(nodes, edges, "v0", "v6")), trial
        assert r.path[0] == "v0" and r.path[-1] == "v6"
        assert np.allclose(r.xyz, [nodes[v] for v in r.path])
        assert r.segment_m.sum() == pytest.approx(r.length_m)


def test_unit_grid_and_errors() -> None:
    nodes = {f"{'abc'[i]}{j}": [float(i), float(j), 0.0] for i in range(3) for j in range(3)}
    edges = unit_grid_edges(nodes)
    assert len(edges) == 12  # a 3 × 3 grid has 2·3·2 unit edges
    assert shortest_route(nodes, edges, "a0", "c2").length_m == pytest.approx(4.0)
    with pytest.raises(UnknownVertexError):
        shortest_route(nodes, [*edges, ("a0", "zz")], "a0", "c2")
    with pytest.raises(UnknownVertexError):
        shortest_route(nodes, edges, "a0", "nowhere")
    with pytest.raises(InfeasibleError):
        shortest_route({**nodes, "d9": [9.0, 9.0, 0.0]}, edges, "a0", "d9")
