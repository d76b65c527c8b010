"""Scene drawers of ``cmbot.climb`` and ``cmbot.manipulate``: the guardrail
(top bar, posts, middle rail, brackets, walkway) as boxes, the CMBOT URDF
animated through the climb or the arm motion, footholds or the tool path,
and the arm's covering spheres (toggle in the GUI)."""

from __future__ import annotations

from typing import Any

import numpy as np

from planners.cmbot.distance import Cuboid
from planners.cmbot.guardrail import Guardrail, GuardrailParams
from server.planview import PlanView
from server.scene.common import FAIL_RGB, ROUTE_RGB, STEEL_RGB, add_polyline, add_spheres
from server.scene.context import DrawContext, set_frame_pose

GROUP_RGB = {
    "guardrail": STEEL_RGB,
    "structure": (120, 120, 110),
    "climber": (90, 160, 90),
    "env": STEEL_RGB,
}
PATH_RGB = (40, 200, 90)
SPHERE_RGB = (90, 200, 255)
CLIMB_SPEEDUP = 10.0  # seed gait: 10 s per swing; show it 10× faster
ARM_SPEEDUP = 1.0


#: What this module draws (read by server.scene.drawers): kind → (function, robot shown live).
DRAWS = {"cmbot.climb": ("draw_climb", "cmbot"), "cmbot.manipulate": ("draw_manipulate", "cmbot")}


def _guardrail(res: dict[str, Any]) -> Guardrail:
    g = res["guardrail"]
    p = GuardrailParams(**g.get("params", {}))
    return Guardrail(np.array(g["segments"], float), np.array(g["posts"], float), p)


def _box(
    scene: Any, name: str, b: Cuboid, color: tuple[int, int, int], opacity: float = 1.0
) -> None:
    T = np.eye(4)
    T[:3, :3] = b.rotation
    T[:3, 3] = b.center
    h = scene.add_box(
        name, color=color, dimensions=tuple(float(v) for v in 2 * b.half), opacity=opacity
    )
    set_frame_pose(h, T)


def _draw_guardrail(ctx: DrawContext, g: Guardrail, x_lo: float, x_hi: float) -> None:
    for i, b in enumerate(g.boxes(x_lo, x_hi)):
        rgb = GROUP_RGB.get(b.group, STEEL_RGB)
        _box(
            ctx.scene,
            f"{ctx.root}/guardrail/{i:03d}_{b.name}",
            b,
            rgb,
            0.5 if b.name == "walkway" else 1.0,
        )


