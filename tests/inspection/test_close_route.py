"""Close inspection of one member against brute force: on small
random structures, the route from ``start`` that drives the whole member is
no longer than any simple approach path plus the member's chain."""

from __future__ import annotations

import itertools
import math

import networkx as nx
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from planners.errors import DisconnectedGraphError, InvalidInputError
from planners.inspection.close import close_route


def _graph(
    n: int, extra: list[tuple[int, int, float]], member_len: int, w: list[float]
) -> nx.MultiGraph:
    """A chain 0..member_len of member 7 plus other spans (member 1) and jumps."""
    g = nx.MultiGraph()
    for i in range(member_len):
        g.add_edge(i, i + 1, kind="span", member=7, route_weight=w[i % len(w)])
    for u, v, wt in extra:
        if u != v:
            g.add_edge(u % n, v % n, kind="span" if wt > 1 else "jump", member=1, route_weight=wt)
    return g


def _brute(g: nx.MultiGraph, start: int, member_len: int) -> float:
    chain = sum(float(d["route_weight"]) for _, _, d in g.edges(data=True) if d.get("member") == 7)
    best = math.inf
    for end in (0, member_len):
        if start == end:
            best = min(best, chain)
            continue
        for path in nx.all_simple_paths(nx.Graph(g), start, end):
            cost = sum(
                min(float(d["route_weight"]) for d in g.get_edge_data(a, b).values())
                for a, b in itertools.pairwise(path)
            )
            best = min(best, cost + chain)
    return best


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(4, 7),
    extra=st.lists(
        st.tuples(st.integers(0, 6), st.integers(0, 6), st.floats(0.1, 5.0)), min_size=3, max_size=9
    ),
    member_len=st.integers(1, 3),
    w=st.lists(st.floats(0.1, 3.0), min_size=1, max_size=3),
    start=st.integers(0, 6),
)
def test_close_route_is_the_cheapest_approach_plus_the_member(
    n, extra, member_len, w, start
) -> None:
    g = _graph(n, extra, member_len, w)
    start = start % g.number_of_nodes()
    if start not in g:
        return
    reachable = nx.node_connected_component(nx.Graph(g), start)
    if 0 not in reachable:
        with pytest.raises(DisconnectedGraphError):
            close_route(g, start, 7, "route_weight")
        return
    r = close_route(g, start, 7, "route_weight")
    assert r.length == pytest.approx(_brute(g, start, member_len))
    # A walk: consecutive edges share vertices, starting at start.
    assert r.vertices[0] == start and len(r.vertices) == len(r.edges) + 1
    for (a, b, k), u, v in zip(r.edges, r.vertices[:-1], r.vertices[1:], strict=True):
        assert (a, b) == (u, v) and g.has_edge(a, b, k)
    spans = {
        (min(u, v), max(u, v), k)
        for u, v, k, d in g.edges(keys=True, data=True)
        if d.get("member") == 7
    }
    assert spans <= {(min(a, b), max(a, b), k) for a, b, k in r.edges}
    assert r.end in (0, member_len) and r.lower_bound == pytest.approx(
        sum(float(d["route_weight"]) for *_, d in g.edges(data=True) if d.get("member") == 7)
    )


def test_a_member_without_spans_or_not_a_chain_is_refused() -> None:
    g = nx.MultiGraph()
    g.add_edge(0, 1, kind="span", member=1, route_weight=1.0)
    with pytest.raises(InvalidInputError, match="no span"):
        close_route(g, 0, 7, "route_weight")
    for a, b in ((1, 2), (1, 3), (1, 4)):  # a star is no chain
        g.add_edge(a, b, kind="span", member=7, route_weight=1.0)
    with pytest.raises(InvalidInputError, match="one chain"):
        close_route(g, 0, 7, "route_weight")
