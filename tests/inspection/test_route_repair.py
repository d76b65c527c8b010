"""Re-pairing a covering walk's passes (planners.inspection.route_repair):
every reversal keeps a walk over the same edges between the same ends, and
the repair never ends worse than it began, nor worse than the best single
reversal found by brute force."""

from __future__ import annotations

from collections import Counter
from collections.abc import Hashable
from itertools import combinations

import networkx as nx
from hypothesis import given, settings
from hypothesis import strategies as st

from planners.inspection.route_repair import _reversed, repair_route, transition_cost
from planners.inspection.transitions import Transition, route_transitions
from planners.vocpp import Route, plan_route


class PairCtx:
    """A transition context whose feasibility is a table: a member change
    ``a → b`` is infeasible when ``(a, b)`` is in ``forbidden``."""

    def __init__(self, graph: nx.MultiGraph, forbidden: set[tuple[int, int]]) -> None:
        self.graph = graph
        self.forbidden = forbidden

    def transition(
        self, route: int, index: int, v: Hashable, landing: Hashable, kind: str, a, b
    ) -> Transition:
        ok = (a, b) not in self.forbidden
        return Transition(
            route, v, index, landing, kind, a, b, "mobile" if a == b else "inchworm",
            None, None, None, {}, ok, "table",
        )  # fmt: skip


@st.composite
def graphs(draw: st.DrawFn) -> nx.MultiGraph:
    """A small connected multigraph of spans, one member per edge."""
    n = draw(st.integers(3, 7))
    g = nx.MultiGraph()
    for i in range(1, n):  # a spanning tree first: connected
        g.add_edge(i, draw(st.integers(0, i - 1)))
    for _ in range(draw(st.integers(0, 6))):
        u, v = draw(st.integers(0, n - 1)), draw(st.integers(0, n - 1))
        if u != v:
            g.add_edge(u, v)
    for m, (u, v, k) in enumerate(g.edges(keys=True)):
        g.edges[u, v, k].update(kind="span", member=m, weight=1.0, route_weight=1.0)
    return g


def _is_walk(g: nx.MultiGraph, r: Route, edges: Counter) -> bool:
    if Counter(frozenset((u, v)) | {k} for u, v, k in r.edges) != edges:
        return False
    return all(
        r.vertices[i] == u and r.vertices[i + 1] == v and g.has_edge(u, v, k)
        for i, (u, v, k) in enumerate(r.edges)
    )


@settings(max_examples=60, deadline=None)
@given(graphs(), st.data())
def test_a_reversal_between_two_passes_is_a_walk_over_the_same_edges(g, data) -> None:
    r = plan_route(g, 0, 0, weight="route_weight")
    edges = Counter(frozenset((u, v)) | {k} for u, v, k in r.edges)
    pairs = [
        (i, j) for i, j in combinations(range(len(r.vertices)), 2) if r.vertices[i] == r.vertices[j]
    ]
    if not pairs:
        return
    i, j = data.draw(st.sampled_from(pairs))
    cand = _reversed(r, i, j)
    assert _is_walk(g, cand, edges)
    assert (cand.vertices[0], cand.vertices[-1]) == (r.vertices[0], r.vertices[-1])


@settings(max_examples=60, deadline=None)
@given(graphs(), st.data())
def test_the_repair_is_never_worse_nor_worse_than_the_best_single_reversal(g, data) -> None:
    members = sorted({int(d["member"]) for *_, d in g.edges(keys=True, data=True)})
    pairs = [(a, b) for a in members for b in members if a != b]
    forbidden = set(data.draw(st.lists(st.sampled_from(pairs), max_size=8))) if pairs else set()
    ctx = PairCtx(g, forbidden)
    r = plan_route(g, 0, 0, weight="route_weight")
    before = transition_cost(route_transitions(ctx, r, 0))  # type: ignore[arg-type]
    fixed, trans = repair_route(ctx, r, 0)  # type: ignore[arg-type]
    after = transition_cost(trans)
    assert after <= before
    assert _is_walk(g, fixed, Counter(frozenset((u, v)) | {k} for u, v, k in r.edges))
    assert after == transition_cost(route_transitions(ctx, fixed, 0))  # type: ignore[arg-type]
    # Brute force: the best of every single reversal of the original walk.
    best = before
    for i, j in combinations(range(len(r.vertices)), 2):
        if r.vertices[i] == r.vertices[j]:
            best = min(best, transition_cost(route_transitions(ctx, _reversed(r, i, j), 0)))  # type: ignore[arg-type]
    if best[0] < before[0]:
        assert after[0] < before[0]
