"""One entry point for the ``blast`` kind: the surface (given,
or picked from a scanned cloud by :func:`planners.blasting.surface_pick.pick_surface`),
the robot placed at its base, :func:`planners.blasting.plan_blasting` (seed 004,
Fig. 3.1: Eq. 3.1 discs → §3.2 editing → Eq. 3.3–3.4 sequencing → §3.4 IK,
Eq. 3.12–3.13 speed limits, §3.4.2 ellipsoid clearance) and the plan in the
stored form: a :class:`planners.result.PlanResult` with the surface, boxes and
planes in the summary, the discs and the trajectory in the arrays (the names
``server/scene/blast.py`` and the kind's ``compile`` read), the plan checks
and the metrics.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from planners.blasting.base_placement import BaseLimits, place_base
from planners.blasting.collision import Box
from planners.blasting.constants import NOZZLE_LENGTH_M
from planners.blasting.pipeline import plan_blasting
from planners.blasting.result import BlastPlan, RobotMotion
from planners.blasting.scenes import DISC_RADIUS_M
from planners.blasting.surface import Surface
from planners.blasting.surface_pick import PickedSurface, nozzle_tip, outline_world, pick_surface
from planners.errors import InvalidInputError
from planners.result import Check, PlanResult
from planners.summary import json_safe, plot, thin

if TYPE_CHECKING:
    from robots.denso_vm6083 import DensoVM6083

__all__ = ["BlastLimits", "BlastOptions", "PlanePick", "plan_blast_result"]

#: at most this many cloud points go into the stored arrays (the scene's view)
CLOUD_POINTS_STORED = 60_000


@dataclass(frozen=True)
class PlanePick:
    """Blast a plane of a scanned cloud: ``points`` (N,3) world frame, metres;
    ``plane_index`` 0 = the largest RANSAC plane; with ``obstacles_from_rest``
    the cloud's other points are obstacle points."""

    points: np.ndarray
    plane_index: int = 0
    threshold_m: float = 0.01
    obstacles_from_rest: bool = True


@dataclass(frozen=True)
class BlastOptions:
    """The choices :func:`planners.blasting.plan_blasting` takes (see there)."""

    nozzle: str = "medium"
    stream_length_mm: float = 300.0
    disc_radius_m: float | None = DISC_RADIUS_M
    fill_stream_mm: float | None = 100.0
    editing: str = "improved"
    sequencer: str = "default"
    seed: int = 0


@dataclass(frozen=True)
class BlastLimits:
    """Check limits: coverage and overspray as fractions of the surface, the
    IK position residual in millimetres."""

    coverage_min: float = 0.99
    overspray_max: float = 0.005
    ik_residual_max_mm: float = 0.1