def _pose(x: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = x
    return T


def draw_climb(ctx: DrawContext, plan: PlanView) -> None:
    """Guardrail, footholds, sole paths and the robot walking (J1…J12 from the plan)."""
    res = plan.result
    g = _guardrail(res)
    t = plan.array("times")
    q = plan.array("q")
    rear = plan.array("rear")
    front = plan.array("front")
    x_lo = float(min(rear[:, 0].min(), front[:, 0].min())) - 1.5
    x_hi = float(max(rear[:, 0].max(), front[:, 0].max())) + 1.5
    _draw_guardrail(ctx, g, x_lo, x_hi)
    soles = np.array(res["footholds"], float).reshape(-1)
    add_spheres(
        ctx.scene,
        f"{ctx.root}/footholds",
        np.c_[soles, 0 * soles, 0 * soles + 0.005],
        radius=0.015,
        colors=ROUTE_RGB,
    )
    for i, (a, b) in enumerate(g.gaps):
        ctx.scene.add_label(
            f"{ctx.root}/labels/gap{i}",
            text=f"gap {1e3 * (b - a):.0f} mm",
            position=(float((a + b) / 2), -0.15, 0.05),
        )
    add_polyline(ctx.scene, f"{ctx.root}/front_path", front, PATH_RGB, width=3.0)
    add_polyline(ctx.scene, f"{ctx.root}/rear_path", rear, (200, 120, 40), width=3.0)
    bad = [v for v in res.get("violations", [])]
    for i, v in enumerate(bad[:20]):
        k = int(np.clip(np.searchsorted(t, v["t_s"]), 0, len(t) - 1))
        ctx.scene.add_icosphere(
            f"{ctx.root}/violations/{i}",
            radius=0.03,
            color=FAIL_RGB,
            position=tuple(float(c) for c in rear[k] + [0, 0, 0.5]),
        )
    urdf = ctx.add_urdf("cmbot", "robot")
    frame = ctx.scene.get_handle_by_name(f"{ctx.root}/robot")

    def update(t_play: float) -> None:
        k = int(np.clip(np.searchsorted(t, t[0] + t_play * CLIMB_SPEEDUP), 0, len(t) - 1))
        set_frame_pose(frame, _pose(rear[k]))
        urdf.update_cfg(q[k])

    update(0.0)
    ctx.animate(max(float(t[-1] - t[0]) / CLIMB_SPEEDUP, 1.0), update)


def draw_manipulate(ctx: DrawContext, plan: PlanView) -> None:
    """Guardrail, the robot in its work stance, the arm moving along the plan,
    the tool path (planned and desired) and the covering spheres (toggle)."""
    from planners.cmbot.arm import ArmKinematics
    from robots import load_robot

    res = plan.result
    g = _guardrail(res)
    T_wb = np.array(res["T_world_base"], float)
    x0 = float(res["rear_foot_x_m"])
    _draw_guardrail(ctx, g, x0 - 3.5, x0 + 3.5)
    t = plan.array("times")
    q = plan.array("q")
    tool = plan.array("tool_pos") @ T_wb[:3, :3].T + T_wb[:3, 3]
    desired = plan.array("desired_pos") @ T_wb[:3, :3].T + T_wb[:3, 3]
    add_polyline(ctx.scene, f"{ctx.root}/tool_path", tool, PATH_RGB, width=4.0)
    add_polyline(ctx.scene, f"{ctx.root}/desired_path", desired, ROUTE_RGB, width=1.5)
    prop = res.get("proposal") or {}
    if prop.get("rear_foot_x_m") is not None:
        ctx.scene.add_icosphere(
            f"{ctx.root}/proposed_base",
            radius=0.04,
            color=(40, 120, 255),
            position=(float(prop["rear_foot_x_m"]), 0.0, 0.05),
        )
    for i, v in enumerate(res.get("violations", [])[:20]):
        k = int(np.clip(np.searchsorted(t, v["t_s"]), 0, len(t) - 1))
        ctx.scene.add_icosphere(
            f"{ctx.root}/violations/{i}",
            radius=0.03,
            color=FAIL_RGB,
            position=tuple(float(c) for c in tool[k]),
        )
    model = load_robot("cmbot")
    arm = ArmKinematics.from_model(model)
    q_climb = np.array(res["q_climb"], float)
    urdf = ctx.add_urdf("cmbot", "robot", root_pose=_pose(np.array([x0, 0.0, 0.0])))
    centers = arm.sphere_centers(arm.frames(q)) @ T_wb[:3, :3].T + T_wb[:3, 3]  # (T,S,3)
    spheres = add_spheres(
        ctx.scene,
        f"{ctx.root}/spheres",
        centers[0],
        radius=float(arm.spheres.radius.max()),
        colors=SPHERE_RGB,
    )
    spheres.visible = False
    toggle = ctx.gui.add_checkbox("CMBOT covering spheres", initial_value=False)

    @toggle.on_update
    def _(_event: Any) -> None:
        with ctx.lock:
            spheres.visible = bool(toggle.value)

    ctx.gui_handles.append(toggle)

    def update(t_play: float) -> None:
        k = int(np.clip(np.searchsorted(t, t[0] + t_play * ARM_SPEEDUP), 0, len(t) - 1))
        urdf.update_cfg(np.concatenate([q_climb, q[k]]))
        if spheres.visible:
            spheres.batched_positions = centers[k].astype(np.float32)

    update(0.0)
    ctx.animate(max(float(t[-1] - t[0]) / ARM_SPEEDUP, 1.0), update)
