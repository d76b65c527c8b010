"""Scene drawer of ``ara.switch``: plane points coloured per plane, NCBE
boundary points, Alg. 2's candidate rectangles (green pass / red fail), the
foothold as axes, and the ARA URDF animated through the inch-worm jump."""

from __future__ import annotations

import numpy as np

from server.planview import PlanView
from server.scene.common import FAIL_RGB, PASS_RGB, add_polyline, label_colors
from server.scene.context import DrawContext, set_frame_pose

LIFT = 0.004  # metres along each plane's normal, so overlays sit above the points


#: What this module draws (read by server.scene.drawers): kind → (function, robot shown live).
DRAWS = {"ara.switch": ("draw", "ara")}


def draw(ctx: DrawContext, plan: PlanView) -> None:
    res = plan.result
    scene, root = ctx.scene, ctx.root
    pts = np.asarray(plan.array("points"), dtype=np.float32)
    labels = np.asarray(plan.array("plane_labels"), dtype=int)
    colors = label_colors(labels)
    for k in np.unique(labels):  # one point cloud per plane (grey: no plane)
        sel = labels == k
        scene.add_point_cloud(
            f"{root}/cloud/{'other' if k < 0 else f'plane{k}'}",
            points=pts[sel],
            colors=colors[sel],
            point_size=0.004,
            precision="float32",
        )
    normals = {pl["index"]: np.asarray(pl["normal"], float) for pl in res["planes"]}
    bnd = np.asarray(plan.array("boundary"), dtype=np.float32).reshape(-1, 3)
    bplane = np.asarray(plan.array("boundary_plane"), dtype=int)
    if len(bnd):
        lift = np.array([normals[int(k)] for k in bplane], dtype=np.float32) * LIFT
        scene.add_point_cloud(
            f"{root}/boundary",
            points=bnd + lift,
            colors=(255, 255, 255),
            point_size=0.008,
            precision="float32",
        )
    corners = np.asarray(plan.array("rect_corners"), dtype=float).reshape(-1, 4, 3)
    passed = np.asarray(plan.array("rect_passed"), dtype=bool)
    rplane = np.asarray(plan.array("rect_plane"), dtype=int)
    for i, (c, ok, k) in enumerate(zip(corners, passed, rplane, strict=True)):
        add_polyline(
            scene,
            f"{root}/rectangles/{i}",
            c + 2 * LIFT * normals[int(k)],
            PASS_RGB if ok else FAIL_RGB,
            width=3.0 if ok else 1.5,
            closed=True,
        )
    if res.get("foothold") is not None:
        axes = scene.add_frame(f"{root}/foothold", axes_length=0.08, axes_radius=0.004)
        set_frame_pose(axes, np.asarray(res["foothold"], float))

    # The robot: chain base = foot 2 at the base-frame origin until the
    # magnets swap, then foot 1 holds and the base pose is W1 · FK(q)⁻¹.
    urdf = ctx.add_urdf("ara", "robot")
    frame = scene.get_handle_by_name(f"{root}/robot")
    jump = res.get("jump")
    if jump is None:
        urdf.update_cfg(np.zeros(6))
        return
    from robots import load_robot

    ara = load_robot("ara")
    Q = np.asarray(plan.array("joint_trajectory"), dtype=float)
    times = np.asarray(plan.array("times"), dtype=float)
    anchor = np.asarray(plan.array("anchor"), dtype=int)
    W1 = np.asarray(jump["foot1_target"], dtype=float)
    step = max(1, len(Q) // 400)  # ≤ 400 poses: precompute base poses
    idx = np.arange(0, len(Q), step)
    F = ara.fk(Q[idx])  # (K,4,4) foot 1 in the chain base
    base = np.where(anchor[idx, None, None] == 1, W1 @ np.linalg.inv(F), np.eye(4))
    for ph in jump["phases"]:
        if ph["stop"] > ph["start"]:
            i = min(ph["start"], len(Q) - 1)
            scene.add_label(
                f"{root}/phases/{ph['name']}",
                text=f"{ph['name']}: {ph['description']}",
                position=tuple(
                    float(v)
                    for v in (base[i // step] @ ara.fk(Q[i], "link2"))[:3, 3] + [0, 0, 0.15]
                ),
            )
    duration = float(times[-1]) if len(times) else 1.0

    def update(t: float) -> None:
        k = int(np.clip(np.searchsorted(times[idx], t), 0, len(idx) - 1))
        set_frame_pose(frame, base[k])
        urdf.update_cfg(Q[idx[k]])

    update(0.0)
    ctx.animate(max(duration / 2.0, 1.0), lambda t: update(t * 2.0))