def plan_blast_result(
    surface: Surface | PlanePick,
    arm: DensoVM6083,
    *,
    robot_base_m: Sequence[float],
    boxes: Sequence[Box] = (),
    options: BlastOptions | None = None,
    limits: BlastLimits | None = None,
    obstacle_points: np.ndarray | None = None,
    base_search: BaseLimits | None = None,
    progress: Callable[[float, str], None] | None = None,
) -> PlanResult:
    """Plan blasting of ``surface`` (or of the plane ``surface`` picks from a
    cloud) by ``arm`` (the VM-6083 model; placed here at ``robot_base_m``,
    world metres) among ``boxes`` (and, for a picked plane, the cloud's other
    points, and ``obstacle_points`` (N,3): a scan's points off the surface's
    plane), and return the plan in the stored form.  With ``base_search``
    the base is searched in that region instead
    (:func:`planners.blasting.base_placement.place_base`; ``robot_base_m``
    then only picks the side of a picked plane) and the summary's
    ``base_placement`` says what the search measured.

    ``progress`` gets 0–1 and a stage name.  Raises ``planners.errors`` types:
    :class:`~planners.errors.NoPlaneError` for a cloud without a plane,
    :class:`~planners.errors.InvalidInputError` for a bad base, plane index or
    surface, and whatever :func:`plan_blasting` raises.
    """
    t0 = time.perf_counter()
    opt = options or BlastOptions()
    lim = limits or BlastLimits()
    report = progress or (lambda f, s: None)
    base_xyz = np.asarray(robot_base_m, dtype=float)
    if base_xyz.shape != (3,) or not np.all(np.isfinite(base_xyz)):
        raise InvalidInputError(f"robot_base_m must be 3 finite numbers, got {robot_base_m!r}")
    report(0.02, "surface")
    picked: PickedSurface | None = None
    cloud: np.ndarray | None = None
    if isinstance(surface, PlanePick):
        cloud = np.asarray(surface.points, dtype=float)
        picked = pick_surface(
            cloud,
            plane_index=surface.plane_index,
            threshold_m=surface.threshold_m,
            toward=base_xyz,
            obstacles_from_rest=surface.obstacles_from_rest,
        )
        surf = picked.surface
    else:
        surf = surface
    cloud_obst = None if picked is None else picked.obstacle_points
    if obstacle_points is not None:
        extra = _off_plane(surf, obstacle_points)
        cloud_obst = extra if cloud_obst is None else np.vstack([cloud_obst, extra])
    placement = None
    if base_search is not None:
        report(0.03, "placing the base")
        placement = place_base(
            surf, arm, standoff_m=opt.stream_length_mm / 1000.0 + NOZZLE_LENGTH_M,
            limits=base_search, obstacle_points=cloud_obst, boxes=boxes,
        )  # fmt: skip
        base_xyz = placement.base_m
    base = np.eye(4)
    base[:3, 3] = base_xyz
    robot = arm.with_base(base)
    obstacles: list[Any] = list(boxes)
    if cloud_obst is not None and len(cloud_obst):
        obstacles.append(cloud_obst)
    plan = plan_blasting(
        surf, nozzle=opt.nozzle, stream_length_mm=opt.stream_length_mm,
        sequencer=opt.sequencer, robot=robot, obstacles=obstacles, seed=opt.seed,
        disc_radius_m=opt.disc_radius_m, editing=opt.editing,
        fill_stream_mm=opt.fill_stream_mm,
        progress=lambda f, stage: report(0.05 + 0.9 * f, stage),
    )  # fmt: skip
    report(0.97, "storing")
    motion = plan.robot_motion()
    # plan_blasting was given a robot, so it attached the trajectory
    assert motion is not None
    tip, axis = nozzle_tip(robot.frames(motion.joint_trajectory)[:, -1])
    plane_index = surface.plane_index if isinstance(surface, PlanePick) else None
    summary = _summary(surf, base, boxes, plan, motion, picked, plane_index)
    if placement is not None:
        summary["base_placement"] = placement.summary()
    arrays = _arrays(plan, motion, tip, axis, picked, cloud, cloud_obst)
    checks = [
        _finite_check(c)
        for c in plan.checks(
            coverage_min=lim.coverage_min,
            overspray_max=lim.overspray_max,
            residual_max_mm=lim.ik_residual_max_mm,
        )
    ]
    metrics = _metrics(plan, motion, t0)
    dropped = sorted(k for k, v in metrics.items() if not math.isfinite(v))
    if dropped:
        # strict JSON has no NaN/inf: a non-finite metric is left out and named here
        summary["metrics_not_finite"] = dropped
        metrics = {k: v for k, v in metrics.items() if k not in dropped}
    return PlanResult(summary=json_safe(summary), arrays=arrays, checks=checks, metrics=metrics)


#: scan points within this of the surface's plane are the surface, not obstacles (m)
ON_PLANE_M = 0.02
#: scan points farther than this from the surface's bounding box cannot touch
#: the arm standing at the surface (the VM-6083 reaches < 1.5 m; m)
NEAR_M = 2.5


def _off_plane(surf: Surface, points: np.ndarray) -> np.ndarray:
    """The scan's points near the surface and more than :data:`ON_PLANE_M`
    off its plane (the rest are the surface itself or out of the arm's way)."""
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 3 or not np.all(np.isfinite(pts)):
        raise InvalidInputError(f"obstacle points must be finite (N, 3), got shape {pts.shape}")
    outline, _ = outline_world(surf)
    lo, hi = outline.min(axis=0) - NEAR_M, outline.max(axis=0) + NEAR_M
    near = np.all((pts >= lo) & (pts <= hi), axis=1)
    off = np.abs((pts - surf.origin) @ surf.normal) > ON_PLANE_M
    return pts[near & off]


