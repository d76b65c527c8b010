"""``blast``: sand-blasting of a planar rusted surface by the DENSO VM-6083
(seed 004, Chapters 3–4; see docs/blasting.md).

The surface is one of the seed's scene surfaces (``seed_surface`` 1–3), a
polygon on a plane (``polygon``), or a plane picked from a stored cloud
(``cloud_id`` + ``plane_index``: sequential RANSAC planes, largest first; the
cloud's other points become obstacle points).  The defaults plan the seed's
Surface 1 on the roof of the I-beam channel with 0.04 m discs (§4.2.1,
§4.2.5).  The planner is :func:`planners.blasting.plan_blasting`.
"""

from __future__ import annotations

import math
import time
from typing import Any, Literal

import numpy as np
from pydantic import Field, field_validator

from planners.blasting import Box, Surface, plan_blasting, scenes
from planners.blasting.nozzle import check_stream_length
from planners.blasting.sample_clouds import under_deck_cloud
from planners.blasting.surface_pick import PickedSurface, nozzle_tip, outline_world, pick_surface
from planners.errors import InvalidInputError, NoPlaneError
from planners.summary import plot, thin
from server.kinds.base import Check, JobContext, KindOutput, PlanKind, PlanView, StrictParams

ROBOT = "denso_vm6083"


class PolygonSurface(StrictParams):
    """A planar surface: outline in the plane frame (DESIGN §5)."""

    origin_m: list[float] = Field(
        ..., min_length=3, max_length=3, description="plane origin [x, y, z] (m)"
    )
    normal: list[float] = Field(
        ..., min_length=3, max_length=3, description="plane normal (any length)"
    )
    boundary_m: list[list[float]] = Field(
        ..., min_length=3, description="outline [[u, v], ...] in the plane frame (m)"
    )
    holes_m: list[list[list[float]]] = Field(
        default_factory=list, description="holes, same frame (m)"
    )
    x_axis: list[float] | None = Field(
        None, min_length=3, max_length=3, description="plane x axis (None: world x projected)"
    )

    def build(self) -> Surface:
        return Surface(
            np.asarray(self.origin_m), np.asarray(self.normal), np.asarray(self.boundary_m),
            x_axis=None if self.x_axis is None else np.asarray(self.x_axis),
            holes=[np.asarray(h) for h in self.holes_m],
        )  # fmt: skip


class BoxObstacle(StrictParams):
    """An axis-aligned box obstacle (world frame, m)."""

    lo_m: list[float] = Field(
        ..., min_length=3, max_length=3, description="min corner [x, y, z] (m)"
    )
    hi_m: list[float] = Field(
        ..., min_length=3, max_length=3, description="max corner [x, y, z] (m)"
    )
    name: str = Field("", description="label shown in the scene")


def _channel() -> list[BoxObstacle]:
    return [
        BoxObstacle(lo_m=list(b.center - b.half), hi_m=list(b.center + b.half), name=b.name)
        for b in scenes.bridge_obstacles()
    ]


class BlastParams(StrictParams):
    """Surface, nozzle, sequencer, obstacles and robot base of one blasting plan."""

    seed_surface: int | None = Field(
        1, ge=1, le=3, description="the seed's scene surface 1–3 (used without polygon / cloud_id)"
    )
    polygon: PolygonSurface | None = Field(None, description="surface as a polygon on a plane")
    cloud_id: str | None = Field(None, description="id of a stored cloud (world frame, m)")
    plane_index: int = Field(0, ge=0, description="plane of the cloud to blast (0 = largest)")
    plane_threshold_m: float = Field(0.01, gt=0, description="RANSAC inlier distance (m)")
    nozzle: Literal["small", "medium", "large"] = Field(
        "medium", description="Boride T159 size (Table 3.1)"
    )
    stream_length_mm: float = Field(
        300.0, description="nozzle-to-surface stream length, 100–500 mm"
    )
    disc_radius_m: float | None = Field(
        scenes.DISC_RADIUS_M,
        gt=0,
        description="disc radius (m); None: Eq. 3.1 (seed §4.2.1 uses 0.04)",
    )
    fill_stream_mm: float | None = Field(
        100.0, description="stream length of the small fill discs (mm); None: no small discs"
    )
    editing: Literal["improved", "seed"] = Field(
        "improved", description="boundary editing: ours or §3.2.3"
    )
    sequencer: Literal["default", "ga"] = Field(
        "default", description="ours or the seed's GA (§3.3.2)"
    )
    obstacles: list[BoxObstacle] | None = Field(
        None, description="box obstacles; None: the seed's I-beam channel and deck (Fig. 4.4)"
    )
    cloud_obstacles: bool = Field(
        True, description="with cloud_id: the cloud's other points are obstacles"
    )
    robot_base_m: list[float] = Field(
        [v / 1000.0 for v in scenes.ROBOT_BASE_MM], min_length=3, max_length=3,
        description="robot base position [x, y, z] (m), seed (500, 375, 370) mm",
    )  # fmt: skip
    seed: int = Field(0, ge=0, description="random seed (GA)")
    coverage_min_pct: float = Field(99.0, ge=0, le=100, description="check: coverage (%)")
    overspray_max_pct: float = Field(0.5, ge=0, description="check: overspray (% of the surface)")
    ik_residual_max_mm: float = Field(0.1, gt=0, description="check: IK position residual (mm)")

    @field_validator("stream_length_mm", "fill_stream_mm")
    @classmethod
    def _window(cls, v: float | None) -> float | None:
        return v if v is None else check_stream_length(v)


