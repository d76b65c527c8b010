"""VOCPP on random graphs: valid walks, exact optimum vs independent methods, thesis ≥ exact."""

from __future__ import annotations

import math

import networkx as nx
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from planners.vocpp import plan_route
from tests.vocpp.checks import assert_valid_route
from tests.vocpp.reference import metric_closure_optimum, milp_optimum, terminals
from tests.vocpp.strategies import FLOAT_WEIGHTS, INT_WEIGHTS, postman_instances

SETTINGS = settings(deadline=None, max_examples=300, suppress_health_check=[HealthCheck.too_slow])


def _close(a: float, b: float) -> bool:
    return math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-9)


@SETTINGS
@given(postman_instances())
def test_exact_is_optimal_and_valid(inst):
    g, s, t = inst
    route = plan_route(g, s, t)
    assert_valid_route(g, route, s, t)
    assert route.method == "exact"
    assert route.optimality_gap == 0.0  # small instances: always certified
    assert _close(route.length, metric_closure_optimum(g, s, t))
    thesis = plan_route(g, s, t, method="thesis")
    assert_valid_route(g, thesis, s, t)
    assert thesis.length >= route.length - 1e-9
    assert thesis.optimality_gap is None


@settings(deadline=None, max_examples=120)
@given(postman_instances(weights=INT_WEIGHTS))
def test_integer_weights_match_milp_exactly(inst):
    g, s, t = inst
    route = plan_route(g, s, t)
    assert route.weight_scaling in ("integer", "none")
    assert route.length == milp_optimum(g, s, t)  # integers: exact equality


@settings(deadline=None, max_examples=60)
@given(postman_instances(weights=FLOAT_WEIGHTS, multigraph=True))
def test_float_weights_match_milp(inst):
    g, s, t = inst
    assert _close(plan_route(g, s, t).length, milp_optimum(g, s, t))


@settings(deadline=None, max_examples=60)
@given(postman_instances(weights=INT_WEIGHTS))
def test_deadhead_is_a_t_join(inst):
    """The repeated edges flip exactly the parities of odd(G) Δ {start, end}."""
    g, s, t = inst
    route = plan_route(g, s, t)
    h = nx.MultiGraph()
    h.add_edges_from((a, b) for a, b, _ in route.added_edges)
    odd = {v for v, d in h.degree() if d % 2}
    assert odd == terminals(g, s, t)


@settings(deadline=None, max_examples=40)
@given(postman_instances(), st.sampled_from(["exact", "thesis"]))
def test_deterministic(inst, method):
    g, s, t = inst
    a = plan_route(g, s, t, method=method)
    b = plan_route(g.copy(), s, t, method=method)
    assert a == b


@settings(deadline=None, max_examples=80)
@given(postman_instances(weights=INT_WEIGHTS))
def test_thesis_equals_exact_when_its_choices_are_forced(inst):
    """Steps 4 and 8 of Alg. 5 make no greedy choice, so there it is optimal too."""
    g, s, t = inst
    odd = {v for v, d in g.degree() if d % 2}
    forced = not odd or (s in odd and t in odd)
    thesis = plan_route(g, s, t, method="thesis").length
    exact = plan_route(g, s, t).length
    if forced:
        assert thesis == exact
    else:
        assert thesis >= exact
