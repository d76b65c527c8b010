"""Shortest open or closed walk covering every edge: the VOCPP route of ARA navigation.

The seed's Algorithm 5 ("Variant Open CPP", §4.2) turns the steel-bar graph into a route
that inspects every bar, starting at ``vs`` and ending at ``vt``.  ``method="exact"``
solves that problem optimally; ``method="thesis"`` runs Algorithm 5 as printed (a
heuristic, kept for comparison).

Exact method (open/closed Chinese postman, Edmonds & Johnson 1973):

1. ``T = odd(G) Δ {start, end}`` (``T = odd(G)`` when ``start == end``).  A walk from
   ``start`` to ``end`` that covers every edge is an Euler trail of ``G`` plus repeated
   edges ``J``; the repeats must flip exactly the parities in ``T``, i.e. ``J`` is a
   T-join, so the shortest route is ``w(G) + min w(J)``.
2. Minimum-weight T-join on the original sparse graph with PyMatching's sparse blossom
   (Higgott & Gidney), which is the minimum-weight perfect matching of ``T`` under
   shortest-path distances without building the metric closure
   (:func:`planners.postman.min_t_join`).
3. Euler trail of ``G + J`` from ``start`` (Hierholzer), which ends at ``end``.

Complexity: O(m log m) to read and deduplicate the graph, the sparse-blossom matching
(near-linear in practice on sparse graphs, Higgott & Gidney), and O(m + |J|) for the
trail.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable
from dataclasses import dataclass, field

import numpy as np

from planners.errors import InvalidInputError
from planners.postman.euler import euler_trail
from planners.postman.graph_arrays import (
    check_connected,
    edge_arrays,
    simple_edges,
    vertex_index,
)
from planners.postman.thesis import thesis_augmentation
from planners.postman.tjoin import min_t_join

__all__ = ["METHODS", "Route", "plan_route"]

#: Accepted values of ``plan_route(method=...)``.
METHODS = ("exact", "thesis")

Edge = tuple[Hashable, Hashable, Hashable]


@dataclass(frozen=True)
class Route:
    """A walk from ``start`` to ``end`` that traverses every edge of the graph at least once.

    - ``vertices``: the walk, ``len(edges) + 1`` vertices from ``start`` to ``end``;
    - ``edges``: ``(u, v, key)`` in driving order (``u`` → ``v``; ``key`` is the multigraph
      key, 0 for a ``Graph``);
    - ``length``: total driven length, ``lower_bound + deadhead``;
    - ``lower_bound``: sum of all edge weights (every edge driven once);
    - ``deadhead``: length driven again (sum of ``added_edges`` weights);
    - ``added_edges``: the repeated edges — for ``"exact"`` the minimum T-join — as
      ``(u, v, key)`` (``u``/``v`` in graph order; the cheapest of parallel edges);
    - ``optimality_gap``: ``"exact"`` only, a certified upper bound on
      ``length - optimum``; ``0.0`` means proven optimal (see :func:`plan_route`);
    - ``weight_scaling``: how weights were made integral for the matching solver.
    """

    vertices: list[Hashable]
    edges: list[Edge]
    length: float
    deadhead: float
    lower_bound: float
    method: str
    start: Hashable
    end: Hashable
    added_edges: list[Edge] = field(default_factory=list)
    optimality_gap: float | None = None
    weight_scaling: str = ""

    def as_dict(self) -> dict[str, object]:
        """A JSON-friendly dict (vertices/keys are passed through unchanged)."""
        return {
            "vertices": list(self.vertices),
            "edges": [list(e) for e in self.edges],
            "length": self.length,
            "deadhead": self.deadhead,
            "lower_bound": self.lower_bound,
            "method": self.method,
            "start": self.start,
            "end": self.end,
            "added_edges": [list(e) for e in self.added_edges],
            "optimality_gap": self.optimality_gap,
            "weight_scaling": self.weight_scaling,
        }


def plan_route(
    graph: object,
    start: Hashable,
    end: Hashable,
    *,
    weight: str | None = "weight",
    method: str = "exact",
    progress: Callable[[float, str], None] | None = None,
) -> Route:
    """Shortest walk from ``start`` to ``end`` covering every edge of ``graph`` (seed Alg. 5).

    ``graph`` is an undirected networkx ``Graph`` or ``MultiGraph`` (parallel edges and
    self-loops are covered too; a self-loop adds 2 to its vertex's degree); vertices
    without edges are ignored unless they are ``start``/``end``.  ``weight`` names the
    edge attribute holding the non-negative length (``None``: every edge weighs 1).
    ``start == end`` asks for a closed walk.

    ``method="exact"`` (default): duplicate a minimum-weight T-join,
    ``T = odd(G) Δ {start, end}`` (Edmonds & Johnson 1973), found with PyMatching's
    sparse blossom on the sparse graph, then take a Hierholzer Euler trail.  What
    "exact" guarantees (see :mod:`planners.postman.tjoin`):

    - integer weights, or weights that are the doubles of decimals with ≤ 6 fractional
      digits (``0.21``, ``1.375``): the route is optimal for those integer/decimal values
      (``optimality_gap == 0.0``);
    - any other floats: weights are floored onto a power-of-two grid
      (``w_max·2**-23``-ish resolution) and ``optimality_gap`` certifies
      ``length - optimum ≤ optimality_gap`` (< number of repeated edges × grid step);
      when that is positive and ``|T| ≤ 64``, the T-join is recomputed exactly in
      arbitrary-precision integers and ``optimality_gap == 0.0``.

    ``method="thesis"``: the seed's Algorithm 5 as printed (greedy choice of the odd
    vertices joined to ``start``/``end``, then a minimum join of the rest); never shorter
    than ``"exact"``.  See :mod:`planners.postman.thesis` for how ambiguities are read.

    ``progress(fraction, stage)`` is called between stages and may raise
    :class:`planners.errors.CancelledError`.

    Raises (all ``ValueError`` subclasses from :mod:`planners.errors`):
    ``InvalidInputError`` (not an undirected networkx graph, unknown ``method``),
    ``EmptyInputError`` (no vertices or no edges), ``InvalidWeightError`` (missing,
    non-numeric, negative or non-finite weight), ``UnknownVertexError`` (``start``/``end``
    not in the graph), ``DisconnectedGraphError`` (the edges, ``start`` and ``end`` are not
    in one connected component; the message names the components and unreachable edges).
    """
    if method not in METHODS:
        raise InvalidInputError(f"method must be one of {METHODS}, got {method!r}")

    def report(fraction: float, stage: str) -> None:
        if progress is not None:
            progress(fraction, stage)

    ea = edge_arrays(graph, weight)
    s = vertex_index(ea, start, "start")
    t = vertex_index(ea, end, "end")
    check_connected(ea, s, t)
    report(0.1, "graph read")

    simple = simple_edges(ea)
    su, sv, sw = ea.u[simple], ea.v[simple], ea.w[simple]
    odd = (ea.degrees() % 2).astype(bool)
    gap: float | None = None
    if method == "exact":
        terminals = odd.copy()
        terminals[s] ^= True
        terminals[t] ^= True  # s == t toggles twice: T = odd(G)
        tj = min_t_join(ea.n, su, sv, sw, terminals)
        added, gap, scaling = tj.edges, tj.gap_bound, tj.scaling
    else:
        aug = thesis_augmentation(ea.n, su, sv, sw, odd, s, t)
        added, scaling = aug.edges, aug.step23.scaling
    report(0.7, "repeated edges chosen")

    added_orig = simple[added]  # simple-edge ids -> original edge ids
    eu = np.concatenate((ea.u, ea.u[added_orig]))
    ev = np.concatenate((ea.v, ea.v[added_orig]))
    order, forward = euler_trail(ea.n, eu, ev, s)
    report(0.9, "euler trail")

    m = ea.m
    nodes, keys = ea.nodes, ea.keys
    ul, vl = eu.tolist(), ev.tolist()
    orig = np.concatenate((np.arange(m), added_orig)).tolist()
    edges: list[Edge] = []
    vertices: list[Hashable] = [start]
    for j, fwd in zip(order, forward, strict=True):
        a, b = (ul[j], vl[j]) if fwd else (vl[j], ul[j])
        edges.append((nodes[a], nodes[b], keys[orig[j]]))
        vertices.append(nodes[b])
    lower_bound = math.fsum(ea.w.tolist())
    deadhead = math.fsum(ea.w[added_orig].tolist())
    added_edges = [ea.label(int(j)) for j in added_orig]
    report(1.0, "done")
    return Route(
        vertices=vertices,
        edges=edges,
        length=lower_bound + deadhead,
        deadhead=deadhead,
        lower_bound=lower_bound,
        method=method,
        start=start,
        end=end,
        added_edges=added_edges,
        optimality_gap=gap,
        weight_scaling=scaling,
    )