def validate(p: BlastParams) -> None:
    """Cheap checks at submission (HTTP 422)."""
    if p.polygon is not None:
        p.polygon.build()
    elif p.cloud_id is None and p.seed_surface is None:
        raise InvalidInputError("give seed_surface (1–3), a polygon or a cloud_id")
    for b in p.obstacles or []:
        Box.from_bounds(b.lo_m, b.hi_m)


def _surface(
    p: BlastParams, ctx: JobContext
) -> tuple[Surface, PickedSurface | None, np.ndarray | None]:
    """The surface to blast and, for a cloud, what was picked from it and the cloud."""
    if p.polygon is not None:
        return p.polygon.build(), None, None
    if p.cloud_id is None:
        return scenes.bridge_surface(int(p.seed_surface or 1)), None, None
    cloud = np.asarray(ctx.load_cloud(p.cloud_id), dtype=float)
    try:
        picked = pick_surface(
            cloud,
            plane_index=p.plane_index,
            threshold_m=p.plane_threshold_m,
            toward=np.asarray(p.robot_base_m, dtype=float),
            obstacles_from_rest=p.cloud_obstacles,
        )
    except NoPlaneError as exc:
        raise NoPlaneError(f"{exc} (cloud {p.cloud_id})") from exc
    return picked.surface, picked, cloud


