"""``blast``: sand-blasting of a planar rusted surface by the DENSO VM-6083
(seed 004, Chapters 3–4; see docs/blasting.md).

The surface is one of the seed's scene surfaces (``seed_surface`` 1–3), a
polygon on a plane (``polygon``), or a plane picked from a stored cloud
(``cloud_id`` + ``plane_index``: sequential RANSAC planes, largest first; the
cloud's other points become obstacle points).  The defaults plan the seed's
Surface 1 on the roof of the I-beam channel with 0.04 m discs (§4.2.1,
§4.2.5).  The planner is :func:`planners.blasting.blast_plan.plan_blast_result`
(around :func:`planners.blasting.plan_blasting`).
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

import numpy as np
from pydantic import Field, field_validator

from planners.blasting import Box, Surface, scenes
from planners.blasting.base_placement import BaseLimits
from planners.blasting.blast_plan import BlastLimits, BlastOptions, PlanePick, plan_blast_result
from planners.blasting.nozzle import STREAM_MAX_MM, STREAM_MIN_MM, check_stream_length
from planners.blasting.sample_clouds import under_deck_cloud
from planners.errors import InvalidInputError, NoPlaneError
from server.kinds.base import (
    Coordinate,
    JobContext,
    KindOutput,
    Offset,
    PlanKind,
    PlanView,
    Seed,
    StrictParams,
)

ROBOT = "denso_vm6083"

#: A stream length (mm).  Its 100–500 mm window is checked by
#: ``BlastParams._window``, whose message gives the seed's reason; the schema
#: states it.
StreamMm = Annotated[
    float, Field(json_schema_extra={"minimum": STREAM_MIN_MM, "maximum": STREAM_MAX_MM})
]


class PolygonSurface(StrictParams):
    """A planar surface: outline in the plane frame (DESIGN §5)."""

    origin_m: list[Coordinate] = Field(
        ..., min_length=3, max_length=3, description="plane origin [x, y, z] (m)"
    )
    # directions of any length: bounded like coordinates
    normal: list[Coordinate] = Field(
        ..., min_length=3, max_length=3, description="plane normal (any length)"
    )
    boundary_m: list[list[Offset]] = Field(
        ..., min_length=3, description="outline [[u, v], ...] in the plane frame (m)"
    )
    holes_m: list[list[list[Offset]]] = Field(
        default_factory=list, description="holes, same frame (m)"
    )
    x_axis: list[Coordinate] | None = Field(
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

    lo_m: list[Coordinate] = Field(
        ..., min_length=3, max_length=3, description="min corner [x, y, z] (m)"
    )
    hi_m: list[Coordinate] = Field(
        ..., min_length=3, max_length=3, description="max corner [x, y, z] (m)"
    )
    name: str = Field("", description="label shown in the scene")


def _channel() -> list[BoxObstacle]:
    return [
        BoxObstacle(lo_m=list(b.center - b.half), hi_m=list(b.center + b.half), name=b.name)
        for b in scenes.bridge_obstacles()
    ]


class BaseSearch(StrictParams):
    """Search the robot base in a region instead of ``robot_base_m``."""

    lo_m: list[Coordinate] | None = Field(
        None,
        min_length=3,
        max_length=3,
        description="region min corner (m); None: around the surface",
    )
    hi_m: list[Coordinate] | None = Field(
        None,
        min_length=3,
        max_length=3,
        description="region max corner (m); None: around the surface",
    )
    step_m: float = Field(0.1, gt=0.01, le=1.0, description="grid step of the search (m)")
    clearance_m: float = Field(
        0.3, ge=0, le=2.0, description="free room the base needs from scan points and boxes (m)"
    )

    def build(self) -> BaseLimits:
        return BaseLimits(self.lo_m, self.hi_m, self.step_m, self.clearance_m)


class BlastParams(StrictParams):
    """Surface, nozzle, sequencer, obstacles and robot base of one blasting plan."""

    seed_surface: int | None = Field(
        1, ge=1, le=3, description="the seed's scene surface 1–3 (used without polygon / cloud_id)"
    )
    polygon: PolygonSurface | None = Field(None, description="surface as a polygon on a plane")
    cloud_id: str | None = Field(None, description="id of a stored cloud (world frame, m)")
    # Sequential RANSAC finds at most 10 planes; a larger index is told so by the planner.
    plane_index: int = Field(
        0, ge=0, le=99, description="plane of the cloud to blast (0 = largest)"
    )
    plane_threshold_m: float = Field(0.01, gt=0, le=1.0, description="RANSAC inlier distance (m)")
    nozzle: Literal["small", "medium", "large"] = Field(
        "medium", description="Boride T159 size (Table 3.1)"
    )
    stream_length_mm: StreamMm = Field(
        300.0, description="nozzle-to-surface stream length, 100–500 mm"
    )
    disc_radius_m: float | None = Field(
        scenes.DISC_RADIUS_M,
        gt=0,
        le=0.5,
        description="disc radius (m); None: Eq. 3.1 (seed §4.2.1 uses 0.04)",
    )
    fill_stream_mm: StreamMm | None = Field(
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
    obstacle_cloud_id: str | None = Field(
        None,
        description="id of a stored cloud whose points off the surface's plane are obstacles "
        "(with polygon: e.g. the scan of the structure a finding's surface is on)",
    )
    base_search: BaseSearch | None = Field(
        None, description="search the base in a region (then robot_base_m is not used)"
    )
    robot_base_m: list[Coordinate] = Field(
        [v / 1000.0 for v in scenes.ROBOT_BASE_MM], min_length=3, max_length=3,
        description="robot base position [x, y, z] (m), seed (500, 375, 370) mm",
    )  # fmt: skip
    seed: Seed = Field(0, description="random seed (GA)")
    coverage_min_pct: float = Field(99.0, ge=0, le=100, description="check: coverage (%)")
    overspray_max_pct: float = Field(
        0.5, ge=0, le=100, description="check: overspray (% of the surface)"
    )
    ik_residual_max_mm: float = Field(
        0.1, gt=0, le=100.0, description="check: IK position residual (mm)"
    )

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
    if p.base_search is not None:
        p.base_search.build()


def _surface(p: BlastParams, ctx: JobContext) -> Surface | PlanePick:
    """The surface to blast, or the cloud (loaded here) and which plane of it."""
    if p.polygon is not None:
        return p.polygon.build()
    if p.cloud_id is None:
        return scenes.bridge_surface(int(p.seed_surface or 1))
    cloud = np.asarray(ctx.load_cloud(p.cloud_id), dtype=float)
    return PlanePick(cloud, p.plane_index, p.plane_threshold_m, p.cloud_obstacles)


def run(p: BlastParams, ctx: JobContext) -> KindOutput:
    from robots import load_robot
    from robots.denso_vm6083 import DensoVM6083

    arm = load_robot(ROBOT)
    # ROBOT names the DENSO arm; its loader returns DensoVM6083 (with_base is its own)
    assert isinstance(arm, DensoVM6083)
    obstacles = _channel() if p.obstacles is None else p.obstacles
    options = BlastOptions(
        nozzle=p.nozzle, stream_length_mm=p.stream_length_mm, disc_radius_m=p.disc_radius_m,
        fill_stream_mm=p.fill_stream_mm, editing=p.editing, sequencer=p.sequencer, seed=p.seed,
    )  # fmt: skip
    limits = BlastLimits(
        coverage_min=p.coverage_min_pct / 100.0,
        overspray_max=p.overspray_max_pct / 100.0,
        ik_residual_max_mm=p.ik_residual_max_mm,
    )
    try:
        r = plan_blast_result(
            _surface(p, ctx), arm, robot_base_m=p.robot_base_m,
            boxes=[Box.from_bounds(b.lo_m, b.hi_m, b.name) for b in obstacles],
            options=options, limits=limits, progress=ctx.progress,
            obstacle_points=(
                None if p.obstacle_cloud_id is None else ctx.load_cloud(p.obstacle_cloud_id)
            ),
            base_search=None if p.base_search is None else p.base_search.build(),
        )  # fmt: skip
    except NoPlaneError as exc:
        if p.cloud_id is None:
            raise
        raise NoPlaneError(f"{exc} (cloud {p.cloud_id})") from exc
    return KindOutput.from_result(r)


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
