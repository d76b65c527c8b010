"""The structure picture of a report, drawn server-side with matplotlib.

:func:`layers` reads what a plan's kind stored — its cloud (``points``,
coloured by ``labels``), structure model members (``result.members``), member
graph (``result.graph``, or ``demo.route``'s ``nodes``/``edges``), clusters'
outlines, a blast surface and its spot order, and its route or path
(``path_xyz`` and like arrays, or an ``ara.inspect`` route's vertices on its
graph) — and :func:`render_png` draws them, with the findings as numbered
markers coloured by condition state, in a 3D view and a plan (top) view.

No pyplot: a :class:`matplotlib.figure.Figure` on an Agg canvas per call, a
fixed size and dpi, a thinned cloud chosen by stride (not at random), and a
PNG without the ``Software`` metadata, so the same data gives the same bytes.
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from server.reports.data import FindingData
from server.store.records import PlanRecord

#: Most cloud points drawn (thinned by a fixed stride).
MAX_POINTS = 20_000
#: Picture size (inches) and resolution.
FIG_SIZE = (11.0, 5.0)
DPI = 110
#: Marker colours of condition states 1–4 (good … severe).
CONDITION_COLOURS = {1: "#2e7d32", 2: "#f9a825", 3: "#ef6c00", 4: "#c62828"}
#: (N, 3) arrays drawn as the route / path, by name, in this order of preference.
PATH_ARRAYS = ("path_xyz", "traj_pos", "nozzle_tip")
#: Coordinates beyond this (m) are drawn from a local origin …
ORIGIN_FAR_M = 1000.0
#: … rounded down to a multiple of this (m).
ORIGIN_STEP_M = 10.0


@dataclass
class Layers:
    """What to draw, world frame (m)."""

    points: np.ndarray | None = None
    point_labels: np.ndarray | None = None
    #: Straight pieces (members, graph edges): (N, 2, 3).
    members: list[np.ndarray] = field(default_factory=list)
    edges: list[np.ndarray] = field(default_factory=list)
    #: Closed outlines (clusters, blast surface).
    outlines: list[np.ndarray] = field(default_factory=list)
    #: Polylines of the route / path.
    routes: list[np.ndarray] = field(default_factory=list)
    #: Graph vertices (M, 3).
    vertices: np.ndarray | None = None

    def empty(self) -> bool:
        return (
            self.points is None
            and not self.members
            and not self.edges
            and not self.outlines
            and not self.routes
            and self.vertices is None
        )


def _arr(plan: PlanRecord, name: str) -> np.ndarray | None:
    if name not in plan.arrays:
        return None
    try:
        a = np.asarray(plan.array(name))
    except (OSError, ValueError, KeyError):
        return None
    return a


def _xyz_rows(a: Any) -> np.ndarray | None:
    try:
        arr = np.asarray(a, dtype=float)
    except (TypeError, ValueError):
        return None
    if arr.ndim != 2 or arr.shape[0] == 0 or arr.shape[1] != 3:
        return None
    return arr[np.isfinite(arr).all(axis=1)]


def layers(plan: PlanRecord) -> Layers:
    """What ``plan`` stored that can be drawn."""
    out = Layers()
    res = plan.result or {}
    pts = _arr(plan, "points")
    if pts is not None and pts.ndim == 2 and pts.shape[1] == 3 and len(pts):
        labels = _arr(plan, "labels")
        step = max(1, -(-len(pts) // MAX_POINTS))  # ceil: at most MAX_POINTS
        out.points = np.asarray(pts[::step], dtype=float)
        if labels is not None and labels.shape == (len(pts),):
            out.point_labels = labels[::step]
    for m in res.get("members", []) or []:
        axis = _xyz_rows(m.get("axis")) if isinstance(m, dict) else None
        if axis is not None and len(axis) >= 2:
            out.members.append(axis[:2])
    graph = res.get("graph")
    pos: dict[Any, np.ndarray] = {}
    if isinstance(graph, dict):
        for n in graph.get("nodes", []) or []:
            if isinstance(n, dict) and _xyz_rows([n.get("pos")]) is not None:
                pos[n.get("id")] = np.asarray(n["pos"], dtype=float)
        pairs = [
            (e.get("u"), e.get("v")) for e in graph.get("edges", []) or [] if isinstance(e, dict)
        ]
    elif isinstance(res.get("nodes"), dict):  # demo.route: name → xyz, edges as name pairs
        for k, p in res["nodes"].items():
            if _xyz_rows([p]) is not None:
                pos[k] = np.asarray(p, dtype=float)
        pairs = [tuple(e[:2]) for e in res.get("edges", []) or [] if isinstance(e, list | tuple)]
    else:
        pairs = []
    out.edges = [np.stack([pos[u], pos[v]]) for u, v in pairs if u in pos and v in pos]
    if pos:
        out.vertices = np.stack(list(pos.values()))
    for c in res.get("clusters", []) or []:
        ring = _xyz_rows(c.get("boundary")) if isinstance(c, dict) else None
        if ring is not None and len(ring) >= 3:
            out.outlines.append(ring)
    surface = res.get("surface")
    if isinstance(surface, dict):
        ring = _xyz_rows(surface.get("outline_world"))
        if ring is not None and len(ring) >= 3:
            out.outlines.append(ring)
    out.routes = _routes(plan, res, pos)
    return out


def _routes(plan: PlanRecord, res: dict[str, Any], pos: dict[Any, np.ndarray]) -> list[np.ndarray]:
    for name in PATH_ARRAYS:
        a = _arr(plan, name)
        if a is not None:
            rows = _xyz_rows(a)
            if rows is not None and len(rows) >= 2:
                return [rows]
    discs = _arr(plan, "disc_centers")
    if discs is not None:  # blast without a tool path: the spots in their order
        order = _arr(plan, "order")
        rows = _xyz_rows(discs if order is None else discs[np.asarray(order, dtype=int)])
        if rows is not None and len(rows) >= 2:
            return [rows]
    routes = res.get("routes") or ([res["route"]] if isinstance(res.get("route"), dict) else [])
    out = []
    for r in routes:
        verts = r.get("vertices", []) if isinstance(r, dict) else []
        line = [pos[v] for v in verts if v in pos]
        if len(line) >= 2:
            out.append(np.stack(line))
    return out


def _shifted(lay: Layers, origin: np.ndarray) -> Layers:
    def sh(a: np.ndarray) -> np.ndarray:
        return a - origin

    return Layers(
        points=None if lay.points is None else sh(lay.points),
        point_labels=lay.point_labels,
        members=[sh(a) for a in lay.members],
        edges=[sh(a) for a in lay.edges],
        outlines=[sh(a) for a in lay.outlines],
        routes=[sh(a) for a in lay.routes],
        vertices=None if lay.vertices is None else sh(lay.vertices),
    )


def _minus(
    p: tuple[float, float, float] | None, o: np.ndarray
) -> tuple[float, float, float] | None:
    if p is None:
        return None
    return (p[0] - float(o[0]), p[1] - float(o[1]), p[2] - float(o[2]))


def render_png(plan: PlanRecord, findings: Sequence[FindingData]) -> bytes | None:
    """The picture as PNG bytes, or None when the plan stored nothing to draw.

    Survey coordinates (hundreds of km) are drawn from a round local origin
    (a multiple of :data:`ORIGIN_STEP_M`), named in the axis labels.
    """
    lay = layers(plan)
    marks = [f for f in findings if f.xyz is not None]
    if lay.empty() and not marks:
        return None
    box0 = _bounds(lay, marks)
    origin = np.zeros(3)
    if box0 is not None and np.abs(box0[0]).max() > ORIGIN_FAR_M:
        origin = np.floor(box0[0] / ORIGIN_STEP_M) * ORIGIN_STEP_M
        lay = _shifted(lay, origin)
        marks = [replace(f, xyz=_minus(f.xyz, origin)) for f in marks]
    names = [
        f"{a} (m)" if o == 0 else f"{a} − {o:.0f} (m)" for a, o in zip("xyz", origin, strict=True)
    ]
    # matplotlib (0.3 s) is imported by the first report drawn, not by every
    # server start-up
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.ticker import MaxNLocator

    fig = Figure(figsize=FIG_SIZE, dpi=DPI)
    FigureCanvasAgg(fig)
    ax3 = fig.add_subplot(1, 2, 1, projection="3d")
    ax2 = fig.add_subplot(1, 2, 2)
    _draw(ax3, lay, marks, three_d=True)
    _draw(ax2, lay, marks, three_d=False)
    ax3.set_title("3D view", fontsize=10)
    ax2.set_title("plan view (x–y)", fontsize=10)
    ax3.set_xlabel(names[0], fontsize=8)
    ax3.set_ylabel(names[1], fontsize=8)
    ax3.set_zlabel(names[2], fontsize=8)
    ax3.tick_params(labelsize=7)
    ax2.set_xlabel(names[0])
    ax2.set_ylabel(names[1])
    ax2.set_aspect("equal", adjustable="datalim")
    ax2.grid(True, linewidth=0.3, alpha=0.5)
    box = _bounds(lay, marks)
    if box is not None:
        lo, hi = box
        span = np.maximum(hi - lo, 1e-6)
        ax3.set_xlim(lo[0], hi[0])
        ax3.set_ylim(lo[1], hi[1])
        ax3.set_zlim(lo[2], hi[2])
        aspect = np.maximum(span / span.max(), 0.12)  # a flat structure keeps a readable z
        ax3.set_box_aspect((float(aspect[0]), float(aspect[1]), float(aspect[2])))
        ax3.zaxis.set_major_locator(MaxNLocator(3))
    handles, names = ax2.get_legend_handles_labels()
    if handles:
        fig.legend(handles, names, loc="lower center", ncol=min(len(names), 6), fontsize=8)
    fig.subplots_adjust(left=0.02, right=0.98, top=0.93, bottom=0.14, wspace=0.3)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI, metadata={"Software": None})
    return buf.getvalue()


def _bounds(lay: Layers, marks: Sequence[FindingData]) -> tuple[np.ndarray, np.ndarray] | None:
    chunks: list[np.ndarray] = []
    if lay.points is not None:
        chunks.append(lay.points)
    chunks += [s.reshape(-1, 3) for s in lay.members + lay.edges]
    chunks += lay.outlines + lay.routes
    if lay.vertices is not None:
        chunks.append(lay.vertices)
    chunks += [np.asarray([f.xyz], dtype=float) for f in marks]
    if not chunks:
        return None
    allp = np.concatenate(chunks)
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    pad = np.maximum((hi - lo) * 0.03, 0.05)
    return lo - pad, hi + pad


def _draw(ax: Any, lay: Layers, marks: Sequence[FindingData], *, three_d: bool) -> None:
    def xy(a: np.ndarray) -> tuple[Any, ...]:
        return (a[:, 0], a[:, 1], a[:, 2]) if three_d else (a[:, 0], a[:, 1])

    if lay.points is not None:
        colour: Any = "#9e9e9e"
        kw: dict[str, Any] = {}
        if lay.point_labels is not None:
            colour = np.asarray(lay.point_labels, dtype=float)
            kw = {"cmap": "tab20"}
        ax.scatter(*xy(lay.points), s=0.6, c=colour, alpha=0.35, linewidths=0, label="cloud", **kw)
    for i, seg in enumerate(lay.members):
        ax.plot(*xy(seg), color="#78909c", linewidth=3.0, label="members" if i == 0 else None)
    for i, seg in enumerate(lay.edges):
        ax.plot(*xy(seg), color="#90a4ae", linewidth=0.8, label="graph" if i == 0 else None)
    for i, ring in enumerate(lay.outlines):
        closed = np.vstack([ring, ring[:1]])
        ax.plot(*xy(closed), color="#6a1b9a", linewidth=1.0, label="outline" if i == 0 else None)
    for i, line in enumerate(lay.routes):
        ax.plot(*xy(line), color="#1565c0", linewidth=1.0, label="route" if i == 0 else None)
    if lay.vertices is not None:
        ax.scatter(*xy(lay.vertices), s=6, color="#455a64", linewidths=0)
    seen: set[int] = set()
    for f in marks:
        assert f.xyz is not None
        p = np.asarray([f.xyz], dtype=float)
        first = f.condition_state not in seen
        seen.add(f.condition_state)
        extra: dict[str, Any] = {"depthshade": False} if three_d else {"zorder": 5}
        ax.scatter(
            *xy(p),
            s=60,
            color=CONDITION_COLOURS.get(f.condition_state, "#000000"),
            edgecolors="black",
            linewidths=0.6,
            marker="o",
            label=f"finding: {f.condition_state} {f.condition}" if first else None,
            **extra,
        )
        if three_d:
            ax.text(f.xyz[0], f.xyz[1], f.xyz[2], f" {f.number}", fontsize=8)
        else:
            ax.annotate(str(f.number), (f.xyz[0], f.xyz[1]), xytext=(4, 4),
                        textcoords="offset points", fontsize=8, zorder=6)  # fmt: skip
