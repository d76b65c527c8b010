"""``ara.inspect``: the ARA's inspection route over a whole scanned steel
structure, with its robot program (see
docs/inspection.md).

The cloud is a stored scan (``cloud_id``: a TLS / photogrammetry survey of
the whole structure, any frame, any spacing) or a synthetic TLS scan
(``sample``: scan_warren, scan_pratt, scan_frame, scan_grillage).  The
planner models the structure — members with their section profile and
faces, joints, member graph (``planners.structure``) — and plans the route
over every member span with the ARA's mobile / inch-worm transitions at each
vertex and inch-worm jumps across the gaps within reach
(``planners.inspection``; seed 000 §3.1, Eq. 3.1–3.4, Alg. 2, Alg. 5).

The planning job also plans the program's parts (``planners.inspection.
program_plan``): the stretches driven on wheels along the members' driving
faces, and every inch-worm jump of the main route with the ``ara.switch``
jump planner (seed §3.2, OMPL RRT-Connect), one plan per distinct jump
geometry placed at every joint of that geometry and re-checked there.
:func:`assemble_program` turns those stored parts into commands — per
stretch a ``base_pose``, wheel commands split every 0.5 m by a ``capture``;
per jump a ``capture`` at the joint, magnet 2 touched, the jump's joint
way-points, magnet 1 touched, magnet 2 released, foot 2's way-points,
magnet 1 released (mobile) — and the job runs it through the checks
(``feet_attached``: the two feet are never both released; joint and wheel
limits) before the plan is stored; :func:`compile_program` assembles the
same program for dispatch.  It never plans: it reads what the job stored.

Robot numbers default to the ARA's ``robots/ara/params.toml``: the foot
rectangle [foot], the jump reach (the largest sole-to-sole distance of the
[arm] chain) and the arm's exact reach bound (wrist offsets and arm length,
the inch-worm check S_hc).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Mapping
from functools import lru_cache
from typing import Any, Literal

import numpy as np
from pydantic import Field

from planners.errors import InvalidInputError
from planners.inspection.inspect_plan import plan_inspection_result, validate_crop_box
from planners.inspection.jumps import JumpSetParams, inspection_jump_params
from planners.inspection.layout import LayoutParams
from planners.inspection.params import InspectionParams
from planners.inspection.program import (
    attachment_check,
    command_limits,
    program_metrics,
    simulate_attachment,
)
from planners.result import PlanResult
from planners.structure.params import StructureParams
from planners.structure.synthetic import SCAN_SAMPLES
from server.kinds.base import (
    SPAN_M,
    Coordinate,
    JobContext,
    KindOutput,
    PlanKind,
    PlanView,
    Seed,
    StrictParams,
    VertexId,
)
from server.structure_tiles import lazy_structure_mapper

Box = tuple[tuple[Coordinate, Coordinate, Coordinate], tuple[Coordinate, Coordinate, Coordinate]]


class AraInspectParams(StrictParams):
    """Cloud, units, route end points, robot numbers and model overrides of an
    ARA inspection plan over a whole structure."""

    cloud_id: str | None = Field(
        None, description="id of a stored cloud (POST /clouds); any frame, e.g. a survey frame"
    )
    sample: str = Field(
        "scan_warren",
        description=f"synthetic TLS scan when no cloud_id: one of {', '.join(SCAN_SAMPLES)}",
        # Listed in the schema so the console offers a choice; refused with
        # the list of names in validate() (a 422 naming the samples).
        json_schema_extra={"enum": list(SCAN_SAMPLES)},
    )
    sample_seed: Seed = Field(
        2,
        description="generator seed of the sample scan (2: the Warren truss's web members are "
        "UPN 200 channels, whose webs take the ARA's foot; 3 of its transitions are beyond the "
        "arm's reach and are named; seed 0's L 80 angles are narrower than the foot)",
    )
    crop_box_m: Box | None = Field(
        None,
        description="region of interest ((xmin, ymin, zmin), (xmax, ymax, zmax)) in metres of "
        "the cloud's frame, after the units are applied; None: the whole cloud",
    )
    units: Literal["auto", "m", "mm", "ft", "us-ft"] = Field(
        "auto",
        description="unit of the cloud's numbers: 'auto' decides from the point spacing and "
        "extent as an upload does (a stored cloud is already metres after its upload, see its "
        "survey record, so 'auto' leaves it); 'mm' scales by 0.001 (for a millimetre cloud the "
        "upload read as metres); 'ft' by 0.3048, 'us-ft' by 1200/3937 (a feet cloud the "
        "upload read as metres); 'm' leaves the numbers",
    )
    start: VertexId | None = Field(
        None, description="start vertex id of the member graph (None: a far free end)"
    )
    end: VertexId | None = Field(
        None,
        description="end vertex id of the member graph (None: the free end farthest away)",
    )
    close_member: VertexId | None = Field(
        None,
        description="close inspection: drive from start to this member and along it "
        "(None: the whole structure)",
    )
    foot_length_m: float | None = Field(
        None, gt=0, le=2.0, description="foot (sole) length (None: ARA [foot] length_m)"
    )
    foot_width_m: float | None = Field(
        None, gt=0, le=2.0, description="foot (sole) width (None: ARA [foot] width_m)"
    )
    jump_reach_m: float | None = Field(
        None,
        gt=0,
        le=5.0,
        description="largest sole-to-sole distance of an inch-worm jump (None: the ARA arm's, "
        "from [arm] of robots/ara/params.toml)",
    )
    coplanar_angle_deg: float = Field(
        10.0,
        ge=0,
        lt=90,
        description="two driving faces continue (mobile transition) when their normals are "
        "within this angle",
    )
    jump_cost_m: float = Field(
        0.5,
        ge=0,
        le=SPAN_M,
        description="what one inch-worm jump is worth in metres when choosing the route",
    )
    max_section_m: float | None = Field(
        None,
        gt=0,
        le=10.0,  # the deepest plate and box girders are a few metres
        description="largest member section depth expected (None: the model's 1.2 m)",
    )
    max_gap_m: float | None = Field(
        None,
        gt=0,
        le=100.0,  # longer than any member an occlusion could hide
        description="collinear fragments across an occlusion gap up to this are one member "
        "(None: the model's 2.0 m)",
    )
    linearity_min: float | None = Field(
        None,
        gt=0,
        lt=1,
        description="a voxel is on a member when its linearity is at least this (None: 0.6)",
    )
    plan_jumps: bool = Field(
        False,
        description="plan the robot program: every inch-worm jump of the main route with the "
        "ARA's jump planner, and the program's checks (False: the route only, no program; "
        "off by default while the jump planner cannot land the samples' jumps, see "
        "docs/inspection.md)",
    )
    jump_seed: Seed = Field(0, description="seed of the jumps' RRT-Connect samples")
    clearance_margin_m: float = Field(
        0.01, ge=0, le=0.2, description="required clearance along every jump"
    )


def ara_robot_numbers() -> dict[str, float]:
    """The ARA's foot rectangle ([foot]), its jump reach — the largest
    sole-to-sole distance of the [arm] chain, every offset straight in line
    (the same derivation as ``planners.inspection.params.ARA_JUMP_REACH_M``)
    — and the exact reach bound of the inch-worm check S_hc: the wrist
    offsets (joint 2 above foot 2's sole, joint 5 off foot 1's sole) and the
    arm length between them (link2 + link3 + link4), read here from the
    robot's file so that an edit to it reaches plans."""
    from robots import load_robot

    prm = load_robot("ara").params
    foot, arm = prm["foot"], prm["arm"]

    def total(*keys: str) -> float:
        return sum(float(arm[k]) for k in keys)

    standing = total("j1_above_sole_m", "j2_above_j1_m")
    landing = total("j6_below_j5_m", "sole_below_j6_m")
    length = total("link2_m", "link3_m", "link4_m")
    return {
        "foot_length_m": float(foot["length_m"]),
        "foot_width_m": float(foot["width_m"]),
        "jump_reach_m": standing + length + landing,
        "arm_length_m": length,
        "wrist_standing_m": standing,
        "wrist_landing_m": landing,
    }


