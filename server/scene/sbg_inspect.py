"""Scene drawer of ``sbg.inspect``: the girder (deck, U-ribs, crossbeams,
welds) from the stored geometry, the planned path coloured by segment type,
the simulated trajectory and the climber's URDF animated along it."""

from __future__ import annotations

from typing import Any

import numpy as np

from server.planview import PlanView
from server.scene.common import ROUTE_RGB, STEEL_RGB
from server.scene.context import DrawContext

SEGMENT_RGB = {
    "lane": ROUTE_RGB,
    "corner_down": (200, 60, 200),
    "corner_up": (200, 60, 200),
    "s1": (40, 170, 220),
    "s2": (40, 120, 220),
    "s3": (40, 170, 220),
    "turn": (255, 255, 255),
}
TRAJ_RGB = (30, 200, 90)
WELD_RGB = (230, 60, 40)
LIFT = 0.003  # draw lines this far off the steel so they are not hidden in it
PLAYBACK_SPEEDUP = 20.0  # the robot drives at 20 mm/s; show it 20× faster


#: What this module draws (read by server.scene.drawers): kind → (function, robot shown live).
DRAWS = {"sbg.inspect": ("draw", "sbg_climber")}


def _rib_mesh(y: float, girder: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """Open trapezoid (two webs and the bottom) extruded along X."""
    L, wt, wb, h = (
        girder["length_m"],
        girder["rib_top_width_m"],
        girder["rib_bottom_width_m"],
        girder["rib_depth_m"],
    )
    prof = np.array([[y - wt / 2, 0.0], [y - wb / 2, -h], [y + wb / 2, -h], [y + wt / 2, 0.0]])
    verts = np.array([[x, py, pz] for x in (0.0, L) for py, pz in prof], dtype=np.float32)
    faces = []
    for i in range(3):
        a, b, c, d = i, i + 1, 4 + i + 1, 4 + i
        faces += [[a, b, c], [a, c, d]]
    return verts, np.array(faces, dtype=np.uint32)


def _lift_off_walls(p: np.ndarray, length: float) -> np.ndarray:
    """Move path points a few mm into the free space (roof normal −Z,
    crossbeam normals +X at X = 0 and −X at X = length)."""
    q = p.copy()
    q[np.abs(p[:, 2]) < 1e-9, 2] -= LIFT
    q[np.abs(p[:, 0]) < 1e-9, 0] += LIFT
    q[np.abs(p[:, 0] - length) < 1e-9, 0] -= LIFT
    return q


def _add_robot(ctx: DrawContext) -> Any:
    """The climber's URDF under ``{root}/robot``."""
    return ctx.add_urdf("sbg_climber", "robot")


def draw(ctx: DrawContext, plan: PlanView) -> None:
    res = plan.result
    g = res["girder"]
    L = float(g["length_m"])
    n_ribs = int(g["n_ribs"])
    ys = np.arange(n_ribs) * float(g["rib_spacing_m"])
    y0, y1 = -float(g["edge_width_m"]), ys[-1] + float(g["edge_width_m"])
    t = float(g["deck_thickness_m"])
    scene = ctx.scene
    root = ctx.root
    # Deck (semi-transparent so the robot under it stays visible from above).
    scene.add_box(
        f"{root}/girder/deck",
        color=STEEL_RGB,
        dimensions=(L, y1 - y0, t),
        position=(L / 2, (y0 + y1) / 2, t / 2),
        opacity=0.35,
    )
    for i, y in enumerate(ys):
        v, f = _rib_mesh(float(y), g)
        scene.add_mesh_simple(
            f"{root}/girder/rib{i}", v, f, color=(120, 130, 145), side="double", opacity=0.8
        )
    ct, cd = float(g["crossbeam_thickness_m"]), float(g["crossbeam_depth_m"])
    for i, x in enumerate((-ct / 2, L + ct / 2)):
        scene.add_box(
            f"{root}/girder/crossbeam{i}",
            color=(110, 120, 135),
            dimensions=(ct, y1 - y0, cd),
            position=(x, (y0 + y1) / 2, -cd / 2),
            opacity=0.45,
        )
    # Rib-to-deck welds: two per rib, along X at the rib toes.
    toes = np.concatenate([ys - g["rib_top_width_m"] / 2, ys + g["rib_top_width_m"] / 2])
    welds = np.array([[[0.0, y, -LIFT], [L, y, -LIFT]] for y in toes], dtype=np.float32)
    scene.add_line_segments(
        f"{root}/girder/welds",
        points=welds,
        colors=WELD_RGB,
        thickness=3.0,
        thickness_units="screen",
    )
    for k, lane in enumerate(res["lane_order"]):
        yc = (lane + 0.5) * float(g["rib_spacing_m"])
        scene.add_label(
            f"{root}/labels/lane{lane}", text=f"lane {lane} (#{k + 1})", position=(L / 2, yc, -0.02)
        )
    # Planned path, one colour per segment type.
    pts = plan.array("path_xyz")
    seg = plan.array("path_segment")
    kinds = [s["kind"] for s in res["segments"]]
    lifted = _lift_off_walls(pts, L)
    same = seg[1:] == seg[:-1]
    pairs = np.stack([lifted[:-1], lifted[1:]], axis=1)[same]
    colors = np.array(
        [SEGMENT_RGB.get(kinds[s], ROUTE_RGB) for s in seg[:-1][same]], dtype=np.uint8
    )
    if len(pairs):
        scene.add_line_segments(
            f"{root}/path",
            points=pairs.astype(np.float32),
            colors=np.repeat(colors[:, None, :], 2, axis=1),
            thickness=5.0,
            thickness_units="screen",
        )
    # Simulated trajectory of the base origin.
    pos = plan.array("traj_pos")
    quat = plan.array("traj_quat")
    tt = plan.array("traj_t")
    arm = plan.array("traj_arm")
    # samples kept for the drawn line (k is the lane counter above)
    keep = np.unique(np.linspace(0, len(pos) - 1, min(len(pos), 4000)).astype(int))
    tp = _lift_off_walls(pos[keep], L) if len(keep) > 1 else pos[keep]
    if len(tp) > 1:
        scene.add_line_segments(
            f"{root}/trajectory",
            points=np.stack([tp[:-1], tp[1:]], axis=1).astype(np.float32),
            colors=TRAJ_RGB,
            thickness=2.0,
            thickness_units="screen",
        )
    # The robot, animated along the simulated run (wheel angle from distance).
    urdf = _add_robot(ctx)
    frame = scene.get_handle_by_name(f"{root}/robot")
    radius = float(res["robot"]["wheel_radius_m"])
    travel = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pos, axis=0), axis=1))])
    duration = float(tt[-1] - tt[0]) if len(tt) > 1 else 1.0

    def update(t_play: float) -> None:
        ts = tt[0] + t_play * PLAYBACK_SPEEDUP
        i = int(np.clip(np.searchsorted(tt, ts), 0, len(tt) - 1))
        frame.position = tuple(float(v) for v in pos[i])
        frame.wxyz = tuple(float(v) for v in quat[i])
        wheel = travel[i] / radius
        urdf.update_cfg(np.array([wheel, wheel, wheel, wheel, arm[i]]))

    update(0.0)
    ctx.animate(max(duration / PLAYBACK_SPEEDUP, 1.0), update)
