"""Minimum T-join: weight scaling modes, chains for big integers, grid bound, exact repair."""

from __future__ import annotations

import math

import networkx as nx
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from planners.postman import euler_trail, min_t_join
from planners.postman.tjoin import MAX_PM_DISTANCE, MAX_PM_WEIGHT, grid_weights, integer_weights
from planners.vocpp import plan_route
from tests.vocpp.checks import assert_valid_route
from tests.vocpp.reference import metric_closure_matching


def _arrays(edges):
    e = np.asarray([(a, b) for a, b, _ in edges], dtype=np.int64)
    return e[:, 0], e[:, 1], np.asarray([w for *_, w in edges], dtype=float)


def _terminals(n, ts):
    t = np.zeros(n, dtype=bool)
    t[list(ts)] = True
    return t


def test_integer_weights_detects_decimals():
    W, mode, scale = integer_weights(np.array([0.21, 1.5, 3.0]))
    assert mode == "decimal 1e-2" and W.tolist() == [21, 150, 300] and scale == 100
    W, mode, scale = integer_weights(np.array([1.0, 2.0, 0.0]))
    assert mode == "integer" and W.tolist() == [1, 2, 0] and scale == 1
    assert integer_weights(np.array([1 / 3])) is None  # not a short decimal
    assert integer_weights(np.array([0.1 + 1e-15])) is None  # a few ulps off a decimal


def test_grid_weights_are_floors_on_a_power_of_two_grid():
    w = np.array([0.3, 1e6 + 0.5, 0.0, 12.345678901])
    W, p = grid_weights(w)
    assert W.max() <= MAX_PM_WEIGHT
    assert np.all(np.ldexp(W.astype(float), -p) <= w)
    assert np.all(w - np.ldexp(W.astype(float), -p) < 2.0**-p)
    # p is maximal: doubling the scale would overflow PyMatching's limit.
    assert np.floor(w.max() * 2.0 ** (p + 1)) > MAX_PM_WEIGHT


def _trap():
    """a=0, b=1 terminals; path 0-2-1 costs 0.30000001 + 0.3, the direct edge 0.6 (optimal).

    A 1e6 edge elsewhere makes the float grid coarse (2^-4): floors give the path 4 + 4 = 8
    and the direct edge 9, so the grid optimum is the wrong one.
    """
    return [(0, 2, 0.30000001), (2, 1, 0.3), (0, 1, 0.6), (1, 3, 1e6 + 0.5)]


def test_grid_without_repair_is_within_certified_gap():
    su, sv, sw = _arrays(_trap())
    tj = min_t_join(4, su, sv, sw, _terminals(4, {0, 1}), exact_fallback=False)
    assert tj.scaling == "grid 2^-4"
    assert sorted(tj.edges.tolist()) == [0, 1]  # the grid's (wrong) choice
    true_gap = sw[tj.edges].sum() - 0.6
    assert 0 < true_gap <= tj.gap_bound
    assert tj.gap_bound < len(tj.edges) * 2.0**-4


def test_exact_repair_fixes_the_grid_choice():
    su, sv, sw = _arrays(_trap())
    tj = min_t_join(4, su, sv, sw, _terminals(4, {0, 1}))
    assert tj.exact_fallback and tj.gap_bound == 0.0
    assert tj.edges.tolist() == [2]


def test_plan_route_reports_the_repaired_optimum():
    g = nx.Graph()
    for a, b, w in _trap():
        g.add_edge(a, b, weight=w)
    route = plan_route(g, 0, 0)
    assert_valid_route(g, route, 0, 0)
    # odd(G) = {0, 3}... plus the trap: compare with the independent optimum exactly.
    cost, _, _ = metric_closure_matching(g, {v for v, d in g.degree() if d % 2})
    assert route.deadhead == pytest.approx(cost, abs=0)
    assert route.optimality_gap == 0.0


def test_large_decimals_use_chains_and_stay_exact():
    """W up to 1e8 > 2**24 - 1: edges become chains; a 0.001 difference still decides."""
    edges = [(0, 2, 50000.001), (2, 1, 50000.001), (0, 1, 100000.003)]
    su, sv, sw = _arrays(edges)
    W, mode, _ = integer_weights(sw)
    assert mode == "decimal 1e-3" and W.max() > MAX_PM_WEIGHT
    tj = min_t_join(3, su, sv, sw, _terminals(3, {0, 1}))
    assert tj.gap_bound == 0.0 and sorted(tj.edges.tolist()) == [0, 1]
    # The float grid alone cannot tell them apart (both floor to 12_800_000 at 2^-7).
    Wg, p = grid_weights(sw)
    assert p == 7 and Wg[0] + Wg[1] == Wg[2]