def inspection_params(p: AraInspectParams) -> InspectionParams:
    """The route's parameters: the request's numbers over the ARA's."""
    ara = ara_robot_numbers()
    return InspectionParams(
        foot_length_m=ara["foot_length_m"] if p.foot_length_m is None else p.foot_length_m,
        foot_width_m=ara["foot_width_m"] if p.foot_width_m is None else p.foot_width_m,
        jump_reach_m=ara["jump_reach_m"] if p.jump_reach_m is None else p.jump_reach_m,
        arm_length_m=ara["arm_length_m"],
        wrist_standing_m=ara["wrist_standing_m"],
        wrist_landing_m=ara["wrist_landing_m"],
        coplanar_angle_deg=p.coplanar_angle_deg,
        jump_cost_m=p.jump_cost_m,
        close_member=p.close_member,
    )


def structure_params(p: AraInspectParams) -> StructureParams:
    """The model's parameters: the model's defaults with the request's overrides."""
    names = ("max_section_m", "max_gap_m", "linearity_min")
    return StructureParams(**{k: getattr(p, k) for k in names if getattr(p, k) is not None})


def validate(p: AraInspectParams) -> None:
    if p.cloud_id is None and p.sample not in SCAN_SAMPLES:
        raise InvalidInputError(f"unknown sample {p.sample!r}; samples: {', '.join(SCAN_SAMPLES)}")
    validate_crop_box(p.crop_box_m)
    inspection_params(p)  # raises for numbers the route planner refuses