def _finite_check(c: dict[str, Any]) -> Check:
    """A plan check in the stored form, strict-JSON safe: a non-finite value
    or limit is stored as ``None`` with the message saying what it was; a
    NaN value always fails (it measured nothing), an infinite one keeps its
    verdict (e.g. no obstacles: clearance ``inf`` passes)."""
    out = dict(c)
    notes = []
    for key in ("value", "limit"):
        v = out.get(key)
        if isinstance(v, float) and not math.isfinite(v):
            notes.append(f"{key} {v}")
            if math.isnan(v):
                out["passed"] = False
            out[key] = None
    if notes:
        out["message"] = f"{out.get('message', '')} ({', '.join(notes)}: not finite)"
    return Check(**out)


def _summary(
    surf: Surface,
    base: np.ndarray,
    boxes: Sequence[Box],
    plan: BlastPlan,
    motion: RobotMotion,
    picked: PickedSurface | None,
    plane_index: int | None,
) -> dict[str, Any]:
    q, t, clr = motion.joint_trajectory, motion.times, motion.clearance
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
    outline, holes = outline_world(surf)
    # Surface.__post_init__ always resolves x_axis (None only as an argument)
    assert surf.x_axis is not None
    out: dict[str, Any] = {
        "surface": {
            "origin": surf.origin.tolist(),
            "normal": surf.normal.tolist(),
            "x_axis": surf.x_axis.tolist(),
            "y_axis": surf.y_axis.tolist(),
            "outline_world": outline.tolist(),
            "holes_world": [h.tolist() for h in holes],
            "area_m2": surf.area,
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
        out["planes"] = [
            {
                "index": pl.index,
                "points": pl.points,
                "normal": pl.normal.tolist(),
                "centroid": pl.centroid.tolist(),
            }
            for pl in picked.planes
        ]
        out["plane_index"] = plane_index
    return out


def _arrays(
    plan: BlastPlan,
    motion: RobotMotion,
    tip: np.ndarray,
    axis: np.ndarray,
    picked: PickedSurface | None,
    cloud: np.ndarray | None,
    obstacles: np.ndarray | None,
) -> dict[str, np.ndarray]:
    arrays: dict[str, np.ndarray] = {
        "disc_centers": plan.centers,
        "disc_radii": plan.radii,
        "disc_classes": plan.classes.astype(np.int8),
        "disc_stream_mm": plan.stream_mm,
        "disc_tilt_deg": plan.tilt_deg,
        "order": plan.order.astype(np.int32),
        "q": motion.joint_trajectory,
        "times": motion.times,
        "clearance": motion.clearance,
        "segment": motion.segment.astype(np.int8),
        "waypoint_spot": motion.waypoint_spot.astype(np.int32),
        "nozzle_tip": tip,
        "nozzle_axis": axis,
    }
    if obstacles is not None and len(obstacles):
        arrays["obstacle_points"] = obstacles[thin(len(obstacles), CLOUD_POINTS_STORED)]
    if picked is not None and cloud is not None:
        sel = thin(len(cloud), CLOUD_POINTS_STORED)
        arrays["cloud_points"] = cloud[sel]
        arrays["cloud_label"] = picked.cloud_label[sel]
    return arrays


def _metrics(plan: BlastPlan, motion: RobotMotion, t0: float) -> dict[str, float]:
    """The flat metrics; ``planning_time_s`` is measured from ``t0`` (the
    entry point's start) to now."""
    t = motion.times
    res = motion.ik_residual_mm
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
        "max_ik_residual_mm": float(np.max(res)) if len(res) else 0.0,
        "planning_time_s": time.perf_counter() - t0,
        **{f"stage_{k}": float(v) for k, v in plan.timings_s.items() if k != "total_s"},
    }
    if math.isfinite(plan.min_clearance_m):
        metrics["min_clearance_mm"] = plan.min_clearance_m * 1000.0
    return metrics
