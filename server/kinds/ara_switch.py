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

from typing import Annotated, Any

import numpy as np
from pydantic import Field

from planners.errors import InvalidInputError
from planners.switching import SwitchingParams
from planners.switching.jump import JumpParams
from planners.switching.scenes import SCENES, make_scene
from planners.switching.switch_result import plan_switch_result
from server.kinds.base import JobContext, KindOutput, PlanKind, PlanView, Seed, StrictParams

SAMPLE_PREFIX = "switch_"

#: An entry of the camera→base transform: rotation entries lie in [-1, 1], and
#: a camera on the robot sits well within 10 m of its base.
TransformEntry = Annotated[float, Field(ge=-10.0, le=10.0)]


class AraSwitchParams(StrictParams):
    """Scan, robot base and tolerances of an ARA switching decision + jump."""

    cloud_id: str | None = Field(
        None, description="id of a stored cloud (POST /clouds), camera frame, metres"
    )
    sample: str = Field(
        "perpendicular",
        description=f"synthetic scan when no cloud_id: one of {', '.join(SCENES)}",
        # Listed in the schema so the console offers a choice; refused with
        # the list of names in validate() (a 422 naming the samples).
        json_schema_extra={"enum": list(SCENES)},
    )
    sample_seed: Seed = Field(0, description="noise seed of the synthetic scan")
    camera_to_base: list[list[TransformEntry]] | None = Field(
        None, description="4×4 camera→base transform (None: the ARA's, from its URDF)"
    )
    # The depth camera sees a few metres: a standing surface is within 10 m.
    base_height_m: float = Field(
        0.0, ge=-10.0, le=10.0, description="height of the standing surface in the base frame"
    )
    height_tolerance_m: float = Field(0.005, gt=0, le=0.5, description="Eq. 3.4 'equal' tolerance")
    distance_tolerance: float = Field(0.02, gt=0, lt=1, description="Alg. 2 t (relative)")
    n_closest: int = Field(5, ge=1, le=50, description="Alg. 2 n (rectangles tried)")
    m_neighbours: int = Field(3, ge=1, le=20, description="Alg. 2 m")
    sliding_factor_m: float = Field(0.01, gt=0, le=0.2, description="NCBE slice width αs")
    voxel_m: float = Field(0.01, gt=0, le=0.1, description="voxel grid edge")
    reach_m: float = Field(
        0.5, gt=0, le=10.0, description="max foothold distance from the base origin"
    )
    plan_jump: bool = Field(True, description="plan the inch-worm jump when the mode is inchworm")
    clearance_margin_m: float = Field(
        0.01, ge=0, le=1.0, description="required clearance along the jump"
    )
    attempts: int = Field(4, ge=1, le=20, description="RRT-Connect restarts per phase")
    seed: Seed = Field(0, description="seed of RANSAC and the RRT samples")


def validate(p: AraSwitchParams) -> None:
    if p.cloud_id is None and p.sample not in SCENES:
        raise InvalidInputError(f"unknown sample {p.sample!r}; samples: {', '.join(SCENES)}")
    if p.camera_to_base is not None and np.asarray(p.camera_to_base).shape != (4, 4):
        raise InvalidInputError("camera_to_base must be a 4×4 matrix (list of 4 rows)")


def _robot():
    from robots import load_robot

    return load_robot("ara")


def run(p: AraSwitchParams, ctx: JobContext) -> KindOutput:
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
    jump = JumpParams(clearance_margin_m=p.clearance_margin_m, attempts=p.attempts, seed=p.seed)
    r = plan_switch_result(
        ara,
        points,
        camera_to_base=T,
        base_height=p.base_height_m,
        foot=foot,
        params=sp,
        jump=jump if p.plan_jump else None,
        progress=ctx.progress,
    )
    ctx.progress(1.0, "done")
    return KindOutput.from_result(r)


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
