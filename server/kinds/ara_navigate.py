"""``ara.navigate``: inspection route of the ARA robot over a steel-bar structure
(seed 000, Ch. 4: segmentation Alg. 3, NCBE Alg. 1, graph Alg. 4, VOCPP
Alg. 5, PIBC Alg. 6 + RRT; see docs/navigation.md).

The cloud is a stored one (``cloud_id``) or a synthetic sample structure
(``sample``: cross, t, l, k, i, warren, pratt).

Which points must stay on steel (Alg. 6's projected robot points) is the
``footprint`` choice.  ``contact_patch`` (default): the magnetic-wheel
contact patch of the driving foot, 0.08 × 0.025 m (chosen; the trailing foot
follows the same track) — the part that must grip the flange, and one that
fits the samples' 60–150 mm flanges.  ``mobile_body``: the whole mobile-mode
body rectangle of robots/ara/params.toml ``[mobile_footprint]`` (0.68 ×
0.16 m), which no 60–150 mm flange can carry, so such plans are rejected by
their ``paths_found`` check — the honest answer for a robot that must not
overhang.  Explicit ``footprint_*_m`` values override both.
"""

from __future__ import annotations

from typing import Any, Literal, TypedDict

import numpy as np
from pydantic import Field

from planners.errors import InvalidInputError
from planners.navigation import NavigationParams
from planners.navigation.footprint_checks import Footprint, alg6_spacing_m, poses_on_steel, to_plane
from planners.navigation.navigate_plan import plan_navigation_result
from planners.navigation.synthetic import SAMPLES, SHAPES
from server.kinds.base import (
    Coordinate,
    JobContext,
    KindOutput,
    PlanKind,
    PlanView,
    Seed,
    StrictParams,
    VertexId,
)


class AraNavigateParams(StrictParams):
    """Cloud, route end points and method choices of an ARA navigation plan."""

    cloud_id: str | None = Field(
        None, description="id of a stored cloud (POST /clouds); metres, any frame"
    )
    crop_box_m: (
        tuple[tuple[Coordinate, Coordinate, Coordinate], tuple[Coordinate, Coordinate, Coordinate]]
        | None
    ) = Field(
        None,
        description="region of interest ((xmin, ymin, zmin), (xmax, ymax, zmax)) in the "
        "cloud's frame; None: the whole cloud",
    )
    passthrough: Literal["auto", "robot_frame", "off"] = Field(
        "auto",
        description="the seed's pass-through window (x −1…6, y −4…4, z −0.5…0.5 m, robot "
        "frame): 'auto' applies it to the samples (the ARA camera's view) and not to a stored "
        "cloud, which may be in any frame; the plan's summary says which",
    )
    sample: str = Field(
        "cross",
        description=f"sample structure when no cloud_id: one of {', '.join(SHAPES)}",
        # Listed in the schema so the console offers a choice; refused with
        # the list of names in validate() (a 422 naming the samples).
        json_schema_extra={"enum": list(SHAPES)},
    )
    sample_seed: Seed = Field(0, description="generator seed of the sample structure")
    start: VertexId | None = Field(None, description="start vertex id (None: a leaf at one end)")
    end: VertexId | None = Field(
        None, description="end vertex id (None: the leaf farthest from the other)"
    )
    segmentation: Literal["default", "thesis"] = Field(
        "default",
        description="'default' strip-based segmentation or the seed's Alg. 3 (EM-GMM + Eq. 4.1)",
    )
    route_method: Literal["exact", "thesis"] = Field(
        "exact", description="'exact' minimum T-join postman route or the seed's Alg. 5 as printed"
    )
    pibc_method: Literal["angular", "thesis"] = Field(
        "angular",
        description="boundary check: exact ray-bracket test or the seed's Alg. 6 as printed",
    )
    plan_paths: bool = Field(True, description="plan the per-edge RRT-Connect robot paths")
    motion_model: Literal["differential", "holonomic"] = Field(
        "differential",
        description="'differential': turns in place and straight drives only, what the ARA's "
        "wheels can do (the program drives exactly these poses); 'holonomic': the seed's RRT in "
        "(x, y, yaw), which slides sideways and so cannot be compiled for the wheels",
    )
    footprint: Literal["contact_patch", "mobile_body"] = Field(
        "contact_patch",
        description="points that must stay on steel: the driving foot's wheel contact patch "
        "or the whole mobile-mode body ([mobile_footprint])",
    )
    # A footprint on a steel member: the ARA's mobile body is 0.68 m long.
    footprint_length_m: float | None = Field(
        None, gt=0, le=2.0, description="robot footprint length (None: from `footprint`)"
    )
    footprint_width_m: float | None = Field(
        None, gt=0, le=2.0, description="robot footprint width (None: ARA [mobile_footprint])"
    )
    footprint_center_x_m: float | None = Field(
        None,
        ge=-2.0,
        le=2.0,
        description="footprint centre ahead of the base frame (None: ARA [mobile_footprint])",
    )
    voxel_m: float = Field(0.01, gt=0, le=0.1, description="voxel grid edge of the down-sampling")
    seed: Seed = Field(0, description="seed of RANSAC and the RRT samples")


