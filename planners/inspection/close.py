"""Close inspection of one member: drive from ``start`` to the
member and along all of it.

With one member required, the rural postman route (the VOCPP of seed Alg. 5
restricted to the member's spans) is: the cheapest way (Dijkstra over the
route weights of :mod:`planners.inspection.plan`) from ``start`` to one end
of the member's chain of spans, then the chain to its other end — the
better of the two ends.  The member's spans always form one chain (a
prismatic member is split only at its joints), which is checked.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Hashable
from typing import cast

import networkx as nx

from planners.errors import DisconnectedGraphError, InvalidInputError
from planners.vocpp import Edge, Route


def _chain(g: nx.MultiGraph, member: int) -> tuple[list[Hashable], list[Edge]]:
    """The member's spans as one walk from one end to the other."""
    spans = [
        (u, v, k)
        for u, v, k, d in g.edges(keys=True, data=True)
        if d.get("kind") == "span" and int(d["member"]) == member
    ]
    if not spans:
        raise InvalidInputError(
            f"member {member} has no span in the member graph: nothing to drive"
        )
    sub: nx.MultiGraph = nx.MultiGraph()
    sub.add_edges_from(spans)
    ends = [n for n in sub.nodes if sub.degree(n) == 1]
    if not nx.is_connected(sub) or len(ends) != 2 or max(d for _, d in sub.degree) > 2:
        raise InvalidInputError(f"member {member}'s spans do not form one chain")
    walk, edges = [ends[0]], []
    seen: set[Edge] = set()
    while walk[-1] != ends[1]:
        u = walk[-1]
        u2, v, k = next((a, b, c) for a, b, c in sub.edges(u, keys=True) if (a, b, c) not in seen)
        seen.add((u2, v, k))
        seen.add((v, u2, k))
        edges.append((u, v, k))
        walk.append(v)
    return walk, edges


def _cheapest(g: nx.MultiGraph, u: Hashable, v: Hashable, weight: str) -> Hashable:
    keys = g[u][v]
    return min(keys, key=lambda k: float(keys[k][weight]))


def close_route(g: nx.MultiGraph, start: Hashable, member: int, weight: str) -> Route:
    """The route from ``start`` that drives all of ``member`` (see the module
    docstring); ``length`` is in ``weight`` units (the caller restates it in
    metres of steel)."""
    walk, chain = _chain(g, member)
    chain_w = math.fsum(float(g.edges[e][weight]) for e in chain)
    # no target: the (distances, paths) form, not (distance, path)
    dist, paths = cast(
        tuple[dict[Hashable, float], dict[Hashable, list[Hashable]]],
        nx.single_source_dijkstra(g, start, weight=weight),
    )
    options = []
    for first, last, forward in ((walk[0], walk[-1], True), (walk[-1], walk[0], False)):
        if first in dist:
            options.append((dist[first] + chain_w, first, last, forward))
    if not options:
        raise DisconnectedGraphError(
            f"member {member} is not reachable from vertex {start!r} (another piece of the "
            "structure that no jump within reach joins)"
        )
    total, first, last, forward = min(options, key=lambda o: (o[0], not o[3]))
    approach = paths[first]
    edges: list[Edge] = [
        (a, b, _cheapest(g, a, b, weight)) for a, b in itertools.pairwise(approach)
    ]
    along = chain if forward else [(v, u, k) for u, v, k in reversed(chain)]
    edges += along
    vertices = list(approach) + [e[1] for e in along]
    return Route(
        vertices=vertices,
        edges=edges,
        length=total,
        deadhead=total - chain_w,
        lower_bound=chain_w,
        method="close",
        start=start,
        end=last,
    )
