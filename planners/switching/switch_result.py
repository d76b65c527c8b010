"""The ``ara.switch`` kind's entry point in the one result contract:
:func:`plan_switch_result` runs :func:`planners.switching.switch_plan.plan_switch`
(the switching decision, seed 000 Eq. 3.1–3.4 and Alg. 1–2, and for
"inchworm" the jump of §3.2) and shapes its outcome into the stored
:class:`planners.result.PlanResult`: the summary the scene drawer and the
compiler read, the arrays, the checks and the metrics.

The jump's checks (joint limits, joint speeds, foothold inside the surface)
are the ones :mod:`planners.switching.jump_checks` recomputed from the
returned trajectory, not the planner's own bookkeeping.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from planners.result import Check, PlanResult, check_ge, check_le
from planners.summary import json_safe
from planners.switching.decide import SwitchingDecision, SwitchingParams
from planners.switching.jump import JumpParams, JumpPlan
from planners.switching.switch_plan import SwitchOutcome, plan_switch


def plan_switch_result(
    robot: Any,
    points: np.ndarray,
    *,
    camera_to_base: np.ndarray,
    base_height: float,
    foot: tuple[float, float],
    params: SwitchingParams,
    jump: JumpParams | None,
    inside_tol_m: float = 0.01,
    progress: Callable[[float, str], None] | None = None,
) -> PlanResult:
    """Decide the mode (and plan the jump when ``jump`` is given and the mode is
    "inchworm") for ``points`` (N,3, camera frame) and return the stored form.

    ``robot`` is the ARA model (``joint_names``, ``joint_limits``,
    ``max_speed`` and what the jump planner needs); ``camera_to_base`` the
    4×4 camera→base transform; ``foot`` (length_m, width_m).  The metric
    ``planning_time_s`` is the wall time of this call.  A jump that cannot
    be planned is a failed ``jump_planned`` check, not an exception; bad
    input raises :mod:`planners.errors` types (from ``decide_mode``).
    """
    t0 = time.perf_counter()
    out = plan_switch(
        robot,
        points,
        camera_to_base=camera_to_base,
        base_height=base_height,
        foot=foot,
        params=params,
        jump=jump,
        inside_tol_m=inside_tol_m,
        progress=progress,
    )
    d = out.decision
    summary: dict[str, Any] = {
        "decision": d.summary(),
        "camera_to_base": _mat(camera_to_base),
        "foot_m": list(foot),
        "planes": _planes(d),
        "foothold": _mat(d.foothold),
        "jump": None,
    }
    arrays = _decision_arrays(d)
    checks = [
        Check(
            name="safe_surface",
            passed=d.mode != "none",
            value=d.mode,
            limit="mobile|inchworm",
            message=d.message,
        )
    ]
    metrics = _decision_metrics(d)
    if out.jump_error is not None:
        checks.append(
            Check(
                name="jump_planned", passed=False, value=False, limit=True, message=out.jump_error
            )
        )
    if out.jump is not None:
        assert jump is not None  # plan_switch plans a jump only when asked to
        checks += _jump_checks(out, out.jump, jump.clearance_margin_m)
        metrics.update(_jump_metrics(out.jump, robot))
        summary["jump"] = _jump_summary(out.jump, robot)
        arrays.update(_jump_arrays(out.jump))
    metrics["planning_time_s"] = time.perf_counter() - t0
    return PlanResult(summary=json_safe(summary), arrays=arrays, checks=checks, metrics=metrics)


def _mat(T: np.ndarray | None) -> list[list[float]] | None:
    return None if T is None else np.round(np.asarray(T, float), 6).tolist()


def _planes(d: SwitchingDecision) -> list[dict[str, Any]]:
    """Each candidate plane with its availability verdicts and its Alg. 2 rectangles."""
    return [
        {
            "index": c.index,
            "n_points": c.n_points,
            "normal": np.round(c.normal, 5).tolist(),
            "centroid_base": np.round(c.centroid, 5).tolist(),
            "centroid_camera": np.round(c.centroid_camera, 5).tolist(),
            "area_m2": c.area_m2,
            "rms_m": c.rms_m,
            "plane_available": True,
            "area_available": c.area_available,
            "height_available": c.height_available,
            "height_error_m": c.height_error_m,
            "normal_angle_deg": c.normal_angle_deg,
            "reachable": c.reachable,
            "reach_distance_m": c.reach_distance_m,
            "rectangles": [
                {
                    "index": r.index,
                    "passed": r.passed,
                    "exact_passed": r.exact_passed,
                    "exact_margin_m": r.exact_margin_m if np.isfinite(r.exact_margin_m) else None,
                    "reason": r.reason,
                    "corners": np.round(r.corners, 5).tolist(),
                }
                for r in c.rectangles
            ],
        }
        for c in d.candidates
    ]


def _decision_arrays(d: SwitchingDecision) -> dict[str, np.ndarray]:
    """The processed cloud with its plane labels, the plane boundaries and the
    Alg. 2 rectangles, under the names the scene drawer reads."""
    labels = np.full(len(d.points), -1, dtype=np.int32)
    for c in d.candidates:
        labels[c.points_index] = c.index
    rects = [r for c in d.candidates for r in c.rectangles]
    rect_plane = [c.index for c in d.candidates for _ in c.rectangles]
    boundaries = [c.frame.to_world(c.area.boundary2d) for c in d.candidates]
    return {
        "points": d.points.astype(np.float32),
        "plane_labels": labels,
        "boundary": (np.vstack(boundaries) if boundaries else np.zeros((0, 3))).astype(np.float32),
        "boundary_plane": np.concatenate(
            [np.full(len(b), k) for k, b in enumerate(boundaries)] or [np.zeros(0)]
        ).astype(np.int32),
        "rect_corners": (np.array([r.corners for r in rects]) if rects else np.zeros((0, 4, 3))),
        "rect_passed": np.array([r.passed for r in rects], dtype=bool),
        "rect_plane": np.array(rect_plane, dtype=np.int32),
    }


def _decision_metrics(d: SwitchingDecision) -> dict[str, float]:
    metrics = {
        "planes_found": float(len(d.candidates)),
        "rectangles_passed": float(d.rectangles_passed),
        "rectangles_total": float(d.rectangles_total),
        "points_input": float(d.n_points_in),
        "points_processed": float(len(d.points)),
        "decision_time_s": float(d.timings_s.get("total", 0.0)),
    }
    if d.height_error_m is not None:
        # decide sets height_m and height_error_m together (both None without a plane)
        assert d.height_m is not None
        metrics["height_error_m"] = float(d.height_error_m)
        metrics["plane_height_m"] = float(d.height_m)
    if d.alg2_exact_agreement is not None:
        metrics["alg2_exact_agreement"] = float(d.alg2_exact_agreement)
    return metrics


def _jump_checks(out: SwitchOutcome, plan: JumpPlan, clearance_margin_m: float) -> list[Check]:
    """The planned jump's checks, recomputed from its trajectory by
    :func:`plan_switch` (:mod:`planners.switching.jump_checks`)."""
    inside = out.foot1_inside
    return [
        Check(
            name="jump_planned", passed=True, value=True, limit=True, message="all phases planned"
        ),
        check_le(
            "joint_limits", out.joint_limit_excess_rad, 0.0, "largest joint-limit excess", " rad"
        ),
        check_le("joint_speeds", out.speed_ratio, 1.0, "largest joint speed / limit", ""),
        check_ge(
            "clearance",
            float(plan.clearance.min()),
            clearance_margin_m,
            "smallest clearance along the jump",
            " m",
        ),
        check_ge(
            "self_clearance",
            float(plan.self_clearance.min()),
            0.0,
            "smallest self clearance",
            " m",
        ),
        Check(
            name="foothold_inside_surface",
            passed=inside,
            value=inside,
            limit=True,
            message="foot 1's footprint lies inside the target plane's concave hull"
            if inside
            else "foot 1's footprint leaves the target plane's concave hull",
        ),
    ]


def _jump_metrics(plan: JumpPlan, robot: Any) -> dict[str, float]:
    m = plan.metrics(robot)
    return {
        "jump_duration_s": m["duration_s"],
        "jump_min_clearance_m": m["min_clearance_m"],
        "jump_min_self_clearance_m": m["min_self_clearance_m"],
        "jump_max_speed_ratio": m["max_speed_ratio"],
        "jump_planning_time_s": m["planning_time_s"],
        "jump_rrt_attempts": m["attempts_used"],
        "foot2_on_seen_surface": float(plan.foot2_target_inside),
    }


def _jump_summary(plan: JumpPlan, robot: Any) -> dict[str, Any]:
    """The feet's targets, the phases (§3.2) with their magnet states and
    times, and the magnet commands the compiler turns into the program."""
    return {
        "foot1_target": _mat(plan.foot1_target),
        "foot2_target": _mat(plan.foot2_target),
        "foot2_on_seen_surface": plan.foot2_target_inside,
        "phases": [
            {
                "name": ph.name,
                "description": ph.description,
                "anchor": ph.anchor,
                "magnets": ph.magnets,
                "start": ph.start,
                "stop": ph.stop,
                "t_start_s": ph.t_start_s,
                "t_end_s": ph.t_end_s,
            }
            for ph in plan.phases
        ],
        "magnet_commands": plan.magnet_commands,
        "joint_names": list(robot.joint_names),
        "timings_s": plan.timings_s,
    }


def _jump_arrays(plan: JumpPlan) -> dict[str, np.ndarray]:
    return {
        "joint_trajectory": plan.joint_trajectory.astype(np.float64),
        "times": plan.times.astype(np.float64),
        "anchor": plan.anchor.astype(np.int32),
        "clearance": plan.clearance.astype(np.float64),
    }