@lru_cache(maxsize=4)
def sample_points(name: str, seed: int) -> np.ndarray:
    """A sample scan, generated once per worker process (0.2–0.3 s for the
    default Warren scan: a tenth of its plan); read-only, shared by plans."""
    pts = SCAN_SAMPLES[name](seed)
    pts.setflags(write=False)
    return pts


def _ara() -> Any:
    from robots import load_robot

    return load_robot("ara")


def _program_inputs(p: AraInspectParams) -> dict[str, Any]:
    """The robot, layout and jump parameters the planning job needs to plan the program."""
    from planners.switching.jump import JumpRobot

    ara = _ara()
    ip = inspection_params(p)
    spacing = float(ara.params["arm"]["foot_spacing_m"])
    return {
        "robot": JumpRobot.from_model(ara),
        "layout": LayoutParams(
            foot_length_m=ip.foot_length_m,
            foot_width_m=ip.foot_width_m,
            foot_spacing_m=spacing,
        ),
        "jumps": JumpSetParams(
            jump=inspection_jump_params(
                spacing, seed=p.jump_seed, clearance_margin_m=p.clearance_margin_m
            )
        ),
        "joint_names": list(ara.joint_names),
    }


def run(p: AraInspectParams, ctx: JobContext) -> KindOutput:
    validate(p)
    ctx.progress(0.0, "loading cloud")
    points = ctx.load_cloud(p.cloud_id) if p.cloud_id else sample_points(p.sample, p.sample_seed)
    from server.survey_io import UNIT_TO_M  # feet: scaled here, the planner knows m and mm

    feet = UNIT_TO_M[p.units] if p.units in ("ft", "us-ft") else None
    if feet is not None:
        points = np.asarray(points, dtype=np.float64) * feet
    extra = _program_inputs(p) if p.plan_jumps else {}
    r = plan_inspection_result(
        points,
        mapper=lazy_structure_mapper(),
        crop_box_m=p.crop_box_m,
        structure=structure_params(p),
        inspection=inspection_params(p),
        start=p.start,
        end=p.end,
        units="m" if feet is not None else p.units,
        progress=ctx.progress,
        **extra,
    )
    if feet is not None:
        reason = f"set by the request ({p.units})"
        r.summary["units"] = {"unit": p.units, "scale_to_m": feet, "reason": reason}
    if p.plan_jumps:
        program_checks(r)
    else:
        # Shown where Dispatch would be: why this plan cannot be sent to the robot.
        r.summary["program_note"] = NO_PROGRAM_NOTE
    return KindOutput.from_result(r)


NO_PROGRAM_NOTE = (
    "no robot program: the inch-worm jumps were not planned (plan_jumps is off; the jump "
    "planner cannot yet land the sample trusses' jumps, see docs/inspection.md)"
)


