"""Hypothesis strategies: small random connected (multi)graphs with start/end vertices."""

from __future__ import annotations

import networkx as nx
from hypothesis import strategies as st

INT_WEIGHTS = st.integers(0, 20)
DECIMAL_WEIGHTS = st.integers(0, 2000).map(lambda x: x / 100)
FLOAT_WEIGHTS = st.floats(0.0, 10.0, allow_nan=False, allow_infinity=False)


@st.composite
def postman_instances(draw, weights=None, multigraph=None, max_n: int = 9, max_extra: int = 12):
    """``(graph, start, end)``: a random spanning tree plus extra edges (loops, parallels).

    Vertices are ``0..n-1`` (sometimes strings); with some probability an isolated vertex
    ``"iso"`` is added, which a route must ignore.
    """
    n = draw(st.integers(1, max_n))
    multi = draw(st.booleans()) if multigraph is None else multigraph
    wst = (
        weights
        if weights is not None
        else draw(st.sampled_from([INT_WEIGHTS, DECIMAL_WEIGHTS, FLOAT_WEIGHTS]))
    )
    names = draw(st.sampled_from(["int", "str"]))
    label = (lambda i: i) if names == "int" else (lambda i: f"v{i}")
    g = nx.MultiGraph() if multi else nx.Graph()
    g.add_nodes_from(label(i) for i in range(n))
    for v in range(1, n):
        g.add_edge(label(v), label(draw(st.integers(0, v - 1))), weight=draw(wst))
    pairs = draw(
        st.lists(st.tuples(st.integers(0, n - 1), st.integers(0, n - 1)), max_size=max_extra)
    )
    for a, b in pairs:
        g.add_edge(label(a), label(b), weight=draw(wst))
    if g.number_of_edges() == 0:
        g.add_edge(label(0), label(0), weight=draw(wst))  # one vertex: a self-loop
    if draw(st.booleans()):
        g.add_node("iso")
    start = label(draw(st.integers(0, n - 1)))
    end = start if draw(st.booleans()) else label(draw(st.integers(0, n - 1)))
    return g, start, end
