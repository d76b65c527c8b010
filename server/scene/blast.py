"""Scene drawer of ``blast``: the surface outline, the blast discs coloured by
visiting order with the nozzle path, the obstacles (I-beam boxes, obstacle
points, the cloud's planes — click a plane's marker to re-plan on it), and
the DENSO arm animated along the joint trajectory with its nozzle and blast
cone (the cone shows while the nozzle is open)."""

from __future__ import annotations

import numpy as np

from server.planview import PlanView
from server.scene.common import (
    FAIL_RGB,
    ROUTE_RGB,
    STEEL_RGB,
    add_polyline,
    add_spheres,
    disc_mesh,
    label_colors,
    ramp_colors,
    rotation_to_wxyz,
)
from server.scene.context import DrawContext
from server.scene.obstacle_editor import ObstacleEditor

LIFT = 0.003  # overlays this far off the steel, toward the nozzle
PLAYBACK_SPEEDUP = 4.0
NOZZLE_M = 0.1
CONE_RGB = (240, 200, 60)
#: A plane's pick marker's radius as a fraction of the cloud's diagonal (2 %:
#: about 8 px in the framed view, clear of its neighbours on the samples).
PLANE_MARKER_FRACTION = 0.02


#: What this module draws (read by server.scene.drawers): kind → (function, robot shown live).
DRAWS = {"blast": ("draw", "denso_vm6083")}


def _rot_z_to(axis: np.ndarray) -> np.ndarray:
    """A rotation taking +z to ``axis``."""
    z = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], axis=1)


