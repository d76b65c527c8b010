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

import math
from typing import Any

import numpy as np
from pydantic import Field, model_validator

from planners.cmbot import SEED_CLIMB_GOAL_X, SEED_CLIMB_START_X, GaitParams, plan_climb
from planners.cmbot.gait import chain_limits, plan_footholds
from planners.cmbot.guardrail import SEED_POSTS, SEED_SEGMENTS, Guardrail, GuardrailParams
from planners.summary import json_safe, plot, thin
from server.kinds.base import Check, JobContext, KindOutput, PlanKind, PlanView, StrictParams

ROBOT = "cmbot"
#: samples of a console plot (the CMBOT runs are long and fine-stepped)
PLOT_SAMPLES = 600


class GuardrailSpec(StrictParams):
    """The guardrail along which CMBOT works (defaults: the sample scene)."""

    segments_m: list[tuple[float, float]] = Field(
        default_factory=lambda: list(SEED_SEGMENTS),
        description="continuous top-bar segments [x_start, x_end] in metres, increasing",
    )
    posts_m: list[float] = Field(
        default_factory=lambda: list(SEED_POSTS), description="post centres along the bar, metres"
    )
    rail_height_m: float = Field(
        GuardrailParams.rail_height_m, gt=0.3, le=3.0, description="bar top above the walkway"
    )
    mid_rail: bool = Field(True, description="round-steel middle rail between the posts")

    @model_validator(mode="after")
    def _ordered(self) -> GuardrailSpec:
        if not self.segments_m:
            raise ValueError("segments_m needs at least one [x_start, x_end] pair")
        for a, b in self.segments_m:
            if not (math.isfinite(a) and math.isfinite(b) and b > a):
                raise ValueError(f"segment [{a}, {b}] must have x_end > x_start (metres)")
        for (_, b), (a2, _) in zip(self.segments_m, self.segments_m[1:], strict=False):
            if a2 < b:
                raise ValueError("segments_m must be increasing and must not overlap")
        return self

    def build(self) -> Guardrail:
        p = GuardrailParams(
            rail_height_m=self.rail_height_m,
            mid_rail_drop_m=GuardrailParams.mid_rail_drop_m if self.mid_rail else None,
        )
        return Guardrail(np.array(self.segments_m, float), np.array(self.posts_m, float), p)


def guardrail_result(g: Guardrail) -> dict[str, Any]:
    """What a drawer needs to redraw the guardrail."""
    p = g.params
    return {
        "segments": g.segments.tolist(),
        "posts": g.posts.tolist(),
        "gaps": g.gaps.tolist(),
        "params": {k: getattr(p, k) for k in p.__dataclass_fields__},
    }


def boxes_result(boxes: list[Any]) -> list[dict[str, Any]]:
    return [
        {
            "name": b.name,
            "group": b.group,
            "center": b.center.tolist(),
            "half": b.half.tolist(),
            "rotation": b.rotation.tolist(),
        }
        for b in boxes
    ]


def gate_checks(gate: Any, prefix: str = "") -> list[Check]:
    """The simulation gate's checks as plan checks (a failed one rejects the plan)."""
    out = []
    for c in gate.checks:
        where = [v for v in gate.violations if v.check == c.name]
        msg = c.message
        if where and "at t =" not in msg:
            msg += f" (first at t = {where[0].t_s:.3f} s: {where[0].where})"
        out.append(
            Check(
                name=prefix + c.name,
                passed=c.passed,
                value=float(c.value) if math.isfinite(c.value) else None,
                limit=float(c.limit),
                message=msg,
            )
        )
    return out