def validate(p: AraNavigateParams) -> None:
    if p.cloud_id is None and p.sample not in SAMPLES:
        raise InvalidInputError(f"unknown sample {p.sample!r}; samples: {', '.join(SHAPES)}")
    if p.crop_box_m is not None:
        NavigationParams(crop_box_m=p.crop_box_m).validated()  # raises for a non-box


#: The driving foot's magnetic-wheel contact patch (chosen; see the module doc).
CONTACT_PATCH = {"length_m": 0.08, "width_m": 0.025, "center_x_m": 0.0, "center_y_m": 0.0}


class _Footprint(TypedDict):
    """The footprint fields of :class:`NavigationParams` (metres)."""

    footprint_length_m: float
    footprint_width_m: float
    footprint_center_x_m: float
    footprint_center_y_m: float
    footprint_spacing_m: float


def _footprint(p: AraNavigateParams) -> _Footprint:
    from robots import load_robot

    fp = (
        load_robot("ara").params["mobile_footprint"]
        if p.footprint == "mobile_body"
        else CONTACT_PATCH
    )
    length = float(p.footprint_length_m or fp["length_m"])
    width = float(p.footprint_width_m or fp["width_m"])
    return {
        "footprint_length_m": length,
        "footprint_width_m": width,
        "footprint_center_x_m": float(
            fp["center_x_m"] if p.footprint_center_x_m is None else p.footprint_center_x_m
        ),
        "footprint_center_y_m": float(fp.get("center_y_m", 0.0)),
        "footprint_spacing_m": alg6_spacing_m(length, width),
    }


class _Passthrough(TypedDict):
    """The pass-through fields of :class:`NavigationParams` (metres, robot frame)."""

    passthrough_x_m: tuple[float, float] | None
    passthrough_y_m: tuple[float, float] | None
    passthrough_z_m: tuple[float, float] | None


def _passthrough(p: AraNavigateParams) -> _Passthrough:
    """The seed's robot-frame window, or none (``auto``: none for a stored
    cloud, which may be in any frame)."""
    off = p.passthrough == "off" or (p.passthrough == "auto" and p.cloud_id is not None)
    seed = NavigationParams()
    return {
        "passthrough_x_m": None if off else seed.passthrough_x_m,
        "passthrough_y_m": None if off else seed.passthrough_y_m,
        "passthrough_z_m": None if off else seed.passthrough_z_m,
    }


def run(p: AraNavigateParams, ctx: JobContext) -> KindOutput:
    validate(p)
    ctx.progress(0.0, "loading cloud")
    points = ctx.load_cloud(p.cloud_id) if p.cloud_id else SAMPLES[p.sample](p.sample_seed)
    params = NavigationParams(
        crop_box_m=p.crop_box_m,
        **_passthrough(p),
        segmentation=p.segmentation,
        route_method=p.route_method,
        pibc_method=p.pibc_method,
        plan_paths=p.plan_paths,
        motion_model=p.motion_model,
        voxel_m=p.voxel_m,
        seed=p.seed,
        **_footprint(p),
    )
    r = plan_navigation_result(
        points, start=p.start, end=p.end, params=params, progress=ctx.progress
    )
    return KindOutput.from_result(r)


