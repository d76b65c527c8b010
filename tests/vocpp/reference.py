"""Independent exact postman optima for tests (no code shared with planners.postman).

- :func:`metric_closure_optimum`: networkx shortest paths between the T vertices and
  networkx's blossom ``min_weight_matching`` on that complete graph (Edmonds & Johnson 1973);
- :func:`milp_optimum`: integer LP over edge-repeat counts with degree-parity constraints
  (scipy ``milp``/HiGHS), a second method sharing nothing with the first.
"""

from __future__ import annotations

import itertools
import math

import networkx as nx
import numpy as np
import scipy.sparse as sp
from scipy.optimize import Bounds, LinearConstraint, milp


def terminals(graph: nx.Graph, start, end) -> set:
    """``odd(G) Δ {start, end}`` (networkx degrees: a self-loop counts 2)."""
    t = {v for v, d in graph.degree() if d % 2}
    return t ^ {start} ^ {end}


def total_weight(graph: nx.Graph, weight: str = "weight") -> float:
    return math.fsum(d for *_, d in graph.edges(data=weight))


def metric_closure_matching(graph: nx.Graph, tset: set, weight: str = "weight"):
    """Minimum perfect matching of ``tset`` under shortest-path distances: (cost, pairs, paths)."""
    tl = list(tset)
    dist, paths = {}, {}
    for a in tl:
        d, p = nx.single_source_dijkstra(graph, a, weight=weight)
        dist[a], paths[a] = d, p
    k = nx.Graph()
    for a, b in itertools.combinations(tl, 2):
        k.add_edge(a, b, weight=dist[a][b])
    pairs = nx.min_weight_matching(k) if tl else set()
    cost = math.fsum(dist[a][b] for a, b in pairs)
    return cost, pairs, {(a, b): paths[a][b] for a, b in pairs}


def metric_closure_optimum(graph: nx.Graph, start, end, weight: str = "weight") -> float:
    """Shortest covering walk length by the metric-closure matching (networkx only)."""
    cost, _, _ = metric_closure_matching(graph, terminals(graph, start, end), weight)
    return total_weight(graph, weight) + cost


def milp_optimum(graph: nx.Graph, start, end, weight: str = "weight") -> float:
    """Shortest covering walk length by integer programming over repeat counts.

    Variables ``x_e ∈ {0, 1}`` (repeat edge ``e``; repeating twice is never needed) and
    ``y_v ≥ 0`` integer with ``Σ_{e∋v} x_e − 2 y_v = [v ∈ T]``; self-loops are left out
    (they never change a parity).  Minimise ``Σ w_e x_e``.
    """
    nodes = list(graph.nodes)
    idx = {v: i for i, v in enumerate(nodes)}
    es = [(idx[a], idx[b], w) for a, b, w in graph.edges(data=weight) if a != b]
    tset = terminals(graph, start, end)
    n, m = len(nodes), len(es)
    if not tset:
        return total_weight(graph, weight)
    rows, cols, vals = [], [], []
    for j, (a, b, _) in enumerate(es):
        rows += [a, b]
        cols += [j, j]
        vals += [1, 1]
    for i in range(n):
        rows.append(i)
        cols.append(m + i)
        vals.append(-2)
    a_mat = sp.csr_matrix((vals, (rows, cols)), shape=(n, m + n))
    rhs = np.array([1.0 if v in tset else 0.0 for v in nodes])
    c = np.concatenate([[w for *_, w in es], np.zeros(n)])
    ub = np.concatenate([np.ones(m), np.full(n, m)])
    res = milp(
        c,
        constraints=LinearConstraint(a_mat, rhs, rhs),
        integrality=np.ones(m + n),
        bounds=Bounds(np.zeros(m + n), ub),
        options={"mip_rel_gap": 0.0},
    )
    assert res.status == 0, res.message
    x = np.round(res.x[:m])
    return total_weight(graph, weight) + math.fsum(
        float(w) * xi for (*_, w), xi in zip(es, x, strict=True)
    )
