"""``ara.inspect``: the ARA's inspection route over a whole scanned steel
structure (issue #14 §5; see docs/inspection.md).

The cloud is a stored scan (``cloud_id``: a TLS / photogrammetry survey of
the whole structure, any frame, any spacing) or a synthetic TLS scan
(``sample``: scan_warren, scan_pratt, scan_frame, scan_grillage).  The
planner models the structure — members with their section profile and
faces, joints, member graph (``planners.structure``) — and plans the route
over every member span with the ARA's mobile / inch-worm transitions at each
vertex and inch-worm jumps across the gaps within reach
(``planners.inspection``; seed 000 §3.1, Eq. 3.1–3.4, Alg. 2, Alg. 5).

Robot numbers default to the ARA's ``robots/ara/params.toml``: the foot
rectangle [foot] and the jump reach, the largest sole-to-sole distance of
the [arm] chain.  The plan has no robot program: it says where the robot
drives and where it must jump; each jump is planned by ``ara.switch``.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Literal

import numpy as np
from pydantic import Field

from planners.errors import InvalidInputError
from planners.inspection.inspect_plan import plan_inspection_result, validate_crop_box
from planners.inspection.params import InspectionParams
from planners.structure.params import StructureParams
from planners.structure.synthetic import SCAN_SAMPLES
from server.kinds.base import (
    SPAN_M,
    Coordinate,
    JobContext,
    KindOutput,
    PlanKind,
    Seed,
    StrictParams,
    VertexId,
)

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
        "UPN 200 channels, whose webs take the ARA's foot, so the default plan passes its "
        "checks; seed 0's L 80 angles are narrower than the foot and its plan is rejected)",
    )
    crop_box_m: Box | None = Field(
        None,
        description="region of interest ((xmin, ymin, zmin), (xmax, ymax, zmax)) in metres of "
        "the cloud's frame, after the units are applied; None: the whole cloud",
    )
    units: Literal["auto", "m", "mm"] = Field(
        "auto",
        description="unit of the cloud's numbers: 'auto' decides from the point spacing and "
        "extent as an upload does (a stored cloud is already metres after its upload, see its "
        "survey record, so 'auto' leaves it); 'mm' scales by 0.001 (for a millimetre cloud the "
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


def ara_robot_numbers() -> dict[str, float]:
    """The ARA's foot rectangle ([foot]) and jump reach: the largest
    sole-to-sole distance of the [arm] chain, every offset straight in line
    (the same derivation as ``planners.inspection.params.ARA_JUMP_REACH_M``,
    read here from the robot's file so that an edit to it reaches plans)."""
    from robots import load_robot

    prm = load_robot("ara").params
    foot, arm = prm["foot"], prm["arm"]
    chain = ("j1_above_sole_m", "j2_above_j1_m", "link2_m", "link3_m", "link4_m")
    reach = sum(float(arm[k]) for k in (*chain, "j6_below_j5_m", "sole_below_j6_m"))
    return {
        "foot_length_m": float(foot["length_m"]),
        "foot_width_m": float(foot["width_m"]),
        "jump_reach_m": reach,
    }


def inspection_params(p: AraInspectParams) -> InspectionParams:
    """The route's parameters: the request's numbers over the ARA's."""
    ara = ara_robot_numbers()
    return InspectionParams(
        foot_length_m=ara["foot_length_m"] if p.foot_length_m is None else p.foot_length_m,
        foot_width_m=ara["foot_width_m"] if p.foot_width_m is None else p.foot_width_m,
        jump_reach_m=ara["jump_reach_m"] if p.jump_reach_m is None else p.jump_reach_m,
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


def run(p: AraInspectParams, ctx: JobContext) -> KindOutput:
    validate(p)
    ctx.progress(0.0, "loading cloud")
    points = ctx.load_cloud(p.cloud_id) if p.cloud_id else sample_points(p.sample, p.sample_seed)
    r = plan_inspection_result(
        points,
        crop_box_m=p.crop_box_m,
        structure=structure_params(p),
        inspection=inspection_params(p),
        start=p.start,
        end=p.end,
        units=p.units,
        progress=ctx.progress,
    )
    return KindOutput.from_result(r)


KIND = PlanKind(
    name="ara.inspect",
    title="ARA: inspection route over a whole scanned structure",
    description=__doc__ or "",
    params_model=AraInspectParams,
    run=run,
    validate=validate,
    robot="ara",
    samples=dict(SCAN_SAMPLES),
)
