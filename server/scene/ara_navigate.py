"""Scene drawer of ``ara.navigate``: the processed cloud coloured by cluster,
cluster boundaries, graph vertices (click: start, then end → a new plan),
the route as numbered arrows, and the robot footprint driven along the path."""

from __future__ import annotations

import numpy as np

from server.planview import PlanView
from server.scene.common import (
    ROUTE_RGB,
    STEEL_RGB,
    add_polyline,
    add_start_end_picker,
    label_colors,
    rotation_to_wxyz,
)
from server.scene.context import DrawContext

LIFT = 0.01  # metres along the structure normal, so overlays sit above the steel


#: What this module draws (read by server.scene.drawers): kind → (function, robot shown live).
DRAWS = {"ara.navigate": ("draw", "ara")}


def draw(ctx: DrawContext, plan: PlanView) -> None:
    res = plan.result
    frame = res["frame"]
    normal = np.asarray(frame["normal"], dtype=float)
    e1, e2 = np.asarray(frame["e1"], dtype=float), np.asarray(frame["e2"], dtype=float)
    pts = np.asarray(plan.array("points"), dtype=np.float32)
    labels = np.asarray(plan.array("labels"), dtype=int)
    colors = label_colors(labels)
    for k in np.unique(labels):  # one point cloud per cluster
        sel = labels == k
        ctx.scene.add_point_cloud(
            f"{ctx.root}/cloud/{'noise' if k < 0 else k}",
            points=pts[sel],
            colors=colors[sel],
            point_size=0.006,
            precision="float32",
        )
    for c in res["clusters"]:
        b = np.asarray(c["boundary"], dtype=float)
        if len(b) >= 2:
            rgb = label_colors(np.array([c["id"]]))[0]
            add_polyline(
                ctx.scene,
                f"{ctx.root}/boundaries/{c['id']}",
                b + LIFT * normal,
                (int(rgb[0]), int(rgb[1]), int(rgb[2])),
                width=2.0,
                closed=True,
            )

    nodes = res["graph"]["nodes"]
    ids = [n["id"] for n in nodes]
    pos = np.array([n["pos"] for n in nodes], dtype=float).reshape(-1, 3)
    edges = res["graph"]["edges"]
    if edges:
        index = {v: i for i, v in enumerate(ids)}
        segs = np.array([[pos[index[e["u"]]], pos[index[e["v"]]]] for e in edges], dtype=np.float32)
        ctx.scene.add_line_segments(
            f"{ctx.root}/graph",
            points=segs + np.float32(2 * LIFT) * normal.astype(np.float32),
            colors=STEEL_RGB,
            thickness=2.0,
            thickness_units="screen",
        )
    add_start_end_picker(
        ctx,
        ctx.root,
        ids,
        pos + 3 * LIFT * normal,
        chosen=res,
        radius=0.035,  # a target a crew can click (2 cm was a few pixels)
        label_positions=pos + 6 * LIFT * normal,
    )

    # The route: one arrow per driven edge, numbered in driving order.
    route = res["route"]["edges"]
    if route:
        index = {v: i for i, v in enumerate(ids)}
        a = pos[[index[u] for u, _ in route]] + 4 * LIFT * normal
        b = pos[[index[v] for _, v in route]] + 4 * LIFT * normal
        ctx.scene.add_arrows(
            f"{ctx.root}/route",
            points=np.stack([a, b], axis=1).astype(np.float32),
            colors=ROUTE_RGB,
            shaft_radius=0.004,
            head_radius=0.012,
            head_length=0.03,
        )
        for k, (p, q) in enumerate(zip(a, b, strict=True)):
            ctx.scene.add_label(
                f"{ctx.root}/route_order/{k}",
                text=str(k + 1),
                position=tuple((p + q) / 2 + 2 * LIFT * normal),
            )

    path = np.asarray(plan.array("path_xyz"), dtype=float).reshape(-1, 3)
    yaw = np.asarray(plan.array("path_yaw"), dtype=float).reshape(-1)
    if len(path):
        add_polyline(
            ctx.scene, f"{ctx.root}/path", path + 3 * LIFT * normal, (255, 60, 200), width=3.0
        )
        fp = res["footprint"]
        box = ctx.scene.add_box(
            f"{ctx.root}/robot",
            color=(220, 40, 40),
            dimensions=(fp["length_m"], fp["width_m"], 0.01),
            opacity=0.6,
        )
        # The planned ARA rides the path on its footprint: the live and the
        # replayed robot are put under this node, so they move with the plan.
        ctx.add_urdf("ara", "ara")
        base = ctx.robot_frames[f"{ctx.root}/ara"]
        seg = np.linalg.norm(np.diff(path, axis=0), axis=1) + 1e-3  # turns take time too
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        speed = 0.3  # m/s, display only

        def update(t: float) -> None:
            i = int(np.clip(np.searchsorted(cum, t * speed), 0, len(path) - 1))
            c, s = np.cos(yaw[i]), np.sin(yaw[i])
            x_axis = c * e1 + s * e2
            y_axis = -s * e1 + c * e2
            R = np.column_stack([x_axis, y_axis, normal])
            centre = path[i] + R @ np.array([fp["center_x_m"], fp.get("center_y_m", 0.0), 0.0])
            box.position = tuple(centre + 2 * LIFT * normal)
            box.wxyz = rotation_to_wxyz(R)
            base.position = tuple(path[i] + 2 * LIFT * normal)
            base.wxyz = rotation_to_wxyz(R)

        update(0.0)
        ctx.animate(float(cum[-1] / speed) if cum[-1] > 0 else 1.0, update)