def _cone(r0: float, r1: float, z0: float, z1: float, n: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """Open truncated cone along +z (vertices, faces)."""
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    ring0 = np.c_[r0 * np.cos(a), r0 * np.sin(a), np.full(n, z0)]
    ring1 = np.c_[r1 * np.cos(a), r1 * np.sin(a), np.full(n, z1)]
    v = np.vstack([ring0, ring1]).astype(np.float32)
    f = []
    for i in range(n):
        j = (i + 1) % n
        f += [[i, j, n + j], [i, n + j, n + i]]
    return v, np.asarray(f, dtype=np.uint32)


def draw(ctx: DrawContext, plan: PlanView) -> None:
    res = plan.result
    scene, root = ctx.scene, ctx.root
    surf = res["surface"]
    n = np.asarray(surf["normal"], dtype=float)
    base = np.asarray(res["robot_base"], dtype=float)
    # the side of the plane the robot is on
    side = 1.0 if (base[:3, 3] - np.asarray(surf["origin"])) @ n >= 0 else -1.0
    lift = side * n * LIFT
    add_polyline(
        scene,
        f"{root}/surface/outline",
        np.asarray(surf["outline_world"]) + lift,
        FAIL_RGB,
        4.0,
        True,
    )
    for i, h in enumerate(surf.get("holes_world", [])):
        add_polyline(scene, f"{root}/surface/hole{i}", np.asarray(h) + lift, FAIL_RGB, 3.0, True)

    # discs coloured by visiting order (skipped ones grey) and the nozzle path
    centers = plan.array("disc_centers")
    radii = plan.array("disc_radii")
    order = plan.array("order")
    rank = np.full(len(centers), -1)
    rank[order] = np.arange(len(order))
    cols = np.full((len(centers), 3), 110, dtype=np.uint8)
    cols[order] = ramp_colors(len(order))
    verts, faces = disc_mesh(32)
    q_disc = rotation_to_wxyz(_rot_z_to(side * n))
    scene.add_batched_meshes_simple(
        f"{root}/discs",
        vertices=verts,
        faces=faces,
        batched_wxyzs=np.tile(np.asarray(q_disc, np.float32), (len(centers), 1)),
        batched_positions=(centers + lift).astype(np.float32),
        batched_scales=radii.astype(np.float32),
        batched_colors=cols,
        batched_opacities=np.full(len(centers), 0.55, np.float32),
        side="double",
        lod="off",
    )
    if len(order) > 1:
        add_polyline(scene, f"{root}/nozzle_path", centers[order] + 2 * lift, ROUTE_RGB, 3.0)
    scene.add_label(
        f"{root}/labels/start", text="start", position=tuple(centers[order[0]] + 8 * lift)
    )

    # obstacles: drawn, and editable in the scene (a proposal with new boxes)
    drawn, editable = [], []
    for i, b in enumerate(res.get("boxes", [])):
        c, h = np.asarray(b["center"], dtype=float), np.asarray(b["half"], dtype=float)
        drawn.append(
            scene.add_box(
                f"{root}/obstacles/box{i}",
                color=STEEL_RGB,
                dimensions=tuple(2.0 * h),
                position=tuple(c),
                opacity=0.3,
            )
        )
        editable.append((c - h, c + h, str(b.get("name", ""))))
    middle = np.asarray(centers, dtype=float).mean(axis=0) if len(centers) else base[:3, 3]
    ctx.tools["obstacles"] = ObstacleEditor(ctx, editable, middle, static=drawn)
    if "obstacle_points" in plan.arrays:
        pts = plan.array("obstacle_points")
        scene.add_point_cloud(
            f"{root}/obstacles/points",
            pts.astype(np.float32),
            (220, 60, 60),
            point_size=0.01,
            precision="float32",
        )
    if "cloud_points" in plan.arrays:
        cp = plan.array("cloud_points")
        lab = plan.array("cloud_label")
        scene.add_point_cloud(
            f"{root}/cloud",
            cp.astype(np.float32),
            label_colors(lab),
            point_size=0.006,
            precision="float32",
        )
        planes = res.get("planes", [])
        if planes:
            cent = np.array([pl["centroid"] for pl in planes], dtype=float)

            def pick(i: int) -> None:
                ctx.propose({"plane_index": int(i)})

            # Pick targets sized to the scene: a fixed 3 cm drew 4 px wide in
            # the framed view of a 3 m sample, too small to hit on a tablet.
            extent = float(np.linalg.norm(np.ptp(cp, axis=0))) if len(cp) else 0.0
            add_spheres(
                scene,
                f"{root}/planes",
                cent,
                radius=float(np.clip(PLANE_MARKER_FRACTION * extent, 0.03, 0.25)),
                colors=label_colors(np.arange(len(planes))),
                on_click=pick,
            )

    # the arm, its nozzle and the blast cone, animated
    q = plan.array("q")
    t = plan.array("times")
    tip = plan.array("nozzle_tip")
    axis = plan.array("nozzle_axis")
    seg = plan.array("segment")
    spot = plan.array("waypoint_spot")
    urdf = ctx.add_urdf("denso_vm6083", "robot", root_pose=base)
    tool = scene.add_frame(f"{root}/tool", show_axes=False)
    scene.add_cylinder(
        f"{root}/tool/nozzle",
        radius=0.012,
        height=NOZZLE_M,
        color=(60, 60, 70),
        position=(0.0, 0.0, NOZZLE_M / 2),
    )
    used = res.get("params_used", {})
    ds = float(used.get("stream_length_mm", 300.0)) / 1000.0
    r = float(res.get("disc_radius_m", 0.04))
    cv, cf = _cone(0.0065, r, NOZZLE_M, NOZZLE_M + ds)
    cone = scene.add_mesh_simple(
        f"{root}/tool/cone", cv, cf, color=CONE_RGB, opacity=0.35, side="double"
    )
    blasting = np.zeros(len(q), dtype=bool)
    on = False
    for k in range(len(q)):  # the nozzle is open from the first spot on, except while reconfiguring
        if seg[k] == 3:
            on = False
        if spot[k] >= 0:
            on = True
        blasting[k] = on
    duration = float(t[-1]) if len(t) > 1 else 1.0

    def update(t_play: float) -> None:
        i = int(np.clip(np.searchsorted(t, t_play * PLAYBACK_SPEEDUP), 0, len(q) - 1))
        urdf.update_cfg(q[i])
        R = _rot_z_to(axis[i])
        tool.position = tuple(float(v) for v in tip[i] - NOZZLE_M * axis[i])
        tool.wxyz = rotation_to_wxyz(R)
        cone.visible = bool(blasting[i])

    update(0.0)
    ctx.animate(max(duration / PLAYBACK_SPEEDUP, 1.0), update)
