"""Ground-truth scoring of the navigation chain on synthetic structures.

Used by the tests and the benchmark (issue "Done when"):

* :func:`transfer_labels` — ground-truth component of every processed point
  (nearest raw steel point, within a tolerance);
* :func:`segmentation_correct` — the predicted clusters match the true bars
  and cross areas one to one (majority mapping is a bijection and the kinds
  agree);
* :func:`bar_coverage` — for every true bar, the fraction of its centre line
  lying within ``half a flange + 3 cm`` of the route's polyline.
"""

from __future__ import annotations

from collections.abc import Sequence

import networkx as nx
import numpy as np
from scipy.spatial import cKDTree

from planners.navigation.synthetic import SyntheticStructure


def transfer_labels(
    points3d: np.ndarray, structure: SyntheticStructure, *, tol_m: float = 0.03
) -> np.ndarray:
    """Ground-truth component per processed point (−1 when no steel point within ``tol_m``)."""
    steel = structure.labels >= 0
    tree = cKDTree(structure.points[steel])
    d, i = tree.query(np.asarray(points3d, dtype=float), k=1)
    out = structure.labels[steel][i]
    return np.where(d <= tol_m, out, -1)


def segmentation_correct(
    labels: np.ndarray,
    kinds: Sequence[str],
    gt_labels: np.ndarray,
    gt_kinds: Sequence[str],
) -> tuple[bool, dict[str, float]]:
    """True when predicted clusters ↔ true components one to one with equal kinds.

    Each predicted cluster maps to the true component holding most of its
    points; the segmentation is correct when that map is a bijection onto
    every true component that has points and each pair has the same kind.
    Also returns the point accuracy under that map.
    """
    valid = (labels >= 0) & (gt_labels >= 0)
    n_pred, n_gt = len(kinds), len(gt_kinds)
    if n_pred == 0 or not np.any(valid):
        return False, {"accuracy": 0.0, "n_pred": n_pred, "n_gt": n_gt}
    conf = np.zeros((n_pred, n_gt), dtype=np.int64)
    np.add.at(conf, (labels[valid], gt_labels[valid]), 1)
    major = conf.argmax(axis=1)
    present = np.nonzero(conf.sum(axis=0) > 0)[0]
    bijective = len(set(major.tolist())) == n_pred and set(major.tolist()) == set(present.tolist())
    kinds_ok = all(kinds[p] == gt_kinds[major[p]] for p in range(n_pred))
    accuracy = float(conf[np.arange(n_pred), major].sum() / conf.sum())
    return bool(bijective and kinds_ok), {
        "accuracy": accuracy,
        "n_pred": n_pred,
        "n_gt": len(present),
    }


def _point_segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(P, S) distances from points (P, 3) to segments a→b (S, 3)."""
    ab = b - a
    ll = np.einsum("sk,sk->s", ab, ab)
    ll = np.where(ll > 0, ll, 1.0)
    t = np.einsum("psk,sk->ps", p[:, None, :] - a[None], ab) / ll
    t = np.clip(t, 0.0, 1.0)
    closest = a[None] + t[..., None] * ab[None]
    return np.linalg.norm(p[:, None, :] - closest, axis=2)


def bar_coverage(
    structure: SyntheticStructure,
    graph: nx.Graph,
    route_edges: Sequence[tuple],
    *,
    extra_m: float = 0.03,
) -> np.ndarray:
    """Per true bar, the fraction of its centre line within ``w/2 + extra_m`` of the route.

    ``route_edges`` are ``(u, v, ...)`` edges of ``graph`` whose node ``pos``
    (xyz, robot frame) gives the route's polyline.
    """
    if route_edges:
        a = np.array([graph.nodes[e[0]]["pos"] for e in route_edges], dtype=float)
        b = np.array([graph.nodes[e[1]]["pos"] for e in route_edges], dtype=float)
    else:
        a = b = np.zeros((0, 3))
    out = np.zeros(structure.n_bars)
    for bar in range(structure.n_bars):  # per bar (tens)
        line = structure.bar_centerline(bar)
        if len(a) == 0:
            continue
        d = _point_segment_distance(line, a, b).min(axis=1)
        tol = structure.layout.widths[bar] / 2.0 + extra_m
        out[bar] = float(np.mean(d <= tol))
    return out
