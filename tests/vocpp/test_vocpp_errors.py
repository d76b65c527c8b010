"""Bad input to plan_route raises planners.errors exceptions whose messages name the input."""

from __future__ import annotations

import math

import networkx as nx
import pytest

from planners.errors import (
    CancelledError,
    DisconnectedGraphError,
    EmptyInputError,
    InvalidInputError,
    InvalidWeightError,
    PlannerError,
    UnknownVertexError,
)
from planners.vocpp import plan_route
from tests.vocpp.checks import assert_valid_route


def _triangle(offset: int = 0, graph=None):
    g = graph if graph is not None else nx.Graph()
    a, b, c = offset, offset + 1, offset + 2
    g.add_weighted_edges_from([(a, b, 1.0), (b, c, 2.0), (c, a, 3.0)])
    return g


def test_unknown_start_and_end_are_named():
    g = _triangle()
    with pytest.raises(
        UnknownVertexError, match=r"start vertex 'x' is not in the graph.*e\.g\. 0, 1, 2"
    ):
        plan_route(g, "x", 0)
    with pytest.raises(UnknownVertexError, match=r"end vertex 7 is not in the graph; it has 3"):
        plan_route(g, 0, 7)
    with pytest.raises(UnknownVertexError, match=r"start vertex \[1\]"):
        plan_route(g, [1], 0)  # unhashable


def test_many_vertices_are_truncated_in_messages():
    g = nx.path_graph(50)
    nx.set_edge_attributes(g, 1, "weight")
    with pytest.raises(UnknownVertexError) as err:
        plan_route(g, -1, 0)
    assert "and 44 more" in str(err.value) and "49" not in str(err.value)


def test_disconnected_graph_names_components_and_unreachable_edges():
    g = _triangle()
    _triangle(10, g)
    with pytest.raises(DisconnectedGraphError) as err:
        plan_route(g, 0, 0)
    msg = str(err.value)
    assert "component 1: {0, 1, 2} (3 vertices, 3 edges)" in msg
    assert "component 2: {10, 11, 12} (3 vertices, 3 edges)" in msg
    assert "Edges unreachable from start 0: (10, 11, 0), (10, 12, 0), (11, 12, 0)" in msg


def test_end_in_other_component():
    g = _triangle()
    _triangle(10, g)
    with pytest.raises(DisconnectedGraphError, match="End 10 cannot be reached from start 0"):
        plan_route(g, 0, 10)


def test_isolated_start_or_end_is_disconnected():
    g = _triangle()
    g.add_node("lonely")
    with pytest.raises(
        DisconnectedGraphError,
        match=r"start 'lonely' is in component 2.*\{'lonely'\} \(1 vertices, 0 edges\)",
    ):
        plan_route(g, "lonely", 0)
    with pytest.raises(DisconnectedGraphError, match="End 'lonely' cannot be reached"):
        plan_route(g, 0, "lonely")
    with pytest.raises(DisconnectedGraphError):
        plan_route(g, "lonely", "lonely")


def test_other_isolated_vertices_are_ignored():
    g = _triangle()
    g.add_nodes_from(["a", "b"])
    route = plan_route(g, 0, 0)
    assert_valid_route(g, route, 0, 0)
    assert route.length == 6.0 and route.deadhead == 0.0


@pytest.mark.parametrize(
    ("value", "pattern"),
    [
        (-1.5, r"edge \(1, 2\) has negative 'weight' = -1.5"),
        (math.nan, r"edge \(1, 2\) has 'weight' = nan \(1 non-finite"),
        (math.inf, r"edge \(1, 2\) has 'weight' = inf"),
        ("3", r"edge \(1, 2\) has 'weight' = '3' of type str"),
        (True, r"of type bool"),
        (None, r"of type NoneType"),
    ],
)
def test_bad_weights_name_the_edge_and_value(value, pattern):
    g = _triangle()
    g[1][2]["weight"] = value
    with pytest.raises(InvalidWeightError, match=pattern):
        plan_route(g, 0, 0)


def test_missing_weight_attribute_on_multigraph():
    g = _triangle(graph=nx.MultiGraph())
    g.add_edge(0, 1)  # key 1, no weight
    with pytest.raises(
        InvalidWeightError, match=r"edge \(0, 1, key=1\) has no 'weight' attribute \(1 of 4"
    ):
        plan_route(g, 0, 0)
    with pytest.raises(InvalidWeightError, match="no 'length' attribute"):
        plan_route(g, 0, 0, weight="length")


def test_unit_weights_with_weight_none():
    g = _triangle()
    g.add_edge(0, 3)  # no weight attribute: fine with weight=None
    route = plan_route(g, 3, 3, weight=None)
    assert route.lower_bound == 4.0 and route.length == 5.0


def test_empty_graphs():
    with pytest.raises(EmptyInputError, match="no vertices"):
        plan_route(nx.Graph(), 0, 0)
    g = nx.Graph()
    g.add_nodes_from([0, 1])
    with pytest.raises(EmptyInputError, match="2 vertices but no edges"):
        plan_route(g, 0, 1)


def test_wrong_graph_types_and_method():
    with pytest.raises(InvalidInputError, match="got list"):
        plan_route([(0, 1)], 0, 1)
    with pytest.raises(InvalidInputError, match="undirected"):
        plan_route(nx.DiGraph([(0, 1)]), 0, 1)
    with pytest.raises(
        InvalidInputError, match=r"method must be one of \('exact', 'thesis'\), got 'fast'"
    ):
        plan_route(_triangle(), 0, 0, method="fast")


def test_errors_are_value_errors():
    for exc in (UnknownVertexError, DisconnectedGraphError, InvalidWeightError, EmptyInputError):
        assert issubclass(exc, PlannerError) and issubclass(exc, ValueError)


def test_progress_is_reported_and_cancellation_propagates():
    seen = []
    plan_route(_triangle(), 0, 1, progress=lambda f, stage: seen.append((f, stage)))
    fractions = [f for f, _ in seen]
    assert fractions == sorted(fractions) and fractions[-1] == 1.0

    def cancel(f, stage):
        if f > 0.5:
            raise CancelledError("operator cancelled")

    with pytest.raises(CancelledError):
        plan_route(_triangle(), 0, 1, progress=cancel)
