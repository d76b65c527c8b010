"""Synthetic truss-like graphs for VOCPP tests and benchmarks (deterministic by seed)."""

from __future__ import annotations

import networkx as nx
import numpy as np


def truss_graph(
    rows: int,
    cols: int,
    *,
    seed: int = 0,
    drop: float = 0.05,
    jitter: float = 0.02,
    panel: float = 1.0,
) -> nx.Graph:
    """A planar truss lattice: chords, posts and alternating (Warren-like) diagonals.

    Vertices ``(i, j)`` sit on a ``rows × cols`` grid of ``panel``-metre panels with
    ``jitter`` metres of noise; edge ``weight`` is the Euclidean length in metres (general
    floats).  A fraction ``drop`` of the members is removed at random (never a spanning-tree
    member, so the graph stays connected), which leaves many odd vertices.
    """
    rng = np.random.default_rng(seed)
    ii, jj = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    pos = np.stack([jj * panel, ii * panel], axis=-1).reshape(-1, 2).astype(float)
    pos += rng.normal(0.0, jitter, pos.shape)
    vid = np.arange(rows * cols).reshape(rows, cols)
    e = [
        np.stack([vid[:, :-1].ravel(), vid[:, 1:].ravel()], 1),  # chords
        np.stack([vid[:-1, :].ravel(), vid[1:, :].ravel()], 1),  # posts
    ]
    ci, cj = np.meshgrid(np.arange(rows - 1), np.arange(cols - 1), indexing="ij")
    up = ((ci + cj) % 2 == 0).ravel()
    d1 = np.stack([vid[:-1, :-1].ravel(), vid[1:, 1:].ravel()], 1)
    d2 = np.stack([vid[:-1, 1:].ravel(), vid[1:, :-1].ravel()], 1)
    e.append(np.where(up[:, None], d1, d2))
    edges = np.concatenate(e)
    # Keep a spanning tree (the chords of row 0 and every post) so drops never disconnect.
    tree = np.zeros(len(edges), dtype=bool)
    n_chord = vid[:, :-1].size
    tree[: cols - 1] = True
    tree[n_chord : n_chord + vid[:-1, :].size] = True
    keep = tree | (rng.random(len(edges)) >= drop)
    edges = edges[keep]
    w = np.linalg.norm(pos[edges[:, 0]] - pos[edges[:, 1]], axis=1)
    g = nx.Graph()
    names = [(int(i), int(j)) for i, j in zip(ii.ravel(), jj.ravel(), strict=True)]
    for k, name in enumerate(names):
        g.add_node(name, pos=(float(pos[k, 0]), float(pos[k, 1]), 0.0))
    g.add_weighted_edges_from(
        (names[a], names[b], float(x)) for (a, b), x in zip(edges.tolist(), w.tolist(), strict=True)
    )
    return g


def with_odd_count(g: nx.Graph, target: int, *, seed: int = 0) -> nx.Graph:
    """Copy of ``g`` with exactly ``target`` odd vertices (removes odd–odd edges, not bridges).

    ``target`` must be even and at most the current number of odd vertices.
    """
    if target % 2:
        raise ValueError("target must be even")
    g = g.copy()
    rng = np.random.default_rng(seed)
    odd = {v for v, d in g.degree() if d % 2}
    if len(odd) < target:
        raise ValueError(f"graph has only {len(odd)} odd vertices, fewer than {target}")
    cand = [(a, b) for a, b in g.edges() if a in odd and b in odd]
    rng.shuffle(cand)
    bridges = set(nx.bridges(g))
    for a, b in cand:
        if len(odd) <= target:
            break
        if a in odd and b in odd and (a, b) not in bridges and (b, a) not in bridges:
            g.remove_edge(a, b)
            odd -= {a, b}
    if len(odd) != target or not nx.is_connected(g):
        raise ValueError(f"could not reach {target} odd vertices (got {len(odd)})")
    return g