#: The ARA's drive limits (the same as ``ara.navigate``'s).
def _drive_limits() -> tuple[float, float]:
    from server.kinds.ara_navigate import DRIVE_SPEED_M_S, TURN_RATE_RAD_S

    return DRIVE_SPEED_M_S, TURN_RATE_RAD_S


#: Magnet channels of the ARA's two feet on the wire (as ``ara.switch``).
MAGNET_CHANNEL = {"foot1": 0, "foot2": 1}


def rpy(R: np.ndarray) -> tuple[float, float, float]:
    """(roll, pitch, yaw) with ``R = Rz(yaw)·Ry(pitch)·Rx(roll)`` (the
    ``base_pose`` convention); at pitch ±90° roll is 0."""
    R = np.asarray(R, float)
    pitch = math.asin(float(np.clip(-R[2, 0], -1.0, 1.0)))
    if abs(math.cos(pitch)) < 1e-9:
        return 0.0, pitch, math.atan2(float(-R[0, 1]), float(R[1, 1]))
    return (
        math.atan2(float(R[2, 1]), float(R[2, 2])),
        pitch,
        math.atan2(float(R[1, 0]), float(R[0, 0])),
    )


def split_drive(poses: np.ndarray, every_m: float) -> list[np.ndarray]:
    """The differential-drive pose sequence ``poses`` (K, 3) cut into pieces
    at every ``every_m`` metres driven (a cut pose interpolated on its
    straight piece); the pieces share their end poses."""
    q = np.asarray(poses, float).reshape(-1, 3)
    pieces: list[list[np.ndarray]] = [[q[0]]]
    run = 0.0
    for a, b in itertools.pairwise(q):
        d = float(np.hypot(*(b[:2] - a[:2])))
        start = a
        while d > 1e-9 and run + d >= every_m - 1e-9:
            f = (every_m - run) / d
            cut = start + f * (b - start)
            cut[2] = b[2]
            pieces[-1].append(cut)
            pieces.append([cut])
            d -= every_m - run
            start, run = cut, 0.0
        if d > 1e-9 or float(np.abs(b - start).max()) > 1e-12:
            pieces[-1].append(b)
            run += d
    return [np.array(p) for p in pieces if len(p) > 1]


def _jump_commands(
    t: np.ndarray, q: np.ndarray, phases: list[Mapping[str, Any]], sample_s: float
) -> list[Any]:
    """Seed §3.2's sequence for one jump's stored trajectory: magnet 2
    touched (the standing foot), foot 1's way-points (phases B, C: to
    P_conv, RRT-Connect path, straight approach), magnet 1 touched (the
    landed foot holds), magnet 2 released, foot 2's way-points (phase E),
    magnet 1 released (both untouched: the mobile configuration).  Way-points
    every ``sample_s`` of the trajectory, always including the sample where
    foot 1 lands and the last one."""
    from robots.protocol.commands import JointMove, SetMagnet

    by = {str(ph["name"]): ph for ph in phases}
    land = int(by["C"]["stop"]) - 1
    dt = float(np.median(np.diff(t))) if len(t) > 1 else sample_s
    step = max(1, round(sample_s / max(dt, 1e-6)))
    idx = np.unique(np.r_[np.arange(0, len(t), step), land, len(t) - 1])
    out: list[Any] = [SetMagnet(MAGNET_CHANNEL["foot2"], True)]
    prev = None
    for i in idx:
        if prev is not None and prev <= land < i:
            out += [SetMagnet(MAGNET_CHANNEL["foot1"], True)]
            out += [SetMagnet(MAGNET_CHANNEL["foot2"], False)]
        dur = 0.0 if prev is None else float(t[i] - t[prev])
        out.append(JointMove(tuple(float(v) for v in q[i]), dur))
        prev = int(i)
    out.append(SetMagnet(MAGNET_CHANNEL["foot1"], False))
    return out


