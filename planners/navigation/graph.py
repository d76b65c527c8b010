"""Structure graph from the clusters (seed Alg. 4, Graph Construction).

As printed: vertices are the cluster centres S_c and the midpoints S_md of
the borders between neighbour clusters; edges join a centre to the border
midpoints it shares with its neighbours; a PCA feature line is fitted to every
cluster and its intersections I_l with the cluster's boundary become extra
vertices ("bar ends"), joined to their centre, when they are farther than
``dmin`` from every vertex.

What changed, and why (the seed's Cross graph, Fig. 5.5p, did not follow the
bars: "the distance from the center points to the corresponding edge points
were too close … no need an edge"):

* only bar clusters get feature-line ends — a cross area has no free end,
  and its PCA line, of a nearly isotropic blob, points anywhere;
* ``dmin`` is small (5 cm, far below any bar length) and an end is skipped
  only when it is that close to an existing vertex, i.e. when the bar
  already ends at a border midpoint there; so every free bar end gets its
  vertex and the route drives the bar to its end;
* the feature line is fitted to the cluster's points (not to its boundary
  points, which the seed's noisy far field skews — its Fig. 5.5v edge "did not
  go along with the steel bar").

Vertices are integers ``0..V-1`` in a deterministic order; node attributes:
``pos`` (xyz, input frame), ``pos2d`` (plane coordinates), ``kind``
("centre" | "border" | "end"), ``clusters`` (tuple of cluster ids).  Edge
attributes: ``weight`` (metres, 3D), ``clusters`` (the cluster ids the edge
runs over), ``kind`` (the kind of that cluster).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import networkx as nx
import numpy as np

from planners.navigation.boundaries import Cluster, line_polygon_hits
from planners.navigation.segmentation import Border


def build_graph(
    clusters: Sequence[Cluster],
    borders: Sequence[Border],
    lift: Callable[[np.ndarray], np.ndarray],
    *,
    dmin_m: float = 0.05,
) -> nx.Graph:
    """Seed Alg. 4 with the fixes listed in the module docstring.

    ``lift`` maps (N, 2) plane coordinates to (N, 3) input-frame points.
    """
    g: nx.Graph[int] = nx.Graph()
    pos2d: list[np.ndarray] = []

    def add_vertex(p: np.ndarray, kind: str, cl: tuple[int, ...]) -> int:
        v = len(pos2d)
        pos2d.append(np.asarray(p, dtype=float))
        g.add_node(
            v,
            pos=tuple(float(x) for x in lift(p[None])[0]),
            pos2d=(float(p[0]), float(p[1])),
            kind=kind,
            clusters=cl,
        )
        return v

    def add_edge(a: int, b: int, cl: int) -> None:
        pa, pb = np.array(g.nodes[a]["pos"]), np.array(g.nodes[b]["pos"])
        g.add_edge(
            a,
            b,
            weight=float(np.linalg.norm(pa - pb)),
            clusters=(cl,),
            kind=clusters[cl].kind,
        )

    centre = [add_vertex(c.centre, "centre", (c.id,)) for c in clusters]  # Alg. 4 l. 3, 7
    own: dict[int, list[int]] = {c.id: [centre[c.id]] for c in clusters}
    for br in borders:  # Alg. 4 l. 4–8
        m = add_vertex(br.midpoint, "border", (br.a, br.b))
        add_edge(centre[br.a], m, br.a)
        add_edge(m, centre[br.b], br.b)
        own[br.a].append(m)
        own[br.b].append(m)
    for c in clusters:  # Alg. 4 l. 9–19, bars only
        if c.kind != "bar" or len(c.boundary) < 3:
            continue
        for end in line_polygon_hits(c.centre, c.axis, c.boundary):
            if end is None:
                continue
            near = np.array([pos2d[v] for v in range(len(pos2d))])
            if np.min(np.linalg.norm(near - end, axis=1)) <= dmin_m:
                continue
            # A bar end is redundant when one of the bar's own border vertices
            # already lies on that side of the centre, closer to the end than
            # to the centre: the bar continues into a neighbour there.
            side = (end - c.centre) @ c.axis
            blocked = False
            for v in own[c.id][1:]:
                sv = (pos2d[v] - c.centre) @ c.axis
                if sv * side > 0 and abs(sv) > 0.5 * abs(side):
                    blocked = True
            if blocked:
                continue
            e = add_vertex(end, "end", (c.id,))
            add_edge(centre[c.id], e, c.id)
    # Isolated centres (a cluster with no neighbour and no end) carry no edge.
    g.remove_nodes_from([v for v in list(g.nodes) if g.degree(v) == 0])
    return g


def default_endpoints(g: nx.Graph) -> tuple[int, int]:
    """Two leaf vertices at the ends of the structure: the pair of degree-1
    vertices farthest apart (all vertices when fewer than two leaves);
    ties go to the smaller ids."""
    nodes = sorted(g.nodes)
    leaves = [v for v in nodes if g.degree(v) == 1]
    cand = leaves if len(leaves) >= 2 else nodes
    if len(cand) == 1:
        return cand[0], cand[0]
    p = np.array([g.nodes[v]["pos"] for v in cand])
    d = np.linalg.norm(p[:, None] - p[None], axis=2)
    i, j = np.unravel_index(int(np.argmax(d)), d.shape)
    a, b = sorted((cand[i], cand[j]))
    return a, b
