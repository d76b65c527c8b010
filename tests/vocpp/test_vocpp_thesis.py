"""The seed's Algorithm 5 (method="thesis"): each printed branch, and where it loses to exact."""

from __future__ import annotations

import networkx as nx
import numpy as np
import pytest

from planners.postman import edge_arrays, simple_edges, thesis_augmentation
from planners.vocpp import plan_route
from tests.vocpp.checks import assert_valid_route


def _graph(edges, multi=False):
    g = nx.MultiGraph() if multi else nx.Graph()
    g.add_weighted_edges_from(edges)
    return g


def _augment(g, s, t):
    ea = edge_arrays(g, "weight")
    simple = simple_edges(ea)
    odd = (ea.degrees() % 2).astype(bool)
    aug = thesis_augmentation(
        ea.n, ea.u[simple], ea.v[simple], ea.w[simple], odd, ea.index[s], ea.index[t]
    )
    return aug, ea


# (edges, start, end, branch, exact length, thesis length) - worked by hand in the comments.
CASES = [
    # odd {0,1,3,4}; vs=2 even, vt=1 odd.  Exact pairs (0,3)+(2,4) = 1+5.  Thesis joins vs
    # to its nearest odd vertex 0 (2), then must pair 3-4 (8): deadhead 10 instead of 6.
    ([(0, 2, 2), (0, 3, 1), (1, 0, 1), (2, 4, 5)], 2, 1, "11", 15.0, 19.0),
    ([(0, 2, 2), (0, 3, 1), (1, 0, 1), (2, 4, 5)], 1, 2, "15", 15.0, 19.0),
    # odd {1,2}; vs=0, vt=3 even.  Exact joins vs-vt directly (9) and 1-2 (5) = 14; step 20
    # only joins each input vertex to a distinct odd vertex: min 4+13 = 9+8 = 17.
    ([(0, 3, 9), (1, 0, 4), (1, 2, 5), (1, 3, 8)], 0, 3, "19", 40.0, 43.0),
    # closed walk from even v=2, odd {0,1}: exact pairs 0-1 (5); step 20 read with vs = vt
    # adds paths 2-0 and 2-1 (2 + 7 = 9).
    ([(0, 2, 2), (0, 3, 9), (0, 1, 5), (2, 3, 3)], 2, 2, "19", 24.0, 28.0),
    # Euler circuit exists (square); open route 0 -> 2 adds the shortest 0-2 path (step 5).
    ([(0, 1, 1), (1, 2, 1), (2, 3, 2), (3, 0, 2)], 0, 2, "4", 8.0, 8.0),
    ([(0, 1, 1), (1, 2, 1), (2, 3, 2), (3, 0, 2)], 1, 1, "4", 6.0, 6.0),
    # Both input vertices odd (step 8): the rest is joined optimally, as in exact.
    ([(0, 1, 1), (1, 2, 1), (1, 3, 1)], 0, 2, "8", 4.0, 4.0),
    # Closed walk from odd leaf 0 of a star: Smov = Sov (documented reading of step 8);
    # any pairing of the four odd vertices costs 3.
    ([(0, 1, 1), (1, 2, 1), (1, 3, 1)], 0, 0, "8", 6.0, 6.0),
]


@pytest.mark.parametrize(("edges", "s", "t", "branch", "exact", "thesis"), CASES)
def test_branches_and_lengths(edges, s, t, branch, exact, thesis):
    g = _graph(edges)
    aug, _ = _augment(g, s, t)
    assert aug.branch == branch
    r_exact = plan_route(g, s, t)
    r_thesis = plan_route(g, s, t, method="thesis")
    assert_valid_route(g, r_exact, s, t)
    assert_valid_route(g, r_thesis, s, t)
    assert (r_exact.length, r_thesis.length) == (exact, thesis)


def test_step12_never_selects_the_odd_end_vertex():
    """Path a-b-c-d: odd {a, d}; vs = b, vt = a.  a is nearest to b but is vt itself."""
    g = _graph([("a", "b", 1), ("b", "c", 1), ("c", "d", 1)])
    aug, ea = _augment(g, "b", "a")
    assert aug.branch == "11" and aug.chosen == (ea.index["d"],)
    route = plan_route(g, "b", "a", method="thesis")
    assert_valid_route(g, route, "b", "a")
    assert route.length == 5.0


def test_step20_picks_two_distinct_vertices():
    """Both inputs even and both nearest to the same odd vertex x: vc1 != vc2."""
    g = _graph([("s", "x", 1), ("t", "x", 1), ("s", "t", 5), ("x", "y", 4), ("y", "z", 1)])
    # degrees: s2 t2 x3 y2 z1 -> odd {x, z}
    aug, ea = _augment(g, "s", "t")
    assert aug.branch == "19"
    vc1, vc2 = aug.chosen
    assert vc1 != vc2 and {vc1, vc2} == {ea.index["x"], ea.index["z"]}
    route = plan_route(g, "s", "t", method="thesis")
    assert_valid_route(g, route, "s", "t")
    assert route.length >= plan_route(g, "s", "t").length


def test_thesis_duplicates_cheapest_parallel_edge_on_multigraph():
    g = _graph([(0, 1, 5), (0, 1, 2), (1, 2, 1)], multi=True)  # odd {1, 2}... degrees 0:2 1:3 2:1
    route = plan_route(g, 0, 0, method="thesis")
    assert_valid_route(g, route, 0, 0)
    # closed from even 0: step 20 joins 0 to 1 (via the 2-edge) and 0 to 2 (2+1).
    assert route.deadhead == 5.0 and plan_route(g, 0, 0).deadhead == 1.0
    assert all(k == 1 for a, b, k in route.added_edges if {a, b} == {0, 1})


def test_thesis_is_deterministic_on_ties():
    g = nx.cycle_graph(6)
    g.add_edges_from([(0, 3), (1, 4)])
    nx.set_edge_attributes(g, 1, "weight")
    routes = {tuple(plan_route(g, 2, 5, method="thesis").edges) for _ in range(3)}
    assert len(routes) == 1
    assert np.isfinite(plan_route(g, 2, 5, method="thesis").length)
