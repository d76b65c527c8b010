"""Array view of a networkx ``Graph``/``MultiGraph`` for the postman solvers.

Everything downstream works on integer vertex indices and numpy edge arrays so that
the 50,000-edge case never loops over edges in Python more than once (here, while
reading the networkx graph).  Validation of the public entry point lives here too:
weights, start/end vertices and connectivity, each raising a :mod:`planners.errors`
exception whose message names the offending input.
"""

from __future__ import annotations

import numbers
from collections.abc import Hashable
from dataclasses import dataclass
from typing import Any

import networkx as nx
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from planners.errors import (
    DisconnectedGraphError,
    EmptyInputError,
    InvalidInputError,
    InvalidWeightError,
    UnknownVertexError,
)

#: How many vertices / edges / components an error message lists before "… and N more".
_SHOW = 6


class _Missing:
    """Sentinel type for an edge without the weight attribute."""

    def __repr__(self) -> str:  # pragma: no cover - only seen in debugging
        return "<missing>"


_MISSING = _Missing()


@dataclass(frozen=True)
class EdgeArrays:
    """A (multi)graph as arrays: vertex ``i`` is ``nodes[i]``; edge ``j`` joins ``u[j]``–``v[j]``.

    ``keys[j]`` is the networkx multigraph key (0 for a simple ``Graph``) and ``w[j]`` the
    validated weight (finite, ≥ 0, ``-0.0`` normalised to ``0.0``).  Edge order is the
    graph's own iteration order, which makes every result deterministic.
    """

    nodes: list[Hashable]
    index: dict[Hashable, int]
    u: np.ndarray
    v: np.ndarray
    keys: list[Hashable]
    w: np.ndarray

    @property
    def n(self) -> int:
        return len(self.nodes)

    @property
    def m(self) -> int:
        return len(self.keys)

    def label(self, j: int) -> tuple[Hashable, Hashable, Hashable]:
        """The edge ``j`` as ``(u, v, key)`` in node names."""
        return (self.nodes[int(self.u[j])], self.nodes[int(self.v[j])], self.keys[j])

    def degrees(self) -> np.ndarray:
        """Vertex degrees; a self-loop counts 2, as in networkx."""
        return np.bincount(self.u, minlength=self.n) + np.bincount(self.v, minlength=self.n)


def _fmt_list(items: list[str], total: int | None = None) -> str:
    total = len(items) if total is None else total
    shown = ", ".join(items[:_SHOW])
    return shown + (f", … and {total - _SHOW} more" if total > _SHOW else "")


def edge_arrays(graph: object, weight: str | None) -> EdgeArrays:
    """Read ``graph`` into :class:`EdgeArrays`, validating its type and every edge weight.

    ``weight=None`` gives every edge weight 1 (networkx's convention).  Raises
    :class:`InvalidInputError` for a non-networkx or directed graph,
    :class:`EmptyInputError` for a graph without vertices or edges and
    :class:`InvalidWeightError` for a missing, non-numeric, negative or non-finite weight.
    """
    if not isinstance(graph, nx.Graph):
        raise InvalidInputError(
            f"graph must be a networkx Graph or MultiGraph, got {type(graph).__name__}"
        )
    if graph.is_directed():
        raise InvalidInputError(
            f"graph must be undirected (networkx Graph or MultiGraph), got {type(graph).__name__}; "
            "convert with graph.to_undirected() if every edge may be driven both ways"
        )
    if graph.number_of_nodes() == 0:
        raise EmptyInputError("graph has no vertices: there is nothing to inspect")
    if graph.number_of_edges() == 0:
        raise EmptyInputError(
            f"graph has {graph.number_of_nodes()} vertices but no edges: a route covers edges, "
            "so there is nothing to plan"
        )
    nodes = list(graph.nodes)
    index = {node: i for i, node in enumerate(nodes)}
    # (u, v, key, weight or _MISSING); undirected MultiGraph is the only multigraph left here
    rows: list[tuple[Any, Any, Any, Any]]
    if weight is None:
        if isinstance(graph, nx.MultiGraph):
            rows = [(a, b, k, 1.0) for a, b, k in graph.edges(keys=True)]
        else:
            rows = [(a, b, 0, 1.0) for a, b in graph.edges()]
    elif isinstance(graph, nx.MultiGraph):
        rows = list(graph.edges(keys=True, data=weight, default=_MISSING))
    else:
        rows = [(a, b, 0, x) for a, b, x in graph.edges(data=weight, default=_MISSING)]
    m = len(rows)
    u = np.fromiter((index[r[0]] for r in rows), dtype=np.int64, count=m)
    v = np.fromiter((index[r[1]] for r in rows), dtype=np.int64, count=m)
    keys = [r[2] for r in rows]
    vals = [r[3] for r in rows]

    def name(j: int) -> str:
        a, b, k = rows[j][:3]
        return f"({a!r}, {b!r})" if not graph.is_multigraph() else f"({a!r}, {b!r}, key={k!r})"

    # One pass over the value types (a set of a few classes) instead of per-edge checks.
    types = set(map(type, vals))
    if _Missing in types:
        j = next(i for i, x in enumerate(vals) if x is _MISSING)
        n_missing = sum(1 for x in vals if x is _MISSING)
        raise InvalidWeightError(
            f"edge {name(j)} has no {weight!r} attribute ({n_missing} of {m} edges lack it); "
            f"give every edge a finite non-negative {weight!r} or pass weight=None for unit weights"
        )
    bad_types = {t for t in types if not issubclass(t, numbers.Real) or issubclass(t, bool)}
    if bad_types:
        j = next(i for i, x in enumerate(vals) if type(x) in bad_types)
        raise InvalidWeightError(
            f"edge {name(j)} has {weight!r} = {vals[j]!r} of type {type(vals[j]).__name__}; "
            "weights must be real numbers (int or float)"
        )
    w = np.asarray(vals, dtype=np.float64) + 0.0  # + 0.0 turns -0.0 into 0.0
    bad = ~np.isfinite(w)
    if bad.any():
        j = int(np.flatnonzero(bad)[0])
        raise InvalidWeightError(
            f"edge {name(j)} has {weight!r} = {vals[j]!r} ({int(bad.sum())} non-finite weights); "
            "weights must be finite and ≥ 0"
        )
    neg = w < 0
    if neg.any():
        j = int(np.flatnonzero(neg)[0])
        raise InvalidWeightError(
            f"edge {name(j)} has negative {weight!r} = {vals[j]!r} ({int(neg.sum())} negative "
            "weights); a postman route needs non-negative edge lengths"
        )
    return EdgeArrays(nodes=nodes, index=index, u=u, v=v, keys=keys, w=w)


