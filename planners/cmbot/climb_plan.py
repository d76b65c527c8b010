"""One entry point for the ``cmbot.climb`` kind: the inchworm
walk along the guardrail (:func:`planners.cmbot.climb.plan_climb`, seed 002
§3.1, Eq. 1–11) with its simulation gate, in the stored form — phases and
their magnet / limiting-plate commands, footholds, chain limits, the gate's
checks and violations, the flip-torque (Eq. 9) and joint plots, the sampled
trajectory arrays and the flat metrics.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from planners.cmbot.climb import ClimbPlan, plan_climb
from planners.cmbot.gait import GaitParams
from planners.cmbot.guardrail import Guardrail
from planners.cmbot.report import (
    PLOT_SAMPLES,
    finite_metrics,
    gate_checks,
    gate_summary,
    guardrail_summary,
    violations_summary,
)
from planners.errors import InvalidInputError
from planners.result import Check, PlanResult
from planners.summary import json_safe, plot, thin


def plan_climb_result(
    robot: Any,
    *,
    guardrail: Guardrail,
    start_rear_x: float,
    goal_rear_x: float,
    params: GaitParams,
    progress: Callable[[float, str], None] | None = None,
) -> PlanResult:
    """Plan and simulate the walk from the contracted stance at
    ``start_rear_x`` to the one at ``goal_rear_x`` (rear-sole positions along
    the bar, metres) and shape it for storage.

    ``robot`` is the CMBOT model (``robots.load_robot("cmbot")``; its
    ``urdf_joint_names`` name the stored joints).  Summary keys: guardrail,
    footholds, phases, limits, violations, gate, plots, joint_names.  Arrays:
    times (T,), q (T,6), rear and front sole positions (T,3), support (T,)
    int8, flip_Nm and flip_no_cw_Nm (T,2).  Checks: ``footholds`` (every sole
    on a bar segment and off the posts) then the gate's.  Raises what
    :func:`~planners.cmbot.climb.plan_climb` raises.
    """
    plan = plan_climb(
        robot,
        guardrail=guardrail,
        start_rear_x=start_rear_x,
        goal_rear_x=goal_rear_x,
        params=params,
        simulate=True,
        progress=progress,
    )
    if progress is not None:
        progress(0.95, "storing")
    return climb_result(plan, list(robot.urdf_joint_names))


def _plots(plan: ClimbPlan) -> list[dict[str, Any]]:
    tr = plan.trajectory
    sup = tr.support > 0
    k = thin(len(tr.times), PLOT_SAMPLES)
    hold = plan.metrics["magnet_holding_moment_Nm"]
    return [
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


def _phases(plan: ClimbPlan) -> list[dict[str, Any]]:
    return [
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


def climb_result(plan: ClimbPlan, joint_names: list[str]) -> PlanResult:
    """The stored form of a simulated :class:`ClimbPlan` (see :func:`plan_climb_result`)."""
    gate = plan.gate
    if gate is None:
        raise InvalidInputError("the climb plan has no simulation-gate report (simulate=False)")
    g, tr, lim = plan.guardrail, plan.trajectory, plan.limits
    soles = np.array(plan.footholds).ravel()
    checks = [
        Check(
            name="footholds",
            passed=bool(np.all(g.valid_foothold(soles, lim.foot_length))),
            value=len(plan.footholds),
            limit=None,
            message=f"{len(plan.footholds)} stances, every sole on a bar segment and off the posts; "
            f"steps ≤ {lim.max_step:.3f} m",
        ),
        *gate_checks(gate),
    ]
    summary = {
        "guardrail": guardrail_summary(g),
        "footholds": plan.footholds,
        "phases": _phases(plan),
        "limits": {
            "d_min_m": lim.d_min,
            "d_max_m": lim.d_max,
            "d_work_m": lim.d_work,
            "max_step_m": lim.max_step,
        },
        "violations": violations_summary(gate),
        "gate": gate_summary(gate),
        "plots": _plots(plan),
        "joint_names": joint_names,
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
    metrics = finite_metrics(plan.metrics)
    metrics["gate_samples"] = float(gate.samples)
    return PlanResult(json_safe(summary), arrays, checks, metrics)
