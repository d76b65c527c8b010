"""Joints where member axes meet and the member graph.

Two members meet when their axis segments, each extended at both ends by
the other's section radius plus a reach, come within the sum of their
radii (a diagonal's axis stops at the chord's surface, not its axis).  The
joint is the midpoint of the two closest points (closest points of two
segments, Lumelsky 1985); joints closer than a section apart are merged.
Candidate pairs come from a KD-tree on sampled axes, never all pairs.

The graph then splits every member at the joints on it: nodes are joints
and free member ends, edges the spans between consecutive nodes.
"""

from __future__ import annotations

import itertools

import networkx as nx
import numpy as np
from scipy.spatial import cKDTree

from planners.structure.model import Joint, Member

#: members closer to parallel than this (15°) meet only along their bodies
PARALLEL_COS = float(np.cos(np.radians(15.0)))


def closest_points(
    p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray
) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Closest points of segments p0p1 and q0q1 and their parameters in [0, 1]."""
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a, e, f = d1 @ d1, d2 @ d2, d2 @ r
    c, b = d1 @ r, d1 @ d2
    denom = a * e - b * b
    s = float(np.clip((b * f - c * e) / denom, 0, 1)) if denom > 1e-12 * a * e else 0.0
    t = (b * s + f) / e if e > 0 else 0.0
    if t < 0:
        t, s = 0.0, float(np.clip(-c / a, 0, 1)) if a > 0 else 0.0
    elif t > 1:
        t, s = 1.0, float(np.clip((b - c) / a, 0, 1)) if a > 0 else 0.0
    return p0 + s * d1, q0 + t * d2, s, float(t)


def _extended(axis: np.ndarray, by: float) -> np.ndarray:
    d = axis[1] - axis[0]
    n = np.linalg.norm(d)
    u = d / n if n > 0 else d
    return np.array([axis[0] - by * u, axis[1] + by * u])


def _past_end(s: float, length: float, ext: float) -> bool:
    """Whether parameter ``s`` ∈ [0, 1] of a segment lengthened by ``ext`` at
    both ends falls beyond the original segment's ends."""
    t = s * (length + 2 * ext) - ext
    return t < 0 or t > length


def find_joints(
    members: list[Member], radii: np.ndarray, reach: float, side_tol: float = 0.0
) -> list[Joint]:
    """Joints of ``members`` (``radii``: section radius per member, m):
    within the radii plus ``reach`` past an end, plus ``side_tol`` along the
    bodies."""
    if len(members) < 2:
        return []
    step = max(0.2, float(radii.max()))
    pts, own = [], []
    for i, m in enumerate(members):
        ax = _extended(m.axis, radii[i] + reach)
        n = max(2, int(np.ceil(np.linalg.norm(ax[1] - ax[0]) / step)) + 1)
        pts.append(ax[0] + np.outer(np.linspace(0, 1, n), ax[1] - ax[0]))
        own.append(np.full(n, i))
    samples, owner = np.vstack(pts), np.concatenate(own)
    pairs = cKDTree(samples).query_pairs(
        2 * float(radii.max()) + reach + step, output_type="ndarray"
    )
    cand = (
        np.unique(
            np.sort(np.column_stack([owner[pairs[:, 0]], owner[pairs[:, 1]]]), axis=1), axis=0
        )
        if len(pairs)
        else np.zeros((0, 2), int)
    )
    raw: list[tuple[np.ndarray, set[int]]] = []
    for i, j in cand:
        if i == j:
            continue
        ext_a, ext_b = radii[j] + reach, radii[i] + reach
        a = _extended(members[i].axis, ext_a)
        b = _extended(members[j].axis, ext_b)
        pa, pb, sa, sb = closest_points(a[0], a[1], b[0], b[1])
        # the reach bridges what a member's points stop short of, past its
        # ends only: two members side by side along their lengths do not meet
        past = _past_end(sa, members[i].length_m, ext_a) or _past_end(
            sb, members[j].length_m, ext_b
        )
        # parallel members side by side do not meet past their ends either
        past = past and abs(float(members[i].direction @ members[j].direction)) < PARALLEL_COS
        allowed = radii[i] + radii[j] + (reach if past else side_tol)
        if np.linalg.norm(pa - pb) <= allowed:
            raw.append((0.5 * (pa + pb), {int(i), int(j)}))
    if not raw:
        return []
    # merge joints closer than a section: one node where several members meet
    pos = np.array([r[0] for r in raw])
    tol = max(float(np.median(radii)) * 2, reach)
    groups: nx.Graph = nx.Graph()
    groups.add_nodes_from(range(len(raw)))
    groups.add_edges_from(cKDTree(pos).query_pairs(tol))
    out: list[Joint] = []
    for comp in sorted(nx.connected_components(groups), key=min):
        idx = sorted(comp)
        meeting: set[int] = set()
        for k in idx:
            meeting |= raw[k][1]
        out.append(
            Joint(len(out), pos[idx].mean(axis=0), tuple(sorted(members[i].id for i in meeting)))
        )
    return out


def member_graph(members: list[Member], joints: list[Joint], end_tol: float) -> nx.MultiGraph:
    """Nodes: joints (``kind="joint"``) and free ends (``kind="end"``) with
    ``pos``; edges: the spans of each member between consecutive nodes along
    it, with ``member`` and ``weight`` (span length along the axis, m).
    A member end within ``end_tol`` of its outermost joint ends there."""
    g: nx.MultiGraph = nx.MultiGraph()
    for j in joints:
        g.add_node(j.id, pos=np.asarray(j.pos, float), kind="joint", joint=j.id)
    next_id = len(joints)
    by_member: dict[int, list[Joint]] = {}
    for j in joints:
        for mid in j.members:
            by_member.setdefault(mid, []).append(j)
    for m in members:
        a, b = m.axis
        length = m.length_m
        u = m.direction
        stops = sorted((float((j.pos - a) @ u), j.id) for j in by_member.get(m.id, []))
        nodes: list[tuple[float, int]] = []
        if not stops or stops[0][0] > end_tol:
            g.add_node(next_id, pos=a.copy(), kind="end", member=m.id)
            nodes.append((0.0, next_id))
            next_id += 1
        nodes.extend(stops)
        if not stops or stops[-1][0] < length - end_tol:
            g.add_node(next_id, pos=b.copy(), kind="end", member=m.id)
            nodes.append((length, next_id))
            next_id += 1
        for (t0, n0), (t1, n1) in itertools.pairwise(nodes):
            if n0 != n1:
                g.add_edge(n0, n1, member=m.id, weight=max(abs(t1 - t0), 1e-6))
    return g


def extend_to_joints(members: list[Member], joints: list[Joint]) -> None:
    """Lengthen each member's axis, in place, to the joints beyond its ends.

    A centroid line runs from joint to joint, but the scanned points of a
    member stop short of the joint, where the neighbour's steel is: the
    points there went to the neighbour, and the line fitted to the rest ends
    early.  Axes only grow here, along their own line."""
    on: dict[int, list[np.ndarray]] = {}
    for j in joints:
        for mid in j.members:
            on.setdefault(mid, []).append(j.pos)
    for m in members:
        if m.id not in on:
            continue
        u = m.direction
        t = np.array([(p - m.axis[0]) @ u for p in on[m.id]])
        lo, hi = min(0.0, float(t.min())), max(m.length_m, float(t.max()))
        m.axis = np.array([m.axis[0] + lo * u, m.axis[0] + hi * u])