def vertex_index(ea: EdgeArrays, vertex: object, role: str) -> int:
    """Index of ``vertex`` or :class:`UnknownVertexError` naming it and a few known vertices."""
    try:
        return ea.index[vertex]
    except (KeyError, TypeError):
        known = _fmt_list([repr(x) for x in ea.nodes[:_SHOW]], ea.n)
        raise UnknownVertexError(
            f"{role} vertex {vertex!r} is not in the graph; it has {ea.n} vertices, e.g. {known}"
        ) from None


def check_connected(ea: EdgeArrays, s: int, t: int) -> None:
    """Raise :class:`DisconnectedGraphError` unless every edge, ``s`` and ``t`` share a component.

    Isolated vertices other than ``s``/``t`` are ignored (nothing to cover there).  The
    message names the components holding edges (vertex lists truncated), the component
    of ``s`` and ``t``, and which edges cannot be reached from ``s``.
    """
    n = ea.n
    adj = sp.csr_matrix((np.ones(ea.m, dtype=np.int8), (ea.u, ea.v)), shape=(n, n))
    _, labels = connected_components(adj, directed=False)
    cs = labels[s]
    edge_comp = labels[ea.u]
    unreachable = np.flatnonzero(edge_comp != cs)
    if unreachable.size == 0 and labels[t] == cs:
        return

    def describe(c: int) -> str:
        members = np.flatnonzero(labels == c)
        n_edges = int(np.count_nonzero(edge_comp == c))
        verts = _fmt_list([repr(ea.nodes[i]) for i in members[:_SHOW]], members.size)
        return f"{{{verts}}} ({members.size} vertices, {n_edges} edges)"

    comps = sorted(set(edge_comp.tolist()) | {int(cs), int(labels[t])})
    lines = [f"component {i + 1}: {describe(c)}" for i, c in enumerate(comps[:_SHOW])]
    if len(comps) > _SHOW:
        lines.append(f"… and {len(comps) - _SHOW} more components")
    start, end = ea.nodes[s], ea.nodes[t]
    where_s = comps.index(int(cs)) + 1
    where_t = comps.index(int(labels[t])) + 1
    msg = (
        "graph is disconnected: a single walk cannot cover every edge. "
        f"start {start!r} is in component {where_s}, end {end!r} in component {where_t}. "
        + "; ".join(lines)
    )
    if unreachable.size:
        shown = _fmt_list([repr(ea.label(int(j))) for j in unreachable[:_SHOW]], unreachable.size)
        msg += f". Edges unreachable from start {start!r}: {shown}"
    if labels[t] != cs:
        msg += f". End {end!r} cannot be reached from start {start!r}"
    raise DisconnectedGraphError(msg)


def simple_edges(ea: EdgeArrays) -> np.ndarray:
    """Ids of the edges a T-join may duplicate: no self-loops, cheapest of each parallel class.

    A self-loop never changes a degree's parity, so a minimum T-join never uses one; among
    parallel edges only the cheapest can be worth driving twice (ties: the first in graph
    order).  Result is sorted by (min endpoint, max endpoint): deterministic.
    """
    keep = np.flatnonzero(ea.u != ea.v)
    a = np.minimum(ea.u[keep], ea.v[keep])
    b = np.maximum(ea.u[keep], ea.v[keep])
    order = np.lexsort((keep, ea.w[keep], b, a))
    a, b = a[order], b[order]
    first = np.ones(order.size, dtype=bool)
    first[1:] = (a[1:] != a[:-1]) | (b[1:] != b[:-1])
    return keep[order[first]]
