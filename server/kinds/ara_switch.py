"""``ara.switch``: ARA mobile / inch-worm switching and the inch-worm jump
(seed 000, Ch. 3: Eq. 3.1–3.4, Alg. 1–2, §3.2; experiments §5.2.1–5.2.2;
see docs/switching.md).

The cloud is a stored one (``cloud_id``, camera frame) or a synthetic depth
scan of one of the seed's experiments (``sample``).  The switching function
decides "mobile", "inchworm" or "none"; for "inchworm" the jump is planned
with the ARA model: timed joint trajectory, magnet commands per phase and
clearance along the path.  Defaults plan Fig. 5.4 (two perpendicular slabs).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from pydantic import Field

from planners.errors import InvalidInputError
from planners.switching import SwitchingParams
from planners.switching.jump import JumpParams
from planners.switching.scenes import SCENES, make_scene
from planners.switching.switch_plan import plan_switch
from server.kinds.base import (
    Check,
    JobContext,
    KindOutput,
    PlanKind,
    PlanView,
    StrictParams,
    check_ge,
    check_le,
)

SAMPLE_PREFIX = "switch_"


class AraSwitchParams(StrictParams):
    """Scan, robot base and tolerances of an ARA switching decision + jump."""

    cloud_id: str | None = Field(
        None, description="id of a stored cloud (POST /clouds), camera frame, metres"
    )
    sample: str = Field(
        "perpendicular",
        description=f"synthetic scan when no cloud_id: one of {', '.join(SCENES)}",
    )
    sample_seed: int = Field(0, ge=0, description="noise seed of the synthetic scan")
    camera_to_base: list[list[float]] | None = Field(
        None, description="4×4 camera→base transform (None: the ARA's, from its URDF)"
    )
    base_height_m: float = Field(
        0.0, description="height of the standing surface in the base frame"
    )
    height_tolerance_m: float = Field(0.005, gt=0, description="Eq. 3.4 'equal' tolerance")
    distance_tolerance: float = Field(0.02, gt=0, lt=1, description="Alg. 2 t (relative)")
    n_closest: int = Field(5, ge=1, le=50, description="Alg. 2 n (rectangles tried)")
    m_neighbours: int = Field(3, ge=1, le=20, description="Alg. 2 m")
    sliding_factor_m: float = Field(0.01, gt=0, le=0.2, description="NCBE slice width αs")
    voxel_m: float = Field(0.01, gt=0, le=0.1, description="voxel grid edge")
    reach_m: float = Field(0.5, gt=0, description="max foothold distance from the base origin")
    plan_jump: bool = Field(True, description="plan the inch-worm jump when the mode is inchworm")
    clearance_margin_m: float = Field(0.01, ge=0, description="required clearance along the jump")
    attempts: int = Field(4, ge=1, le=20, description="RRT-Connect restarts per phase")
    seed: int = Field(0, ge=0, description="seed of RANSAC and the RRT samples")


def validate(p: AraSwitchParams) -> None:
    if p.cloud_id is None and p.sample not in SCENES:
        raise InvalidInputError(f"unknown sample {p.sample!r}; samples: {', '.join(SCENES)}")
    if p.camera_to_base is not None and np.asarray(p.camera_to_base).shape != (4, 4):
        raise InvalidInputError("camera_to_base must be a 4×4 matrix (list of 4 rows)")


def _robot():
    from robots import load_robot

    return load_robot("ara")


def _mat(T: np.ndarray | None) -> list[list[float]] | None:
    return None if T is None else np.round(np.asarray(T, float), 6).tolist()


def run(p: AraSwitchParams, ctx: JobContext) -> KindOutput:
    t0 = time.perf_counter()
    validate(p)
    ara = _robot()
    ctx.progress(0.0, "loading cloud")
    if p.cloud_id:
        points = ctx.load_cloud(p.cloud_id)
        T = np.asarray(p.camera_to_base, float) if p.camera_to_base else ara.camera_to_base
    else:
        scene = make_scene(p.sample, p.sample_seed)
        points = scene.points
        T = np.asarray(p.camera_to_base, float) if p.camera_to_base else scene.camera_to_base
    foot = (float(ara.params["foot"]["length_m"]), float(ara.params["foot"]["width_m"]))
    sp = SwitchingParams(
        voxel_m=p.voxel_m,
        sliding_factor_m=p.sliding_factor_m,
        n_closest=p.n_closest,
        m_neighbours=p.m_neighbours,
        distance_tolerance=p.distance_tolerance,
        height_tolerance_m=p.height_tolerance_m,
        reach_m=p.reach_m,
        seed=p.seed,
    )
    out = plan_switch(
        ara,
        points,
        camera_to_base=T,
        base_height=p.base_height_m,
        foot=foot,
        params=sp,
        jump=JumpParams(clearance_margin_m=p.clearance_margin_m, attempts=p.attempts, seed=p.seed)
        if p.plan_jump
        else None,
        progress=ctx.progress,
    )
    d = out.decision
    labels = np.full(len(d.points), -1, dtype=np.int32)
    for c in d.candidates:
        labels[c.points_index] = c.index
    rects = [r for c in d.candidates for r in c.rectangles]
    rect_plane = [c.index for c in d.candidates for _ in c.rectangles]
    boundaries = [c.frame.to_world(c.area.boundary2d) for c in d.candidates]
    result: dict[str, Any] = {
        "decision": d.summary(),
        "camera_to_base": _mat(T),
        "foot_m": list(foot),
        "planes": [
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
                        "exact_margin_m": r.exact_margin_m
                        if np.isfinite(r.exact_margin_m)
                        else None,
                        "reason": r.reason,
                        "corners": np.round(r.corners, 5).tolist(),
                    }
                    for r in c.rectangles
                ],
            }
            for c in d.candidates
        ],
        "foothold": _mat(d.foothold),
        "jump": None,
    }
    metrics: dict[str, float] = {
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
    checks = [
        Check(
            name="safe_surface",
            passed=d.mode != "none",
            value=d.mode,
            limit="mobile|inchworm",
            message=d.message,
        )
    ]
    arrays: dict[str, np.ndarray] = {
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
    if out.jump_error is not None:
        checks.append(
            Check(
                name="jump_planned", passed=False, value=False, limit=True, message=out.jump_error
            )
        )
    plan = out.jump
    if plan is not None:
        m = plan.metrics(ara)
        Q = plan.joint_trajectory
        # checks recomputed from the returned trajectory (planners.switching.jump_checks)
        ratio, viol, foot1_inside = out.speed_ratio, out.joint_limit_excess_rad, out.foot1_inside
        checks += [
            Check(
                name="jump_planned",
                passed=True,
                value=True,
                limit=True,
                message="all phases planned",
            ),
            check_le("joint_limits", viol, 0.0, "largest joint-limit excess", " rad"),
            check_le("joint_speeds", ratio, 1.0, "largest joint speed / limit", ""),
            check_ge(
                "clearance",
                float(plan.clearance.min()),
                p.clearance_margin_m,
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
                passed=foot1_inside,
                value=foot1_inside,
                limit=True,
                message="foot 1's footprint lies inside the target plane's concave hull"
                if foot1_inside
                else "foot 1's footprint leaves the target plane's concave hull",
            ),
        ]
        metrics.update(
            {
                "jump_duration_s": m["duration_s"],
                "jump_min_clearance_m": m["min_clearance_m"],
                "jump_min_self_clearance_m": m["min_self_clearance_m"],
                "jump_max_speed_ratio": m["max_speed_ratio"],
                "jump_planning_time_s": m["planning_time_s"],
                "jump_rrt_attempts": m["attempts_used"],
                "foot2_on_seen_surface": float(plan.foot2_target_inside),
            }
        )
        result["jump"] = {
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
            "joint_names": list(ara.joint_names),
            "timings_s": plan.timings_s,
        }
        arrays.update(
            {
                "joint_trajectory": Q.astype(np.float64),
                "times": plan.times.astype(np.float64),
                "anchor": plan.anchor.astype(np.int32),
                "clearance": plan.clearance.astype(np.float64),
            }
        )
    metrics["planning_time_s"] = time.perf_counter() - t0
    ctx.progress(1.0, "done")
    return KindOutput(result=result, arrays=arrays, checks=checks, metrics=metrics)


def _sample(name: str):
    def make(seed: int) -> np.ndarray:
        return make_scene(name, seed).points

    return make


#: Magnet channels of the ARA's two feet on the wire.
MAGNET_CHANNEL = {"foot1": 0, "foot2": 1}


def compile_program(plan: PlanView, sample_s: float = 0.1) -> list[dict[str, Any]] | None:
    """The inch-worm jump as a command program: J1…J6 way-points every
    ``sample_s`` of the timed trajectory (§3.2: magnet 2 touched → Pconv →
    foot 1 to the target → swap → foot 2 follows → mobile configuration),
    with each magnet command inserted after the last way-point reached by its
    time, so a foot is released only after the other one holds.

    ``None`` when there is nothing for the arm to do: in mobile mode the
    robot keeps driving (no jump), and with mode "none" it must not move.
    """
    from robots.protocol.commands import SetMagnet
    from server.kinds.programs import as_dicts, sampled_joints_with_events

    jump = plan.result.get("jump")
    if plan.result.get("decision", {}).get("mode") != "inchworm" or not jump:
        return None
    events = [
        (float(c["t_s"]), SetMagnet(MAGNET_CHANNEL[c["foot"]], c["state"] == "touched"))
        for c in jump["magnet_commands"]
    ]
    return as_dicts(
        sampled_joints_with_events(
            plan.array("times"), plan.array("joint_trajectory"), events, sample_s=sample_s
        )
    )


KIND = PlanKind(
    name="ara.switch",
    title="ARA: mobile / inch-worm switching and inch-worm jump",
    description=__doc__ or "",
    params_model=AraSwitchParams,
    run=run,
    validate=validate,
    robot="ara",
    compile=compile_program,
    samples={f"{SAMPLE_PREFIX}{name}": _sample(name) for name in SCENES},
)
