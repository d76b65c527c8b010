"""The seed's Algorithm 5 ("Variant Open CPP", VOCPP) as printed — a heuristic, for comparison.

Algorithm 5 (seed §4.2) with ``Sov`` the odd vertices of ``G``:

- step 4  ``Sov = ∅``: add the shortest ``vs``–``vt`` path ``Ee`` and go to step 24;
- step 8  ``vs, vt ∈ Sov``: ``Smov = Sov \\ {vs, vt}``;
- step 11 ``vs ∉ Sov, vt ∈ Sov``: add the shortest path ``Ec`` from ``vs`` to the nearest
  ``vc ∈ Sov``; ``Smov = Sov \\ {vt, vc}``;
- step 15 ``vs ∈ Sov, vt ∉ Sov``: symmetric, path from ``vt``; ``Smov = Sov \\ {vs, vc}``;
- step 19 ``vs, vt ∉ Sov``: add two shortest paths ``vs``–``vc1`` and ``vt``–``vc2`` whose sum
  is smallest; ``Smov = Sov \\ {vc1, vc2}``;
- step 23 "find a set of edges ``Ea`` whose sum is shortest to convert all vertices in
  ``Smov`` to even vertices" — a minimum ``Smov``-join (computed with the same exact
  solver; distances in ``Gm`` equal those in ``G`` because ``Gm`` only repeats edges);
- step 24 Euler trail of ``(V, Em ∪ Ea)`` from ``vs`` to ``vt`` (the seed names Fleury;
  any Euler trail has the same edge multiset and length, so Hierholzer is used).

The greedy choices in steps 12, 16 and 20 are what make it a heuristic: e.g. when both
``vs`` and ``vt`` are even it never considers joining ``vs`` to ``vt`` directly.

Readings chosen where the print is ambiguous (the most literal one that yields a trail):

- step 12/16 "select a vertex ``vc ∈ Sov``": ``vc`` ranges over ``Sov`` minus the odd
  input vertex (choosing it would leave ``|Smov|`` odd and no trail ``vs → vt``);
- step 20: ``vc1 ≠ vc2`` (the same reason), ``Ed1`` joins ``vs`` to ``vc1`` and ``Ed2``
  joins ``vt`` to ``vc2`` (the narrative: odd vertices nearest the even input vertices);
- ties: the smallest distance, then the lowest vertex index (graph order);
- ``vs == vt`` (a closed walk; the seed assumes ``vs ≠ vt``): steps 4 and 19 read as
  printed (an empty path; two paths ``v–vc1``, ``v–vc2``); step 8 would remove ``v``
  from ``Sov`` and leave ``|Smov|`` odd, so there ``Smov = Sov``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

from planners.postman.tjoin import TJoin, min_t_join


@dataclass(frozen=True)
class ThesisAugmentation:
    """Edges Algorithm 5 adds (indices into the simple-edge arrays, repeats allowed).

    ``branch`` is the printed step that applied (``"4"``, ``"8"``, ``"11"``, ``"15"``,
    ``"19"``), ``chosen`` the vertex indices it selected (``vc`` or ``vc1, vc2``) and
    ``step23`` the ``Smov``-join of step 23.
    """

    edges: np.ndarray
    branch: str
    chosen: tuple[int, ...]
    step23: TJoin


def _path_edges(
    pred: np.ndarray, edge_id: dict[tuple[int, int], int], src: int, dst: int
) -> list[int]:
    out: list[int] = []
    x = dst
    while x != src:
        p = int(pred[x])
        out.append(edge_id[(p, x) if p < x else (x, p)])
        x = p
    out.reverse()
    return out


def thesis_augmentation(
    n: int,
    su: np.ndarray,
    sv: np.ndarray,
    sw: np.ndarray,
    odd: np.ndarray,
    s: int,
    t: int,
) -> ThesisAugmentation:
    """Run the seed's Algorithm 5 on the simple graph ``(su, sv, sw)``; see the module doc."""
    sov = np.flatnonzero(odd)
    # Explicitly stored zeros are edges for scipy.sparse.csgraph, so 0-weight edges count.
    A = sp.csr_matrix((sw, (su, sv)), shape=(n, n))
    dist, pred = dijkstra(A, directed=False, indices=[s, t], return_predecessors=True)
    edge_id = {
        (a, b) if a < b else (b, a): j
        for j, (a, b) in enumerate(zip(su.tolist(), sv.tolist(), strict=True))
    }
    added: list[int] = []
    chosen: tuple[int, ...] = ()
    smov = np.zeros(n, dtype=bool)
    smov[sov] = True
    if sov.size == 0:  # step 4-6: Euler circuit exists; add the shortest vs-vt path
        branch = "4"
        added += _path_edges(pred[0], edge_id, s, t)
    elif odd[s] and odd[t]:  # step 8-9
        branch = "8"
        if s != t:
            smov[[s, t]] = False
    elif odd[t]:  # step 11-13: vs even, vt odd
        branch = "11"
        cand = sov[sov != t]
        vc = int(cand[np.argmin(dist[0, cand])])
        chosen = (vc,)
        added += _path_edges(pred[0], edge_id, s, vc)
        smov[[t, vc]] = False
    elif odd[s]:  # step 15-17: vs odd, vt even
        branch = "15"
        cand = sov[sov != s]
        vc = int(cand[np.argmin(dist[1, cand])])
        chosen = (vc,)
        added += _path_edges(pred[1], edge_id, t, vc)
        smov[[s, vc]] = False
    else:  # step 19-21: both even; two paths with the smallest sum, vc1 != vc2
        branch = "19"
        ds, dt = dist[0, sov], dist[1, sov]
        top_s = np.argsort(ds, kind="stable")[:2]
        top_t = np.argsort(dt, kind="stable")[:2]
        best = min(
            (ds[i] + dt[j], int(sov[i]), int(sov[j]))
            for i in top_s.tolist()
            for j in top_t.tolist()
            if i != j
        )
        vc1, vc2 = best[1], best[2]
        chosen = (vc1, vc2)
        added += _path_edges(pred[0], edge_id, s, vc1)
        added += _path_edges(pred[1], edge_id, t, vc2)
        smov[[vc1, vc2]] = False
    step23 = min_t_join(n, su, sv, sw, smov)  # step 23 (empty Smov for step 4)
    edges = np.asarray(added + step23.edges.tolist(), dtype=np.int64)
    return ThesisAugmentation(edges=edges, branch=branch, chosen=chosen, step23=step23)