def assemble_program(
    result: Mapping[str, Any],
    array: Callable[[str], np.ndarray],
    *,
    track_m: float,
    speed_m_s: float,
    turn_rate_rad_s: float,
    sample_s: float = 0.1,
) -> list[Any]:
    """The robot program (command objects) from a plan's stored parts:
    ``result`` the summary, ``array(name)`` its arrays.  Used by the
    planning job (for the program checks) and by :func:`compile_program`,
    so both see the same program.  Per stretch: ``base_pose`` (its start,
    relative to ``world_origin_m``), wheel commands
    (:func:`server.kinds.programs.differential_drive_poses`) cut every
    ``capture_every_m`` by a ``capture``; per jump that ends a stretch: a
    ``capture`` at the joint and :func:`_jump_commands`.  A jump that was
    not planned ends the program there.  Empty without a program."""
    from robots.protocol.commands import BasePose, Capture, Stop
    from server.kinds.programs import differential_drive_poses

    prog = result.get("program")
    if not prog or not prog.get("stretches"):
        return []
    origin = np.asarray(result.get("world_origin_m") or prog["world_origin_m"], float)
    offsets = np.asarray(array("jump_offsets"), np.int64)
    jq, jt = array("jump_q"), array("jump_times")
    out: list[Any] = []
    for st in prog["stretches"]:
        S = np.asarray(st["start"], float)
        out.append(BasePose(tuple(float(v) for v in S[:3, 3] - origin), rpy(S[:3, :3])))
        for piece in split_drive(
            np.asarray(st["waypoints"], float), float(prog["capture_every_m"])
        ):
            cmds = differential_drive_poses(
                piece, track_m=track_m, speed_m_s=speed_m_s, turn_rate_rad_s=turn_rate_rad_s
            )
            out += cmds
            moved = float(np.hypot(*(piece[-1, :2] - piece[0, :2])))
            if moved > 1e-9 and len(cmds) > 1:
                out.append(Capture())
        if st["ends_in"] is None:
            continue
        site = prog["sites"][st["ends_in"]]
        out.append(Capture())  # the structural joint, before the jump
        k = site["unique"]
        if k is None or site["foot1"] is None:
            break
        sl = slice(int(offsets[k]), int(offsets[k + 1]))
        out += _jump_commands(jt[sl], jq[sl], prog["unique_jumps"][k]["phases"], sample_s)
    out.append(Stop())
    return out


def _program_dicts(result: Mapping[str, Any], array: Callable[[str], np.ndarray]) -> list[dict]:
    from server.kinds.programs import as_dicts

    speed, turn = _drive_limits()
    track = float(_ara().params["foot"]["wheel_track_m"])
    return as_dicts(
        assemble_program(result, array, track_m=track, speed_m_s=speed, turn_rate_rad_s=turn)
    )


def program_checks(r: PlanResult) -> list[dict]:
    """Assemble the program from ``r``'s stored parts and add its checks to
    ``r``: ``feet_attached`` (:func:`planners.inspection.program.simulate_attachment`),
    ``program_joint_limits``, ``program_joint_speeds``,
    ``program_wheel_speeds``; metrics ``program_duration_s``,
    ``program_distance_m`` and the command counts.  Returns the program."""
    ara = _ara()
    program = _program_dicts(r.summary, r.arrays.__getitem__)
    speed, turn = _drive_limits()
    r.checks.append(attachment_check(simulate_attachment(program, q_mobile=ara.q_mobile)))
    r.checks += command_limits(
        program,
        joint_limits=ara.joint_limits,
        max_speed=ara.max_speed,
        drive_speed_m_s=speed,
        turn_rate_rad_s=turn,
        track_m=float(ara.params["foot"]["wheel_track_m"]),
        q_start=ara.q_mobile,
    )
    r.metrics.update(program_metrics(program))
    return program


def compile_program(plan: PlanView) -> list[dict[str, Any]] | None:
    """The stored program parts assembled into commands
    (:func:`assemble_program`, the same code the planning job checked);
    ``None`` when the plan has no program (``plan_jumps`` false, or no
    member to drive)."""
    program = _program_dicts(plan.result, plan.array)
    return program or None


KIND = PlanKind(
    name="ara.inspect",
    title="ARA: inspection route over a whole scanned structure",
    description=__doc__ or "",
    params_model=AraInspectParams,
    run=run,
    validate=validate,
    robot="ara",
    compile=compile_program,
    samples=dict(SCAN_SAMPLES),
)