class CmbotClimbParams(StrictParams):
    """Walk of CMBOT along the guardrail: positions of the rear sole (metres)."""

    guardrail: GuardrailSpec = Field(default_factory=GuardrailSpec, description="the guardrail")
    start_rear_x_m: float = Field(
        SEED_CLIMB_START_X, description="rear sole at the start (contracted stance)"
    )
    goal_rear_x_m: float = Field(SEED_CLIMB_GOAL_X, description="rear sole at the goal")
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
    from robots.cmbot import CmbotModel

    model = load_robot(ROBOT)
    # ROBOT is CMBOT, whose loader returns CmbotModel (urdf_joint_names is its own)
    assert isinstance(model, CmbotModel)
    g = p.guardrail.build()
    plan = plan_climb(
        model,
        guardrail=g,
        start_rear_x=p.start_rear_x_m,
        goal_rear_x=p.goal_rear_x_m,
        params=_gait(p),
        progress=ctx.progress,
    )
    tr = plan.trajectory
    ctx.progress(0.95, "storing")
    sup = tr.support > 0
    k = thin(len(tr.times), PLOT_SAMPLES)
    hold = plan.metrics["magnet_holding_moment_Nm"]
    plots = [
        plot(
            "flip torque about the holding sole (Eq. 9), single support",
            tr.times[k],
            {
                "with counterweight": np.where(sup[k], np.abs(tr.flip_Nm[k, 1]), np.nan),
                "arm held vertical": np.where(sup[k], np.abs(tr.flip_no_cw_Nm[k, 1]), np.nan),
                "magnet holding moment": np.full(len(k), hold),
            },
            x_label="s",
            y_label="N·m",
        ),
        plot(
            "climbing joints J1–J5 and the counterweight J6",
            tr.times[k],
            {f"J{j + 1}": np.degrees(tr.q[k, j]) for j in range(6)},
            x_label="s",
            y_label="deg",
        ),
    ]
    phases = [
        {
            "index": ph.index,
            "kind": ph.kind,
            "swing": ph.swing,
            "x_from_m": ph.x_from,
            "x_to_m": ph.x_to,
            "step_m": ph.step_m,
            "t_start_s": ph.t_start,
            "t_lift_s": ph.t_lift,
            "t_touch_s": ph.t_touch,
            "t_end_s": ph.t_end,
            "commands": [
                {"t_s": c.t_s, "device": c.device, "action": c.action} for c in ph.commands
            ],
        }
        for ph in plan.phases
    ]
    gate = plan.gate
    # plan_climb simulates by default (simulate=True), so the gate report is there
    assert gate is not None
    checks = [
        Check(
            name="footholds",
            passed=bool(
                np.all(g.valid_foothold(np.array(plan.footholds).ravel(), plan.limits.foot_length))
            ),
            value=len(plan.footholds),
            limit=None,
            message=f"{len(plan.footholds)} stances, every sole on a bar segment and off the posts; "
            f"steps ≤ {plan.limits.max_step:.3f} m",
        ),
        *gate_checks(gate),
    ]
    result = {
        "guardrail": guardrail_result(g),
        "footholds": plan.footholds,
        "phases": phases,
        "limits": {
            "d_min_m": plan.limits.d_min,
            "d_max_m": plan.limits.d_max,
            "d_work_m": plan.limits.d_work,
            "max_step_m": plan.limits.max_step,
        },
        "violations": [vars(v) for v in gate.violations],
        "gate": {"dt_s": gate.dt_s, "samples": gate.samples, "summary": gate.summary()},
        "plots": plots,
        "joint_names": list(model.urdf_joint_names),
    }
    arrays = {
        "times": tr.times,
        "q": tr.q,
        "rear": tr.rear,
        "front": tr.front,
        "support": tr.support.astype(np.int8),
        "flip_Nm": tr.flip_Nm,
        "flip_no_cw_Nm": tr.flip_no_cw_Nm,
    }
    metrics = {k2: float(v) for k2, v in plan.metrics.items() if math.isfinite(v)}
    metrics["gate_samples"] = float(gate.samples)
    return KindOutput(result=json_safe(result), arrays=arrays, checks=checks, metrics=metrics)


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