#: Wheel-command constants (chosen: slow inspection speed, servo-class turn rate).
DRIVE_SPEED_M_S = 0.05
TURN_RATE_RAD_S = 0.5
#: How far the replayed wheel motion may end from the planned last pose.
REPLAY_TOL_M = 1e-3


def compile_program(plan: PlanView) -> list[dict[str, Any]]:
    """Differential-drive wheel commands that drive exactly the planned poses.

    The per-edge paths are planned for the ARA's differential wheels (turns
    in place and straight drives, forwards or backwards: ``motion_model
    "differential"``), so the program is those poses turned into commands
    (:func:`server.kinds.programs.differential_drive_poses`); a path that
    slides sideways (``"holonomic"``) cannot be compiled and says so.  Then,
    as an independent final check, the commands are replayed
    (:func:`server.kinds.programs.replay_wheels`: exact unicycle integration
    of the quantised wheel speeds and durations, the ARA's wheel track) from
    the planned start pose, and every replayed pose, with the area swept
    between consecutive ones, must keep the footprint inside the cluster
    boundaries (exact, shapely) and the replay must end on the planned last
    pose; otherwise compilation fails and the plan's ``command_program``
    check says where.  The operator places the robot at ``result.start_pose``.
    """
    from robots import load_robot
    from server.kinds.programs import as_dicts, differential_drive_poses, replay_wheels

    res = plan.result
    if not res.get("paths") or not all(p_["ok"] for p_ in res["paths"]):
        bad = next((p_["message"] for p_ in res.get("paths", []) if not p_["ok"]), "")
        raise ValueError(
            "no complete on-steel path to drive" + (f" ({bad})" if bad else " (plan_paths was off)")
        )
    poses = np.asarray(plan.array("path_poses"), dtype=float).reshape(-1, 3)
    if len(poses) < 2:
        raise ValueError("the path has fewer than two poses, so there is nothing to drive")
    track = float(load_robot("ara").params["foot"]["wheel_track_m"])
    try:
        cmds = differential_drive_poses(
            poses, track_m=track, speed_m_s=DRIVE_SPEED_M_S, turn_rate_rad_s=TURN_RATE_RAD_S
        )
    except ValueError as exc:
        raise ValueError(
            f"the '{res.get('motion_model', '?')}' path cannot be driven by the ARA's "
            f"differential wheels: {exc}"
        ) from exc
    frame = res["frame"]
    polys = [
        to_plane(c["boundary"], frame["origin"], frame["e1"], frame["e2"]) for c in res["clusters"]
    ]
    fp = res["footprint"]
    footprint = Footprint(
        *(float(fp[k]) for k in ("length_m", "width_m", "center_x_m", "center_y_m"))
    )
    replay = replay_wheels(poses[0], cmds, track_m=track)
    report = poses_on_steel([replay], polys, footprint)
    bad = report.first_off
    if bad is not None:
        ok = report.on_steel
        raise ValueError(
            f"{int((~ok).sum())} of {len(ok)} replayed wheel poses put the footprint off the "
            f"steel (first at x={bad[0]:.3f} m, y={bad[1]:.3f} m, yaw={np.degrees(bad[2]):.0f}°)"
        )
    miss = float(np.hypot(*(replay[-1, :2] - poses[-1, :2])))
    if miss > REPLAY_TOL_M:
        raise ValueError(
            f"the replayed wheel motion ends {miss * 1000:.1f} mm from the planned last pose"
        )
    return as_dicts(cmds)


KIND = PlanKind(
    name="ara.navigate",
    title="ARA: inspection route over a steel-bar structure",
    description=__doc__ or "",
    params_model=AraNavigateParams,
    run=run,
    validate=validate,
    robot="ara",
    samples=dict(SAMPLES),
    compile=compile_program,
)
