"""Hand-built StructureModels for the inspection tests: I-members with a top
and a bottom flange face (plane through the axis ± depth/2 along ``up``,
boundary the length × width rectangle) and a web face."""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import networkx as nx
import numpy as np

from planners.structure.model import Face, Joint, Member, StructureModel

_face_ids = iter(range(10**9))


def _unit(v) -> np.ndarray:
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def _rotate(v: np.ndarray, axis: np.ndarray, deg: float) -> np.ndarray:
    """Rodrigues rotation of v about the unit axis."""
    a = np.radians(deg)
    return v * np.cos(a) + np.cross(axis, v) * np.sin(a) + axis * (axis @ v) * (1 - np.cos(a))


def i_member(
    mid: int,
    p0,
    p1,
    *,
    width: float = 0.3,
    depth: float = 0.3,
    up=None,
    roll_deg: float = 0.0,
    faces: bool = True,
    flange_from: float = 0.0,
    flange_to: float | None = None,
) -> Member:
    """An I-member from p0 to p1; ``up`` the top flange's normal (default: world
    z made perpendicular to the axis, world x for a vertical axis), rolled
    about the axis by ``roll_deg``; the flanges run from ``flange_from`` to
    ``flange_to`` metres along the axis (default: the whole member)."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    d = _unit(p1 - p0)
    length = float(np.linalg.norm(p1 - p0))
    ref = np.array([0.0, 0.0, 1.0]) if up is None else np.asarray(up, float)
    if np.linalg.norm(ref - (ref @ d) * d) < 1e-9:
        ref = np.array([1.0, 0.0, 0.0])
    u = _unit(ref - (ref @ d) * d)
    u = _rotate(u, d, roll_deg)
    hi = length if flange_to is None else flange_to
    rect = np.array(
        [[flange_from, -width / 2], [hi, -width / 2], [hi, width / 2], [flange_from, width / 2]]
    )
    fl = []
    if faces:
        for sign in (1.0, -1.0):
            fl.append(
                Face(
                    id=next(_face_ids),
                    member=mid,
                    kind="flange",
                    origin=p0 + sign * u * depth / 2,
                    normal=sign * u,
                    x_axis=d,
                    boundary=rect.copy(),
                    area_m2=(hi - flange_from) * width,
                    n_points=100,
                )
            )
        side = np.cross(d, u)
        web = np.array([[0, -depth / 2], [length, -depth / 2], [length, depth / 2], [0, depth / 2]])
        fl.append(
            Face(
                id=next(_face_ids),
                member=mid,
                kind="web",
                origin=p0 + side * 0.005,
                normal=side,
                x_axis=d,
                boundary=web,
                area_m2=length * (depth - 0.02),
                n_points=100,
            )
        )
    return Member(
        id=mid, axis=np.stack([p0, p1]), profile="I", depth_m=depth, width_m=width, faces=fl
    )


def structure(
    nodes: dict[int, Sequence[float]], chains: Sequence[tuple[Sequence[int], dict]]
) -> StructureModel:
    """``chains``: (node ids along one member, i_member keyword arguments); the
    member runs from its first to its last node, one span per consecutive
    pair.  Vertices of degree 1 are ``"end"``, the others ``"joint"``."""
    g: nx.MultiGraph = nx.MultiGraph()
    members = []
    for mid, (ids, kw) in enumerate(chains):
        m = i_member(mid, nodes[ids[0]], nodes[ids[-1]], **kw)
        members.append(m)
        for a, b in itertools.pairwise(ids):
            w = float(np.linalg.norm(np.subtract(nodes[b], nodes[a])))
            g.add_edge(a, b, member=mid, weight=w)
    joints: list[Joint] = []
    for n in g.nodes:
        pos = np.asarray(nodes[n], float)
        kind = "end" if g.degree(n) == 1 else "joint"
        g.nodes[n].update(pos=pos, kind=kind)
        if kind == "joint":
            ms = tuple(sorted({d["member"] for _, _, d in g.edges(n, data=True)}))
            g.nodes[n]["joint"] = len(joints)
            joints.append(Joint(id=len(joints), pos=pos, members=ms))
    return StructureModel(
        members=members, joints=joints, graph=g, labels=np.zeros(0, int), spacing_m=0.01
    )