@pytest.mark.parametrize(
    ("unit", "scaling"),
    [(10**7, "integer"), (10**9, "grid")],  # chains of pieces | beyond MAX_PM_DISTANCE
)
def test_large_integer_weights(unit, scaling):
    edges = [(0, 1, 3 * unit), (1, 2, unit), (0, 2, 4 * unit + 1), (2, 3, 7)]
    g = nx.Graph()
    for a, b, w in edges:
        g.add_edge(a, b, weight=w)
    route = plan_route(g, 0, 3)
    assert route.weight_scaling.startswith(scaling) and route.optimality_gap == 0.0
    cost, _, _ = metric_closure_matching(g, {v for v, d in g.degree() if d % 2} ^ {0, 3})
    assert route.deadhead == cost
    assert_valid_route(g, route, 0, 3)


@pytest.mark.timeout(60)
@pytest.mark.parametrize("kind", ["int", "float"])
def test_long_paths_between_terminals_do_not_hang(kind):
    """Regression: PyMatching 2.4 never returns once terminals are > ~2**31 units apart.

    A 400-edge cycle with start and end opposite (the only terminals): at full resolution
    the terminals are ~200 * 2**24 units apart.
    """
    rng = np.random.default_rng(5)
    n = 400
    w = rng.integers(15_000_000, 16_000_000, n) if kind == "int" else 1 + rng.random(n)
    g = nx.cycle_graph(n)  # all even: T = {start, end}
    for i, (a, b) in enumerate(g.edges()):
        g[a][b]["weight"] = w[i].item()
    route = plan_route(g, 0, 200)
    assert_valid_route(g, route, 0, 200)
    expected = nx.shortest_path_length(g, 0, 200, weight="weight")
    assert math.isclose(route.deadhead, expected, rel_tol=1e-12)
    assert route.optimality_gap == 0.0  # |T| = 2: repaired exactly


def test_grid_resolution_shrinks_with_terminal_distance():
    w = np.full(10, 1.5)
    _, p_free = grid_weights(w)
    _, p_far = grid_weights(w, distance_bound=1e6)
    assert p_far < p_free and 1e6 * 2.0**p_far <= MAX_PM_DISTANCE


@settings(deadline=None, max_examples=60)
@given(st.integers(2, 12), st.integers(0, 10**6), st.data())
def test_grid_mode_bound_holds_on_random_graphs(n, seed, data):
    """Without the exact repair, w(J) - OPT ≤ gap_bound on random float graphs."""
    rng = np.random.default_rng(seed)
    g = nx.gnm_random_graph(n, data.draw(st.integers(n - 1, n * (n - 1) // 2)), seed=seed)
    for v in range(1, n):
        g.add_edge(v, int(rng.integers(v)))
    scale = 10.0 ** data.draw(st.integers(-3, 6))
    for a, b in g.edges():
        g[a][b]["weight"] = float(rng.random() * scale)
    ts = {v for v, d in g.degree() if d % 2}
    if not ts:
        ts = {0, n - 1}
    es = [(a, b, d["weight"]) for a, b, d in g.edges(data=True)]
    su, sv, sw = _arrays(es)
    tj = min_t_join(n, su, sv, sw, _terminals(n, ts), exact_fallback=False)
    opt, _, _ = metric_closure_matching(g, ts)
    got = math.fsum(sw[tj.edges].tolist())
    assert got - opt <= tj.gap_bound + 1e-12 * max(1.0, opt)
    odd = np.bincount(np.concatenate([su[tj.edges], sv[tj.edges]]), minlength=n) % 2
    assert set(np.flatnonzero(odd).tolist()) == ts


def test_zero_weights_and_empty_terminals():
    su, sv, sw = _arrays([(0, 1, 0.0), (1, 2, 0.0), (2, 3, 5.0)])
    assert min_t_join(4, su, sv, sw, _terminals(4, set())).edges.size == 0
    tj = min_t_join(4, su, sv, sw, _terminals(4, {0, 2}))
    assert sorted(tj.edges.tolist()) == [0, 1]


def test_euler_trail_handles_loops_and_repeats():
    eu = np.array([0, 0, 1, 1, 1, 2])
    ev = np.array([1, 1, 1, 2, 2, 0])  # double 0-1, loop at 1, double 1-2, 2-0: 0 and 2 odd
    order, fwd = euler_trail(3, eu, ev, 0)
    assert sorted(order) == list(range(6))
    pos = 0
    for j, f in zip(order, fwd, strict=True):
        a, b = (eu[j], ev[j]) if f else (ev[j], eu[j])
        assert a == pos
        pos = b
    assert pos == 2  # an open trail ends at the other odd vertex


def test_euler_trail_rejects_disconnected_input():
    with pytest.raises(RuntimeError, match="covered 1 of 2"):
        euler_trail(4, np.array([0, 2]), np.array([0, 3]), 0)
