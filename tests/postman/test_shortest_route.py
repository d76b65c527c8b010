"""planners.postman.shortest_route against brute force over all simple paths, and
the ``demo.route`` entry point's stored form."""

from __future__ import annotations

import itertools
import json

import networkx as nx
import numpy as np
import pytest

from planners.errors import CancelledError, InfeasibleError, UnknownVertexError
from planners.postman.shortest_route import plan_demo_route, shortest_route, unit_grid_edges
from planners.result import Check


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


def test_plan_demo_route_stored_form_checks_and_progress() -> None:
    nodes = {f"{'abc'[i]}{j}": [float(i), float(j), 0.0] for i in range(3) for j in range(3)}
    edges = unit_grid_edges(nodes)
    calls: list[tuple[float, str]] = []
    r = plan_demo_route(
        nodes, edges, "a0", "c1", max_length_m=3.0, progress=lambda f, s: calls.append((f, s))
    )
    json.dumps(r.summary, allow_nan=False)
    assert r.summary["nodes"] == nodes and r.summary["edges"] == [list(e) for e in edges]
    path = r.summary["path"]
    assert path[0] == "a0" and path[-1] == "c1" and len(path) == 4
    xyz = r.arrays["path_xyz"]
    assert xyz.shape == (4, 3) and xyz.dtype == np.float64
    assert np.array_equal(xyz, [nodes[v] for v in path])
    length = float(np.linalg.norm(np.diff(xyz, axis=0), axis=1).sum())
    assert length == pytest.approx(_brute(nodes, edges, "a0", "c1")) == pytest.approx(3.0)
    found, within = r.checks
    assert found == Check("route_found", True, "a0→c1", "a0→c1", "route runs from a0 to c1")
    assert within.name == "route_length" and within.passed  # 3 m ≤ 3 m
    assert within.value == pytest.approx(length) and within.limit == 3.0
    assert within.message == "route length 3 m ≤ 3 m"
    assert r.metrics["route_length_m"] == pytest.approx(length)
    assert r.metrics["route_vertices"] == 4.0 and r.metrics["graph_edges"] == 12.0
    assert r.metrics["planning_time_s"] >= 0.0
    # progress: graph, search, then one report per route step up to 0.95
    assert [s for _, s in calls] == ["graph", "shortest path", "step 1/3", "step 2/3", "step 3/3"]
    fs = [f for f, _ in calls]
    assert fs == sorted(fs) and fs[-1] == pytest.approx(0.95)
    # a tighter limit fails the length check, the route is still stored
    tight = plan_demo_route(nodes, edges, "a0", "c1", max_length_m=2.5)
    assert not tight.passed and tight.checks[1].message == "route length 3 m > 2.5 m"


def test_plan_demo_route_pauses_cancels_and_refuses_bad_endpoints(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import planners.postman.shortest_route as sr

    nodes = {f"{'abc'[i]}{j}": [float(i), float(j), 0.0] for i in range(3) for j in range(3)}
    edges = unit_grid_edges(nodes)
    slept: list[float] = []
    monkeypatch.setattr(sr.time, "sleep", slept.append)
    plan_demo_route(nodes, edges, "a0", "c2", max_length_m=10, step_delay_s=0.25)
    assert slept == [0.25] * 4  # one pause before each of the 4 steps
    slept.clear()
    plan_demo_route(nodes, edges, "a0", "c2", max_length_m=10)
    assert slept == []

    def cancel_at_step_two(f: float, stage: str) -> None:
        if stage == "step 2/4":
            raise CancelledError("cancelled")

    with pytest.raises(CancelledError):
        plan_demo_route(nodes, edges, "a0", "c2", max_length_m=10, progress=cancel_at_step_two)
    with pytest.raises(UnknownVertexError, match="start vertex 'zz'"):
        plan_demo_route(nodes, edges, "zz", "c2", max_length_m=10)
