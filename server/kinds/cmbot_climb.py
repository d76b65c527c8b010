"""``cmbot.climb``: CMBOT walks along the top bar of a railway-bridge
guardrail like an inchworm (seed 002 §3.1, Eq. 1–11).

Footholds avoid gaps and post joints, steps never exceed S, every phase has
its magnet / limiting-plate / counterweight command sequence, and the joint
trajectories (closed-form IK, compound-cycloid feet, Eq. 10 counterweight)
are replayed by the simulation gate at fine steps: joint limits and speeds,
foot placement, flip torque against the magnets' holding moment, clearance
of the folded arm.  Any failed gate check rejects the plan, saying where and
when.  Defaults: the seed's gait (S = 240 mm, H = 50 mm, D = 0, Tb = 10 s)
across the 10 cm gap of the sample guardrail.  See docs/cmbot.md.
"""

from __future__ import annotations

from typing import Any

from pydantic import Field

from planners.cmbot import SEED_CLIMB_GOAL_X, SEED_CLIMB_START_X, GaitParams
from planners.cmbot.climb_plan import plan_climb_result
from planners.cmbot.gait import chain_limits, plan_footholds
from server.kinds.base import JobContext, KindOutput, Offset, PlanKind, PlanView, StrictParams
from server.kinds.cmbot_params import ROBOT, GuardrailSpec


class CmbotClimbParams(StrictParams):
    """Walk of CMBOT along the guardrail: positions of the rear sole (metres)."""

    guardrail: GuardrailSpec = Field(default_factory=GuardrailSpec, description="the guardrail")
    start_rear_x_m: Offset = Field(
        SEED_CLIMB_START_X, description="rear sole at the start (contracted stance)"
    )
    goal_rear_x_m: Offset = Field(SEED_CLIMB_GOAL_X, description="rear sole at the goal")
    step_m: float = Field(0.24, gt=0, le=1.0, description="longest swing S (seed §4: 240 mm)")
    lift_m: float = Field(0.05, ge=0, le=0.3, description="swing height H (seed §4: 50 mm)")
    side_m: float = Field(0.0, ge=-0.1, le=0.1, description="sideways swing D (seed §4: 0)")
    phase_time_s: float = Field(10.0, gt=0.2, le=120.0, description="swing time Tb (seed §4: 10 s)")
    switch_time_s: float = Field(
        0.2, ge=0, le=5.0, description="magnet on/off and limiting-plate time"
    )
    counterweight: bool = Field(True, description="swing the folded arm as counterweight (Eq. 10)")
    dt_s: float = Field(0.02, gt=0.001, le=0.1, description="trajectory sample time")


def _gait(p: CmbotClimbParams) -> GaitParams:
    return GaitParams(
        max_step_m=p.step_m,
        lift_m=p.lift_m,
        side_m=p.side_m,
        phase_time_s=p.phase_time_s,
        switch_time_s=p.switch_time_s,
        dt_s=p.dt_s,
        counterweight=p.counterweight,
    )


def validate(p: CmbotClimbParams) -> None:
    """Cheap: the footholds must exist (HTTP 422 with the reason if not)."""
    from robots import load_robot

    g = p.guardrail.build()
    gp = _gait(p)
    plan_footholds(
        g, p.start_rear_x_m, p.goal_rear_x_m, chain_limits(load_robot(ROBOT), gp), gp.grid_m
    )


def run(p: CmbotClimbParams, ctx: JobContext) -> KindOutput:
    from robots import load_robot

    r = plan_climb_result(
        load_robot(ROBOT),
        guardrail=p.guardrail.build(),
        start_rear_x=p.start_rear_x_m,
        goal_rear_x=p.goal_rear_x_m,
        params=_gait(p),
        progress=ctx.progress,
    )
    return KindOutput.from_result(r)


#: Protocol channels of the electromagnets and limiting plates (rear = stance 0).
_CHANNEL = {"rear": 0, "front": 1}


def compile_program(plan: PlanView, sample_s: float = 0.1) -> list[dict[str, Any]]:
    """The walk as a command program: J1…J12 way-points every ``sample_s``
    (climbing chain and the counterweight swing of the arm), with each
    phase's magnet on/off and limiting-plate seize/release commands inserted
    at their times — after the last way-point reached by then, so a magnet
    lets go only once the other foot holds.  Foot lift/touch-down are the
    way-points themselves; range-finder checks run on the robot."""
    from robots.protocol.commands import Command, LimitingPlate, SetMagnet
    from server.kinds.programs import as_dicts, sampled_joints_with_events

    events: list[tuple[float, Command]] = []
    for ph in plan.result["phases"]:
        for c in ph["commands"]:
            dev, _, side = c["device"].partition("_")
            if dev == "magnet":
                events.append((c["t_s"], SetMagnet(_CHANNEL[side], c["action"] == "on")))
            elif dev == "plate":
                events.append((c["t_s"], LimitingPlate(_CHANNEL[side], c["action"] == "seize")))
    return as_dicts(
        sampled_joints_with_events(plan.array("times"), plan.array("q"), events, sample_s=sample_s)
    )


KIND = PlanKind(
    name="cmbot.climb",
    title="CMBOT: inchworm climb along a guardrail",
    description=__doc__ or "",
    params_model=CmbotClimbParams,
    run=run,
    validate=validate,
    robot="cmbot",
    compile=compile_program,
)
