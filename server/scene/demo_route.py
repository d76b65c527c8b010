"""Scene drawer of ``demo.route``: the graph, its vertices (clickable) and the route."""

from __future__ import annotations

import numpy as np

from server.planview import PlanView
from server.scene.common import ROUTE_RGB, STEEL_RGB, add_polyline, add_spheres
from server.scene.context import DrawContext

# Lift overlays above the steel so they are not hidden in it.
LIFT_LABEL = np.array([0.0, 0.0, 0.08])
LIFT_ROUTE = np.array([0.0, 0.0, 0.01])
LIFT_MARKER = np.array([0.0, 0.0, 0.05])


#: What this module draws (read by server.scene.drawers): kind → (function, robot shown live).
DRAWS = {"demo.route": ("draw", "ara")}


def draw(ctx: DrawContext, plan: PlanView) -> None:
    nodes: dict[str, list[float]] = plan.result.get("nodes") or plan.params["nodes"]
    names = list(nodes)
    pos = np.array([nodes[n] for n in names], dtype=float)
    edges = plan.result.get("edges") or plan.params["edges"]
    if edges:
        segs = np.array([[nodes[u], nodes[v]] for u, v in edges], dtype=np.float32)
        ctx.scene.add_line_segments(
            f"{ctx.root}/edges",
            points=segs,
            colors=STEEL_RGB,
            thickness=3.0,
            thickness_units="screen",
        )
    picks: list[str] = []

    def clicked(i: int) -> None:
        # First click picks the start, second the end, then a new plan is proposed.
        picks.append(names[i])
        if len(picks) == 2:
            ctx.propose({"start": picks[0], "end": picks[1]})
            picks.clear()

    add_spheres(ctx.scene, f"{ctx.root}/vertices", pos, radius=0.05, on_click=clicked)
    for n, p in zip(names, pos, strict=True):
        ctx.scene.add_label(f"{ctx.root}/labels/{n}", text=n, position=tuple(p + LIFT_LABEL))
    if "path_xyz" in plan.arrays:
        path = plan.array("path_xyz")
        add_polyline(ctx.scene, f"{ctx.root}/route", path + LIFT_ROUTE, ROUTE_RGB, width=6.0)
        marker = ctx.scene.add_icosphere(f"{ctx.root}/robot", radius=0.07, color=(220, 40, 40))
        seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        speed = 0.5  # m/s, for display only

        def update(t: float) -> None:
            s = min(t * speed, cum[-1])
            xyz = np.array([np.interp(s, cum, path[:, k]) for k in range(3)])
            marker.position = tuple(xyz + LIFT_MARKER)

        ctx.animate(float(cum[-1] / speed) if cum[-1] > 0 else 1.0, update)
