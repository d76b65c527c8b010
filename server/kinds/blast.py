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
from planners.errors import InvalidInputError, NoPlaneError
from server.kinds.base import Check, JobContext, KindOutput, PlanKind, StrictParams

ROBOT = "denso_vm6083"
FACING_DEG = 30.0  # chosen: a plane point whose local normal is further off is not of the patch


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


def _surface(p: BlastParams, ctx: JobContext) -> tuple[Surface, np.ndarray | None, dict[str, Any]]:
    """The surface, obstacle points from the cloud, and what to show of the cloud."""
    base = np.asarray(p.robot_base_m, dtype=float)
    if p.polygon is not None:
        return p.polygon.build(), None, {}
    if p.cloud_id is None:
        return scenes.bridge_surface(int(p.seed_surface or 1)), None, {}
    from planners.pointcloud.filters import statistical_outliers, voxel_downsample
    from planners.pointcloud.normals import facing_mask
    from planners.pointcloud.ransac import detect_planes

    pts = np.asarray(ctx.load_cloud(p.cloud_id), dtype=float)
    planes = detect_planes(
        pts, threshold_m=p.plane_threshold_m, min_points=100, cluster_radius_m=0.05
    )
    if not planes:
        raise NoPlaneError(f"no plane with ≥ 100 points found in cloud {p.cloud_id}")
    # detect_planes reports in discovery order (one plane's pieces together);
    # the operator picks by index, and index 0 is promised to be the largest
    planes = sorted(planes, key=lambda pl: -pl.n_inliers)
    if p.plane_index >= len(planes):
        raise InvalidInputError(
            f"plane_index {p.plane_index} out of range: the cloud has {len(planes)} planes"
        )
    mask = planes[p.plane_index].inliers.copy()
    # a distance threshold also takes the strip where a perpendicular face
    # (a flange) crosses the plane; only points whose own surface faces
    # the plane's way outline the patch
    # (normals from the whole cloud: the strip's neighbours are on its face)
    if len(pts) >= 12:
        mask &= facing_mask(pts, planes[p.plane_index].normal, FACING_DEG)
    # isolated points left in the plane would pull thin spikes into the outline
    idx = np.nonzero(mask)[0]
    mask[idx[statistical_outliers(pts[idx])]] = False
    surf = Surface.from_points(pts[mask], toward=base)
    label = np.full(len(pts), -1, dtype=np.int32)
    for i, pl in enumerate(planes):
        label[pl.inliers & (label < 0)] = i
    others = pts[~mask] if p.cloud_obstacles else None
    if others is not None and len(others):
        others = voxel_downsample(others, 0.02)
    info = {
        "planes": [
            {
                "index": i,
                "points": pl.n_inliers,
                "normal": pl.normal.tolist(),
                "centroid": pl.centroid.tolist(),
            }
            for i, pl in enumerate(planes)
        ],
        "cloud_points": pts,
        "cloud_label": label,
    }
    return surf, others, info


def _thin(n: int, k: int = 400) -> np.ndarray:
    return np.unique(np.linspace(0, n - 1, min(n, k)).astype(int))


