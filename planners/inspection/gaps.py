"""Gaps between the disconnected parts of a structure model, and joining the
ones the ARA can jump across.

A scan often leaves a structure in pieces (occlusion, a member not picked
up).  The pieces are the connected components of the member graph (isolated
vertices without spans are ignored).  Between two pieces the gap is the
shortest distance between their member spans, each span the segment between
its two vertices' ``pos`` — closest points between segments (Ericsson,
*Real-Time Collision Detection*, §5.1.9), not merely between vertices, so two
parallel chords side by side measure their true spacing.

Which gaps are reported: the minimum spanning tree of the pieces under that
distance (Borůvka's algorithm on the pieces, each round giving every piece
its nearest other piece), so k pieces give k − 1 gaps.  Every gap no wider
than the jump reach is *joined*: the spans are split at the two closest
points (a new vertex of kind ``"split"`` unless the point is within 1 mm of a
span end) and an inch-worm edge ``kind="jump"``, ``member=None`` connects
them.  Because the MST contains a spanning forest of every distance-threshold
subgraph, joining its short edges connects exactly the pieces that chains of
jumps within reach could connect.

Cost: each Borůvka round compares every span with every span of other
pieces, O(m²) time in blocks of ≤ 65 536 pairs (O(m) memory); at most
⌈log₂ k⌉ rounds.
"""

from __future__ import annotations

import itertools
from collections.abc import Hashable
from dataclasses import dataclass

import networkx as nx
import numpy as np

__all__ = ["Gap", "closest_segment_points", "component_gaps", "join_gaps"]

#: Pairs of spans compared per block (bounds the memory of one round).
_BLOCK_PAIRS = 65_536
#: A closest point this close to a span end (metres) is that end's vertex.
_SNAP_M = 1e-3


@dataclass(frozen=True)
class Gap:
    """The shortest gap between two pieces of the structure.

    ``component_a``/``component_b`` index ``InspectionPlan.components``;
    ``point_a``/``point_b`` the closest points (on spans of ``member_a``,
    ``member_b``); ``width_m`` their distance; ``joined``: within the jump
    reach, so the routing graph has a jump edge ``vertex_a``–``vertex_b``
    (``None`` when not joined).
    """

    component_a: int
    component_b: int
    point_a: np.ndarray
    point_b: np.ndarray
    width_m: float
    joined: bool
    member_a: int
    member_b: int
    vertex_a: Hashable | None = None
    vertex_b: Hashable | None = None