def run(p: BlastParams, ctx: JobContext) -> KindOutput:
    from robots import load_robot

    t0 = time.perf_counter()
    ctx.progress(0.02, "surface")
    surface, picked, cloud = _surface(p, ctx)
    cloud_obst = None if picked is None else picked.obstacle_points
    base = np.eye(4)
    base[:3, 3] = p.robot_base_m
    from robots.denso_vm6083 import DensoVM6083

    arm = load_robot(ROBOT)
    # ROBOT names the DENSO arm; its loader returns DensoVM6083 (with_base is its own)
    assert isinstance(arm, DensoVM6083)
    robot = arm.with_base(base)
    boxes = [
        Box.from_bounds(b.lo_m, b.hi_m, b.name)
        for b in (_channel() if p.obstacles is None else p.obstacles)
    ]
    obstacles: list[Any] = list(boxes)
    if cloud_obst is not None and len(cloud_obst):
        obstacles.append(cloud_obst)

    def prog(f: float, stage: str) -> None:
        ctx.progress(0.05 + 0.9 * f, stage)

    plan = plan_blasting(
        surface, nozzle=p.nozzle, stream_length_mm=p.stream_length_mm, sequencer=p.sequencer,
        robot=robot, obstacles=obstacles, seed=p.seed, disc_radius_m=p.disc_radius_m,
        editing=p.editing, fill_stream_mm=p.fill_stream_mm, progress=prog,
    )  # fmt: skip
    ctx.progress(0.97, "storing")
    motion = plan.robot_motion()
    # plan_blasting was given a robot, so it attached the trajectory
    assert motion is not None
    q, t, clr = motion.joint_trajectory, motion.times, motion.clearance
    tip, axis = nozzle_tip(robot.frames(q)[:, -1])
    k = thin(len(t))
    plots = [
        plot(
            "Fig. 4.22 style: ellipsoid clearance to the obstacles",
            t[k], {"clearance_mm": clr[k] * 1000.0}, x_label="s", y_label="mm",
        ),
        plot(
            "Fig. 4.16 style: joint angles (speed-limited)",
            t[k], {f"J{j + 1}": np.degrees(q[k, j]).round(3) for j in range(6)},
            x_label="s", y_label="deg",
        ),
    ]  # fmt: skip
    outline, holes = outline_world(surface)
    # Surface.__post_init__ always resolves x_axis (None only as an argument)
    assert surface.x_axis is not None
    result: dict[str, Any] = {
        "surface": {
            "origin": surface.origin.tolist(),
            "normal": surface.normal.tolist(),
            "x_axis": surface.x_axis.tolist(),
            "y_axis": surface.y_axis.tolist(),
            "outline_world": outline.tolist(),
            "holes_world": [h.tolist() for h in holes],
            "area_m2": surface.area,
        },
        "robot_base": base.tolist(),
        "boxes": [
            {"name": b.name, "center": b.center.tolist(), "half": b.half.tolist()} for b in boxes
        ],
        "disc_radius_m": plan.radius,
        "params_used": {k2: v for k2, v in plan.params.items() if k2 != "tilt_direction_2d"},
        "skipped": plan.skipped.tolist(),
        "timings_s": plan.timings_s,
        "plots": plots,
    }
    if picked is not None:
        result["planes"] = [
            {
                "index": pl.index,
                "points": pl.points,
                "normal": pl.normal.tolist(),
                "centroid": pl.centroid.tolist(),
            }
            for pl in picked.planes
        ]
        result["plane_index"] = p.plane_index
    checks = [
        Check(**c)
        for c in plan.checks(
            coverage_min=p.coverage_min_pct / 100.0,
            overspray_max=p.overspray_max_pct / 100.0,
            residual_max_mm=p.ik_residual_max_mm,
        )
    ]
    arrays: dict[str, np.ndarray] = {
        "disc_centers": plan.centers,
        "disc_radii": plan.radii,
        "disc_classes": plan.classes.astype(np.int8),
        "disc_stream_mm": plan.stream_mm,
        "disc_tilt_deg": plan.tilt_deg,
        "order": plan.order.astype(np.int32),
        "q": q,
        "times": t,
        "clearance": clr,
        "segment": motion.segment.astype(np.int8),
        "waypoint_spot": motion.waypoint_spot.astype(np.int32),
        "nozzle_tip": tip,
        "nozzle_axis": axis,
    }
    if cloud_obst is not None and len(cloud_obst):
        arrays["obstacle_points"] = cloud_obst
    if picked is not None and cloud is not None:
        sel = thin(len(cloud), 60_000)
        arrays["cloud_points"] = cloud[sel]
        arrays["cloud_label"] = picked.cloud_label[sel]
    metrics = {
        "discs": float(len(plan.centers)),
        "distance_m": plan.distance_m,
        "turns": float(plan.turns),
        "objective_eq34": plan.objective,
        "distance_per_lower_bound": plan.ratio_to_lower_bound,
        "distance_per_mst": plan.distance_m / plan.mst_m if plan.mst_m > 0 else 1.0,
        "coverage_pct": plan.coverage * 100.0,
        "overspray_pct": plan.overspray * 100.0,
        "disc_radius_mm": plan.radius * 1000.0,
        "tilt_deg": float(plan.params["tilt_deg"]),
        "skipped_discs": float(len(plan.skipped)),
        "waypoints": float(len(t)),
        "trajectory_duration_s": float(t[-1]),
        "max_joint_speed_deg_s": math.degrees(plan.max_joint_speed_rad_s),
        "max_ik_residual_mm": float(np.max(motion.ik_residual_mm))
        if len(motion.ik_residual_mm)
        else 0.0,
        "planning_time_s": time.perf_counter() - t0,
        **{f"stage_{k2}": float(v) for k2, v in plan.timings_s.items() if k2 != "total_s"},
    }
    if math.isfinite(plan.min_clearance_m):
        metrics["min_clearance_mm"] = plan.min_clearance_m * 1000.0
    return KindOutput(result=result, arrays=arrays, checks=checks, metrics=metrics)


def compile_program(plan: PlanView) -> list[dict[str, Any]]:
    """Timed joint way-points for the arm with the nozzle opened at the
    first spot, closed during reconfigurations and at the end."""
    from robots.protocol.commands import JointMove, Nozzle, Stop

    q = plan.array("q")
    t = plan.array("times")
    seg = plan.array("segment")
    spot = plan.array("waypoint_spot")
    cmds: list[Any] = []
    on = False
    for k in range(len(q)):
        if on and seg[k] == 3:
            cmds.append(Nozzle(False))
            on = False
        cmds.append(
            JointMove(tuple(float(v) for v in q[k]), 0.0 if k == 0 else float(t[k] - t[k - 1]))
        )
        if not on and spot[k] >= 0:
            cmds.append(Nozzle(True))
            on = True
    if on:
        cmds.append(Nozzle(False))
    cmds.append(Stop())
    return [c.to_dict() for c in cmds]


KIND = PlanKind(
    name="blast",
    title="Sand-blasting a rusted surface (DENSO VM-6083)",
    description=__doc__ or "",
    params_model=BlastParams,
    run=run,
    validate=validate,
    samples={"blast_under_deck": under_deck_cloud},
    robot=ROBOT,
    compile=compile_program,
)