def _finite(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None


def run(p: BlastParams, ctx: JobContext) -> KindOutput:
    from robots import load_robot

    t0 = time.perf_counter()
    ctx.progress(0.02, "surface")
    surface, cloud_obst, cloud_info = _surface(p, ctx)
    base = np.eye(4)
    base[:3, 3] = p.robot_base_m
    robot = load_robot(ROBOT).with_base(base)
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
    q, t, clr = plan.joint_trajectory, plan.times, plan.clearance
    F = robot.frames(q)[:, -1]
    tip = F[:, :3, 3] + 0.1 * F[:, :3, 2]  # nozzle tip (100 mm along the flange z axis)
    k = _thin(len(t))
    plots = [
        {
            "title": "Fig. 4.22 style: ellipsoid clearance to the obstacles",
            "x": t[k].tolist(),
            "x_label": "s",
            "y_label": "mm",
            "series": {"clearance_mm": [_finite(v * 1000.0) for v in clr[k]]},
        },
        {
            "title": "Fig. 4.16 style: joint angles (speed-limited)",
            "x": t[k].tolist(),
            "x_label": "s",
            "y_label": "deg",
            "series": {f"J{j + 1}": np.degrees(q[k, j]).round(3).tolist() for j in range(6)},
        },
    ]
    outline = surface.to_world(np.asarray(surface.polygon.exterior.coords) if surface.polygon.geom_type == "Polygon"
                               else np.asarray(surface.polygon.convex_hull.exterior.coords))  # fmt: skip
    holes = (
        [surface.to_world(np.asarray(h.coords)).tolist() for h in surface.polygon.interiors]
        if surface.polygon.geom_type == "Polygon"
        else []
    )
    result: dict[str, Any] = {
        "surface": {
            "origin": surface.origin.tolist(),
            "normal": surface.normal.tolist(),
            "x_axis": surface.x_axis.tolist(),
            "y_axis": surface.y_axis.tolist(),
            "outline_world": outline.tolist(),
            "holes_world": holes,
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
    if cloud_info:
        result["planes"] = cloud_info["planes"]
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
        "segment": plan.segment.astype(np.int8),
        "waypoint_spot": plan.waypoint_spot.astype(np.int32),
        "nozzle_tip": tip,
        "nozzle_axis": F[:, :3, 2],
    }
    if cloud_obst is not None and len(cloud_obst):
        arrays["obstacle_points"] = cloud_obst
    if cloud_info:
        sel = _thin(len(cloud_info["cloud_points"]), 60_000)
        arrays["cloud_points"] = cloud_info["cloud_points"][sel]
        arrays["cloud_label"] = cloud_info["cloud_label"][sel]
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
        "max_ik_residual_mm": float(np.max(plan.ik_residual_mm))
        if len(plan.ik_residual_mm)
        else 0.0,
        "planning_time_s": time.perf_counter() - t0,
        **{f"stage_{k2}": float(v) for k2, v in plan.timings_s.items() if k2 != "total_s"},
    }
    if math.isfinite(plan.min_clearance_m):
        metrics["min_clearance_mm"] = plan.min_clearance_m * 1000.0
    return KindOutput(result=result, arrays=arrays, checks=checks, metrics=metrics)


def compile_program(plan: Any) -> list[dict[str, Any]]:
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


def sample_under_deck(seed: int) -> np.ndarray:
    """The seed's Fig. 4.4 environment as a cloud (2 mm noise): the three
    rusted patches (Surfaces 1–3) densely, and the I-beam channel around them
    sparsely — pick a plane with ``plane_index``."""
    rng = np.random.default_rng(seed)
    parts = []
    import shapely

    for k in (1, 2, 3):
        s = scenes.bridge_surface(k)
        minx, miny, maxx, maxy = s.polygon.bounds
        uv = rng.uniform([minx, miny], [maxx, maxy], size=(int(s.area / 2.5e-5) * 2, 2))
        uv = uv[shapely.contains_xy(s.polygon, uv[:, 0], uv[:, 1])]
        parts.append(s.to_world(uv))
    # sparse context: the flanges of both girders and the far girder's web
    # (the deck and the near web carry the patches and are left out so the
    # patches come out as planes of their own)
    for b in scenes.bridge_obstacles()[1:]:
        if "x=0 web" in b.name:
            continue
        n = int(np.prod(np.sort(b.half)[1:]) * 4 / 4e-4)
        loc = rng.uniform(-1, 1, size=(n, 3))
        ax = rng.integers(0, 3, n)
        loc[np.arange(n), ax] = np.sign(loc[np.arange(n), ax])  # on a face
        parts.append(b.center + loc * b.half)
    pts = np.concatenate(parts)
    return pts + rng.normal(scale=0.002, size=pts.shape)


KIND = PlanKind(
    name="blast",
    title="Sand-blasting a rusted surface (DENSO VM-6083)",
    description=__doc__ or "",
    params_model=BlastParams,
    run=run,
    validate=validate,
    samples={"blast_under_deck": sample_under_deck},
    robot=ROBOT,
    compile=compile_program,
)