def closest_segment_points(
    p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closest points between segments ``p0p1`` (B, 3) and ``q0q1`` (M, 3),
    every pair: parameters ``s`` (B, M) on p, ``t`` (B, M) on q, distances
    (B, M).  Degenerate (zero-length) segments are points."""
    d1 = (p1 - p0)[:, None, :]
    d2 = (q1 - q0)[None, :, :]
    r = p0[:, None, :] - q0[None, :, :]
    a = np.sum(d1 * d1, axis=2)  # (B, 1)
    e = np.sum(d2 * d2, axis=2)  # (1, M)
    f = np.sum(d2 * r, axis=2)
    c = np.sum(d1 * r, axis=2)
    b = np.sum(d1 * d2, axis=2)
    eps = 1e-24
    a_ok, e_ok = a > eps, e > eps
    a_safe, e_safe = np.where(a_ok, a, 1.0), np.where(e_ok, e, 1.0)
    denom = a * e - b * b
    # Parallel segments (denom 0): any s works; 0 is taken and t fixed below.
    safe = np.where(denom > 1e-12 * a * e, denom, 1.0)
    s = np.where(denom > 1e-12 * a * e, np.clip((b * f - c * e) / safe, 0.0, 1.0), 0.0)
    t = (b * s + f) / e_safe
    s = np.where(t < 0, np.clip(-c / a_safe, 0.0, 1.0), s)
    s = np.where(t > 1, np.clip((b - c) / a_safe, 0.0, 1.0), s)
    t = np.clip(t, 0.0, 1.0)
    # One or both segments degenerate.
    s = np.where(~e_ok, np.clip(-c / a_safe, 0.0, 1.0), s)
    t = np.where(~e_ok, 0.0, t)
    s = np.where(~a_ok, 0.0, s)
    t = np.where(~a_ok, np.clip(f / e_safe, 0.0, 1.0) * e_ok, t)
    gap = (p0[:, None, :] + d1 * s[..., None]) - (q0[None, :, :] + d2 * t[..., None])
    return s, t, np.linalg.norm(gap, axis=2)


def component_gaps(
    p0: np.ndarray, p1: np.ndarray, comp: np.ndarray, k: int
) -> list[tuple[float, int, int, float, float]]:
    """Borůvka MST of ``k`` pieces: span ``i`` runs ``p0[i]``→``p1[i]`` and
    belongs to piece ``comp[i]``.  Returns the k − 1 tree edges as
    ``(distance, span_i, span_j, s, t)`` (closest points at parameters ``s``
    on ``i``, ``t`` on ``j``), ties broken by the lowest span indices."""
    parent = list(range(k))

    def find(x: int) -> int:
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    m = len(p0)
    block = max(1, _BLOCK_PAIRS // max(m, 1))
    out: list[tuple[float, int, int, float, float]] = []
    while True:
        roots = np.array([find(c) for c in range(k)])
        lab = roots[comp]
        if len(np.unique(lab)) <= 1:
            break
        best: dict[int, tuple[float, int, int, float, float]] = {}  # one per piece: O(k)
        for lo in range(0, m, block):
            hi = min(m, lo + block)
            s, t, d = closest_segment_points(p0[lo:hi], p1[lo:hi], p0, p1)
            d = np.where(lab[lo:hi, None] == lab[None, :], np.inf, d)
            jmin = np.argmin(d, axis=1)
            rows = np.arange(hi - lo)
            dmin = d[rows, jmin]
            for r in np.nonzero(np.isfinite(dmin))[0].tolist():
                i, j, li = lo + r, int(jmin[r]), int(lab[lo + r])
                cand = (float(dmin[r]), i, j, float(s[r, j]), float(t[r, j]))
                if li not in best or cand < best[li]:
                    best[li] = cand
        merged = False
        for cand in sorted(best.values()):
            ra, rb = find(int(comp[cand[1]])), find(int(comp[cand[2]]))
            if ra != rb:
                parent[ra] = rb
                out.append(cand)
                merged = True
        if not merged:  # cannot happen with finite positions; guards the loop
            break
    return out


def join_gaps(
    graph: nx.MultiGraph,
    spans: list[tuple[Hashable, Hashable, Hashable]],
    gaps: list[Gap],
    at: list[tuple[int, float, int, float]],
) -> tuple[nx.MultiGraph, list[Gap]]:
    """Split spans at the joined gaps' closest points and add the jump edges.

    ``graph`` is the routing graph (edited in place and returned), ``spans``
    the span list the gaps' indices refer to, ``at[g] = (span_a, s, span_b,
    t)`` gap ``g``'s closest-point parameters.  Returns the graph and the
    gaps with ``vertex_a``/``vertex_b`` set on the joined ones.
    """
    requests: dict[int, list[tuple[float, int, int]]] = {}  # span → (param, gap, side)
    for g, (gap, (ia, s, ib, t)) in enumerate(zip(gaps, at, strict=True)):
        if gap.joined:
            requests.setdefault(ia, []).append((s, g, 0))
            requests.setdefault(ib, []).append((t, g, 1))
    ints = all(isinstance(n, int) for n in graph.nodes)
    counter = [max((n for n in graph.nodes), default=-1) + 1 if ints else 0]

    def new_node(pos: np.ndarray) -> Hashable:
        node: Hashable = counter[0] if ints else ("split", counter[0])
        counter[0] += 1
        graph.add_node(node, pos=pos, kind="split")
        return node

    vertex: dict[tuple[int, int], Hashable] = {}
    for span, reqs in sorted(requests.items()):
        u, v, key = spans[span]
        data = dict(graph.edges[u, v, key])
        pu = np.asarray(graph.nodes[u]["pos"], float)
        pv = np.asarray(graph.nodes[v]["pos"], float)
        length = float(np.linalg.norm(pv - pu))
        chain: list[tuple[float, Hashable]] = [(0.0, u), (1.0, v)]
        for param, g, side in sorted(reqs):
            here = next((n for q, n in chain if abs(q - param) * length <= _SNAP_M), None)
            if here is None:
                here = new_node(pu + param * (pv - pu))
                chain.append((param, here))
                chain.sort(key=lambda qn: qn[0])
            vertex[(g, side)] = here
        if len(chain) > 2:  # replace the span by its pieces, same member, weight shared out
            graph.remove_edge(u, v, key)
            w = float(data["weight"])
            for (qa, na), (qb, nb) in itertools.pairwise(chain):
                piece = dict(data, weight=w * (qb - qa), steel_m=w * (qb - qa))
                graph.add_edge(na, nb, **piece)
    out: list[Gap] = []
    for g, gap in enumerate(gaps):
        if not gap.joined:
            out.append(gap)
            continue
        va, vb = vertex[(g, 0)], vertex[(g, 1)]
        pa = np.asarray(graph.nodes[va]["pos"], float)
        pb = np.asarray(graph.nodes[vb]["pos"], float)
        graph.add_edge(
            va,
            vb,
            member=None,
            kind="jump",
            weight=float(np.linalg.norm(pb - pa)),
            steel_m=0.0,
            ends={va: gap.member_a, vb: gap.member_b},
        )
        out.append(
            Gap(
                gap.component_a,
                gap.component_b,
                gap.point_a,
                gap.point_b,
                gap.width_m,
                True,
                gap.member_a,
                gap.member_b,
                va,
                vb,
            )
        )
    return graph, out
