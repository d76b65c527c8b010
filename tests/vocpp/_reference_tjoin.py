"""Former ``planners.postman.tjoin`` (before per-component solving), kept verbatim as the benchmark's
"before" and a test reference.  It solves all components in one PyMatching call with one
distance bound (``inf`` across components: see test_vocpp_components for the hang).

Minimum-weight T-join on a sparse graph, exact, with PyMatching's sparse blossom.

A T-join is an edge set whose odd-degree vertices are exactly ``T``.  Duplicating a
minimum-weight T-join with ``T = odd(G) Δ {start, end}`` is the whole optimisation in
the open/closed Chinese postman problem (Edmonds & Johnson 1973, "Matching, Euler tours
and the Chinese postman").  Its weight equals a minimum-weight perfect matching of ``T``
under shortest-path distances, and that is exactly what PyMatching's sparse blossom
(Higgott & Gidney, "Sparse Blossom: correcting a million errors per core second with
minimum-weight matching", 2023) solves directly on the sparse graph: detection events
= ``T``, one matching-graph edge per graph edge, and ``Matching.decode`` returns the set
of edges (mod 2) of the matched shortest paths, i.e. a minimum T-join.

Exactness.  PyMatching solves the problem exactly for *integer* weights.  For other
weights it rescales internally so that the largest becomes ``2**24 - 1`` and rounds
(``pm::UserGraph::get_edge_weight_normalising_constant`` and ``iter_discretized_edges``
in ``sparse_blossom/driver/user_graph.h``: integral weights are kept as they are, anything
else is multiplied by ``(2**24-1)/max|w|`` and rounded; ``|w| > 2**24-1`` is rejected).
We therefore never hand it a non-integer weight; :func:`integer_weights` picks how:

1. ``"integer"`` / ``"decimal 1e-k"`` — every weight is exactly the double nearest to
   ``W / 10**k`` for an integer ``W`` (``k ≤ 6``; e.g. CSV values such as ``0.21``).
   The problem with integer weights ``W`` is solved exactly; an edge whose ``W`` exceeds
   ``2**24 - 1`` is split into a chain of pieces (each ≤ ``2**24 - 1``, summing to ``W``)
   whose inner vertices are not terminals, so a T-join takes the whole chain or none of
   it.  **Guarantee: the T-join is optimal for the decimal weights ``W / 10**k``.**
2. ``"grid 2^-p"`` — general floats.  ``W = floor(w * 2**p)`` with the largest ``p`` that
   keeps ``W ≤ 2**24 - 1`` (a power of two, so scaling and flooring are exact).  The
   result ``J`` is optimal for ``W`` and therefore, for the true weights,
   ``w(J) - OPT ≤ Σ_{e∈J} (w_e - W_e / 2**p) =: gap_bound < |J| · 2**-p``
   (since ``W ≤ w·2**p`` edge-wise, ``W(J) ≤ W(J*) ≤ 2**p · OPT``).  ``gap_bound`` is
   returned.  When it is positive and the instance is small enough
   (``|T| ≤ EXACT_FALLBACK_MAX_TERMINALS``), the T-join is recomputed exactly in
   arbitrary-precision integers (each double is an exact dyadic rational): Dijkstra from
   every terminal, then networkx's blossom ``min_weight_matching`` on the metric closure
   (integer arithmetic throughout) — after which ``gap_bound = 0``.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass

import networkx as nx
import numpy as np
import pymatching
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

#: PyMatching's largest accepted |edge weight| (``pm::MAX_USER_EDGE_WEIGHT = 2**24 - 1``).
MAX_PM_WEIGHT = (1 << 24) - 1
#: Largest terminal-to-terminal distance (in PyMatching's integer units) we let the sparse
#: blossom see.  Its flooder keeps event times as cyclic 32-bit integers; measured with
#: PyMatching 2.4, a path of k edges of weight 2**24-1 between two detection events decodes
#: for k ≤ 129 (distance ≈ 2.16e9) and never returns for k ≥ 130.  The algorithm's final
#: time is at most the largest distance between two terminals (two exposed roots grow at
#: unit rate and cannot overlap), so keeping that distance ≤ 2**30 leaves a factor-2 margin.
MAX_PM_DISTANCE = 1 << 30
#: Decimal places tried when looking for an exact integer scaling of the weights.
MAX_DECIMALS = 6
#: Chain pieces allowed in total, as a multiple of the edge count, before giving up on
#: exact integer scaling and falling back to the power-of-two grid.
SUBDIVISION_FACTOR = 3
#: Exact big-integer repair of a grid solution is attempted when |T| is at most this ...
EXACT_FALLBACK_MAX_TERMINALS = 64
#: ... and |T| · (vertices + edges) is at most this (|T| pure-Python Dijkstra runs).
EXACT_FALLBACK_MAX_WORK = 4_000_000


@dataclass(frozen=True)
class TJoin:
    """A T-join: ``edges`` are indices into the edge arrays given to :func:`min_t_join`.

    ``gap_bound`` is a certified upper bound on ``weight(edges) - optimum`` (``0.0``:
    proven optimal); ``scaling`` says how weights were made integral for PyMatching and
    ``exact_fallback`` whether the big-integer repair ran.
    """

    edges: np.ndarray
    scaling: str
    gap_bound: float
    exact_fallback: bool = False


def integer_weights(
    w: np.ndarray, m_budget: int | None = None
) -> tuple[np.ndarray, str, float] | None:
    """Exact integers ``W`` with ``w == fl(W / 10**k)`` for the smallest ``k ≤ MAX_DECIMALS``.

    ``fl(W / 10**k)`` is correctly rounded, so the test accepts exactly the doubles that a
    decimal string with ``k`` fractional digits parses to.  Returns ``(W, mode, 10**k)``,
    or ``None`` when no such ``k`` exists or the chains needed for large ``W`` exceed the
    subdivision budget.
    """
    if w.size == 0:
        return np.zeros(0, dtype=np.int64), "integer", 1.0
    budget = SUBDIVISION_FACTOR * (w.size if m_budget is None else m_budget) + 1024
    for k in range(MAX_DECIMALS + 1):
        scale = 10.0**k
        r = np.rint(w * scale)
        if r.max() >= 2.0**53:  # beyond exact integers in float64
            return None
        if np.array_equal(r / scale, w):
            pieces = np.ceil(r / MAX_PM_WEIGHT).sum()
            if pieces > budget:
                return None
            return r.astype(np.int64), ("integer" if k == 0 else f"decimal 1e-{k}"), scale
    return None


def grid_weights(w: np.ndarray, distance_bound: float = 0.0) -> tuple[np.ndarray, int]:
    """``(floor(w * 2**p), p)`` for the largest ``p`` with every value ≤ ``2**24 - 1`` and
    ``distance_bound * 2**p ≤ MAX_PM_DISTANCE`` (see :data:`MAX_PM_DISTANCE`)."""
    wmax = float(w.max())
    if wmax == 0.0:
        return np.zeros(w.size, dtype=np.int64), 0
    _, e = math.frexp(wmax)  # wmax < 2**e, so wmax * 2**(24-e) < 2**24
    p = 24 - e
    if distance_bound > 0.0:
        _, e2 = math.frexp(distance_bound)  # bound < 2**e2
        p = min(p, 30 - e2)
    return np.floor(np.ldexp(w, p)).astype(np.int64), p


def terminal_distance_bound(
    n: int, su: np.ndarray, sv: np.ndarray, sw: np.ndarray, t: np.ndarray
) -> float:
    """Upper bound on the largest shortest-path distance between two terminals.

    One Dijkstra from a terminal ``r``: ``d(x, y) ≤ d(x, r) + d(r, y) ≤ 2 max_x d(r, x)``.
    Terminals must share one connected component.
    """
    terms = np.flatnonzero(t)
    A = sp.csr_matrix((sw, (su, sv)), shape=(n, n))  # explicit zeros stay edges in csgraph
    # one source given as a list (the stubs take no scalar index): row 0 is its distances
    d = dijkstra(A, directed=False, indices=[int(terms[0])])[0]
    return 2.0 * float(d[terms].max())


def _pymatching_tjoin(
    n: int, su: np.ndarray, sv: np.ndarray, W: np.ndarray, t: np.ndarray
) -> np.ndarray:
    """Minimum T-join for integer weights ``W`` (any size; long edges become chains)."""
    ms = su.size
    k = np.maximum(1, -(-W // MAX_PM_WEIGHT))  # pieces per edge (ceil division)
    if int(k.max()) == 1:
        rows = np.empty(2 * ms, dtype=np.int64)
        rows[0::2], rows[1::2] = su, sv
        cols = np.repeat(np.arange(ms, dtype=np.int64), 2)
        H = sp.csc_matrix((np.ones(2 * ms, dtype=np.uint8), (rows, cols)), shape=(n, ms))
        weights = W.astype(np.float64)
        faults = None  # identity: fault id j = column j = edge j
        n_rows = n
    else:
        # Chain a - x1 - ... - x_{k-1} - b; only the first piece carries the edge's fault id,
        # which is enough because a T-join takes a chain entirely or not at all.
        n_pieces = int(k.sum())
        edge = np.repeat(np.arange(ms, dtype=np.int64), k)
        first = np.concatenate(([0], np.cumsum(k)[:-1]))
        j = np.arange(n_pieces, dtype=np.int64) - np.repeat(first, k)
        base = n + np.concatenate(([0], np.cumsum(k - 1)[:-1]))  # first inner vertex per edge
        kk = k[edge]
        left = np.where(j == 0, su[edge], base[edge] + j - 1)
        right = np.where(j == kk - 1, sv[edge], base[edge] + j)
        q, r = W // k, W % k
        weights = (q[edge] + (j < r[edge])).astype(np.float64)
        n_rows = n + int((k - 1).sum())
        rows = np.empty(2 * n_pieces, dtype=np.int64)
        rows[0::2], rows[1::2] = left, right
        cols = np.repeat(np.arange(n_pieces, dtype=np.int64), 2)
        H = sp.csc_matrix(
            (np.ones(2 * n_pieces, dtype=np.uint8), (rows, cols)), shape=(n_rows, n_pieces)
        )
        fcols = np.flatnonzero(j == 0)
        faults = sp.csc_matrix(
            (np.ones(ms, dtype=np.uint8), (edge[fcols], fcols)), shape=(ms, n_pieces)
        )
    matching = pymatching.Matching.from_check_matrix(
        H, weights=weights, faults_matrix=faults, use_virtual_boundary_node=True
    )
    syndrome = np.zeros(matching.num_detectors, dtype=np.uint8)
    syndrome[np.flatnonzero(t)] = 1
    correction = matching.decode(syndrome)
    return np.flatnonzero(correction[:ms])


def _exact_tjoin_bigint(
    n: int, su: np.ndarray, sv: np.ndarray, w: np.ndarray, t: np.ndarray
) -> tuple[np.ndarray, list[int]]:
    """Exact minimum T-join in arbitrary-precision integers (small instances only).

    Each double is ``num / 2**j`` exactly; scaling by the largest ``2**j`` gives exact
    Python integers.  Dijkstra from every terminal, then the blossom algorithm
    (networkx ``min_weight_matching``, integer arithmetic) on the metric closure; the
    T-join is the mod-2 sum of the matched shortest paths (Edmonds & Johnson 1973).
    """
    ratios = [x.as_integer_ratio() for x in w.tolist()]
    den = max((d for _, d in ratios), default=1)
    W = [num * (den // d) for num, d in ratios]
    adj: list[list[tuple[int, int]]] = [[] for _ in range(n)]
    for j, (a, b) in enumerate(zip(su.tolist(), sv.tolist(), strict=True)):
        adj[a].append((b, j))
        adj[b].append((a, j))
    terms = np.flatnonzero(t).tolist()
    tset = set(terms)
    closure: nx.Graph[int] = nx.Graph()
    parents: dict[int, list[int]] = {}
    for s in terms:
        dist: dict[int, int] = {s: 0}
        par = [-1] * n
        done = [False] * n
        heap = [(0, s)]
        while heap:
            d, x = heapq.heappop(heap)
            if done[x]:
                continue
            done[x] = True
            for y, j in adj[x]:
                nd = d + W[j]
                if nd < dist.get(y, nd + 1):
                    dist[y] = nd
                    par[y] = j
                    heapq.heappush(heap, (nd, y))
        parents[s] = par
        for y, d in dist.items():
            if y in tset and y > s:
                closure.add_edge(s, y, weight=d)
    mate = nx.min_weight_matching(closure)
    count = np.zeros(su.size, dtype=np.int64)
    for a, b in sorted(tuple(sorted(p)) for p in mate):
        par, x = parents[a], b
        while x != a:
            j = par[x]
            count[j] += 1
            x = int(su[j]) if int(sv[j]) == x else int(sv[j])
    return np.flatnonzero(count % 2), W


def min_t_join(
    n: int,
    su: np.ndarray,
    sv: np.ndarray,
    sw: np.ndarray,
    terminals: np.ndarray,
    *,
    exact_fallback: bool = True,
) -> TJoin:
    """Minimum-weight T-join, ``T = flatnonzero(terminals)`` (Edmonds & Johnson 1973).

    ``su, sv, sw`` describe a loop-free simple graph on ``n`` vertices with weights ≥ 0
    (see :func:`planners.postman.graph_arrays.simple_edges`); every connected component
    must hold an even number of terminals.  See the module docstring for what "exact"
    guarantees for each kind of weight.
    """
    t = np.asarray(terminals, dtype=bool)
    if not t.any():
        return TJoin(edges=np.zeros(0, dtype=np.int64), scaling="none", gap_bound=0.0)
    bound = terminal_distance_bound(n, su, sv, sw, t)
    ints = integer_weights(sw)
    # The 1e-6 relative slack covers the float rounding of `bound` against exact W sums.
    if ints is not None and bound * ints[2] * (1 + 1e-6) + 1 <= MAX_PM_DISTANCE:
        W, scaling, _ = ints
        J = _pymatching_tjoin(n, su, sv, W, t)
        return TJoin(edges=J, scaling=scaling, gap_bound=0.0)
    W, p = grid_weights(sw, bound * (1 + 1e-6))
    J = _pymatching_tjoin(n, su, sv, W, t)
    # Exact per edge (power-of-two scaling); fsum rounds the total once.
    gap = math.fsum((sw[J] - np.ldexp(W[J].astype(np.float64), -p)).tolist())
    scaling = f"grid 2^-{p}"
    n_t = int(t.sum())
    if (
        gap > 0.0
        and exact_fallback
        and n_t <= EXACT_FALLBACK_MAX_TERMINALS
        and n_t * (n + su.size) <= EXACT_FALLBACK_MAX_WORK
    ):
        J_exact, W_big = _exact_tjoin_bigint(n, su, sv, sw, t)
        # Keep PyMatching's answer when it is optimal too (exact comparison).
        if sum(W_big[j] for j in J.tolist()) > sum(W_big[j] for j in J_exact.tolist()):
            J = J_exact
        return TJoin(edges=J, scaling=scaling, gap_bound=0.0, exact_fallback=True)
    return TJoin(edges=J, scaling=scaling, gap_bound=gap)
