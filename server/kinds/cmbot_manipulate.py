"""``cmbot.manipulate``: CMBOT's 7-DoF arm tracks a maintenance trajectory
while avoiding the guardrail, its brackets and its own climbing mechanism
(seed 002 §3.2, Eq. 12–20, and the §4 experiment, Eq. 21–26).

The tool follows the seed's 20 s test trajectory from (0, 820, −2790 mm,
0°, 0°, −90°) in frame (6) with the gradient-projection solution and the
escape velocities of covering spheres against cuboids (GJK distances).  The
simulation gate replays the motion at fine steps — tracking, joint limits
and speeds, clearance to the environment and to itself, static joint torques
— and a failed check rejects the plan.  When the arm would pass too close,
the plan proposes the nearest base position along the guardrail for which
the whole motion passes (the seed's remedy).  See docs/cmbot.md.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

import numpy as np
from pydantic import Field

from planners.cmbot import SEED_WORK_REAR_X, AvoidanceParams, ExperimentParams, Section4Trajectory
from planners.cmbot.manipulate_plan import plan_manipulation_result
from planners.errors import InvalidInputError
from server.kinds.base import JobContext, KindOutput, Offset, PlanKind, PlanView, StrictParams
from server.kinds.cmbot_params import ROBOT, GuardrailSpec

#: A tool position in frame (6), mm: the arm reaches about a metre; 10 m is generous.
ToolMm = Annotated[float, Field(ge=-10_000.0, le=10_000.0)]
#: A tool angle, degrees: one turn either way.
ToolDeg = Annotated[float, Field(ge=-360.0, le=360.0)]


class CmbotManipulateParams(StrictParams):
    """Work stance, trajectory reading, avoidance and gate limits of one arm motion."""

    guardrail: GuardrailSpec = Field(default_factory=GuardrailSpec, description="the guardrail")
    rear_foot_x_m: Offset = Field(
        SEED_WORK_REAR_X, description="rear sole of the work stance, metres"
    )
    start_mm_deg: tuple[ToolMm, ToolMm, ToolMm, ToolDeg, ToolDeg, ToolDeg] = Field(
        (0.0, 820.0, -2790.0, 0.0, 0.0, -90.0),
        description="tool start pose in frame (6): x, y, z in mm, roll, pitch, yaw in deg (seed §4)",
    )
    angular_unit: Literal["mrad", "deg"] = Field(
        "mrad", description="unit of Eq. 24–26 (mrad/s: consistent reading; deg/s: as printed)"
    )
    avoidance: bool = Field(True, description="add the escape term of Eq. 15–20")
    compare_without_avoidance: bool = Field(
        True, description="also simulate the motion without the escape term (console plot)"
    )
    d_s_m: float = Field(0.15, gt=0, le=1.0, description="Eq. 15 safety threshold d_s")
    v_max_m_s: float = Field(0.3, gt=0, le=2.0, description="Eq. 15 maximum escape speed")
    min_clearance_m: float = Field(
        0.05, ge=0, le=1.0, description="check: clearance the gate requires (< d_s, docs/cmbot.md)"
    )
    payload_kg: float = Field(2.0, ge=0, le=10.0, description="tool mass at Q for the torque check")
    dt_s: float = Field(0.01, gt=0.001, le=0.05, description="control step of the tracking loop")
    relocate: bool = Field(True, description="propose the nearest passing base when a check fails")
    max_shift_m: float = Field(0.5, ge=0, le=3.0, description="farthest base shift tried")
    shift_step_m: float = Field(0.1, gt=0.01, le=1.0, description="base shift step")


def _params(p: CmbotManipulateParams) -> ExperimentParams:
    return ExperimentParams(
        trajectory=Section4Trajectory(start_mm_deg=p.start_mm_deg, angular_unit=p.angular_unit),
        avoidance=AvoidanceParams(d_s=p.d_s_m, v_max=p.v_max_m_s),
        min_clearance_m=p.min_clearance_m,
        dt_s=p.dt_s,
        payload_kg=p.payload_kg,
    )


def validate(p: CmbotManipulateParams) -> None:
    """Cheap: the work stance must stand on valid footholds (HTTP 422 if not)."""
    from robots import load_robot

    g = p.guardrail.build()
    c = load_robot(ROBOT).params["climber"]
    for x in (p.rear_foot_x_m, p.rear_foot_x_m + c["work_foot_distance_m"]):
        why = g.why_invalid(x, c["foot_length_m"])
        if why:
            raise InvalidInputError(
                f"rear_foot_x_m = {p.rear_foot_x_m} m is not a valid work stance: {why}"
            )


def run(p: CmbotManipulateParams, ctx: JobContext) -> KindOutput:
    from robots import load_robot

    r = plan_manipulation_result(
        load_robot(ROBOT),
        guardrail=p.guardrail.build(),
        rear_foot_x=p.rear_foot_x_m,
        params=_params(p),
        avoidance=p.avoidance,
        compare=p.compare_without_avoidance,
        relocate=p.relocate,
        max_shift_m=p.max_shift_m,
        shift_step_m=p.shift_step_m,
        progress=ctx.progress,
    )
    return KindOutput.from_result(r)


def compile_program(plan: PlanView) -> list[dict[str, Any]]:
    """Timed way-points of J1…J12 every 0.1 s (the climbing joints J1…J5 held
    in the work stance, the arm J6…J12 as simulated); the nozzle works on the
    straight line of Eq. 21–26 (t ≥ 5 s) and closes at the end."""
    from robots import load_robot
    from robots.cmbot import CmbotModel
    from robots.protocol.commands import JointMove, Nozzle, Stop

    t = plan.array("times")
    arm = plan.array("q")
    model = load_robot("cmbot")
    # the CMBOT loader returns CmbotModel (stance_climber_q is its own)
    assert isinstance(model, CmbotModel)
    stance = model.stance_climber_q()
    q = np.hstack([np.tile(stance, (len(arm), 1)), arm])
    idx = np.unique(
        np.r_[np.arange(0, len(t), max(1, round(0.1 / max(t[1] - t[0], 1e-6)))), len(t) - 1]
    )
    cmds: list[Any] = []
    on = False
    prev = 0.0
    for i in idx:
        if not on and t[i] >= 5.0:
            cmds.append(Nozzle(True))
            on = True
        cmds.append(JointMove(tuple(float(v) for v in q[i]), float(t[i] - prev) if cmds else 0.0))
        prev = float(t[i])
    if on:
        cmds.append(Nozzle(False))
    cmds.append(Stop())
    return [c.to_dict() for c in cmds]


KIND = PlanKind(
    name="cmbot.manipulate",
    title="CMBOT: arm maintenance motion with obstacle avoidance",
    description=__doc__ or "",
    params_model=CmbotManipulateParams,
    run=run,
    validate=validate,
    robot=ROBOT,
    compile=compile_program,
)
