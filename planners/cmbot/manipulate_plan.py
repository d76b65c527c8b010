"""One entry point for the ``cmbot.manipulate`` kind: the §4
arm motion (:func:`planners.cmbot.manipulation.plan_manipulation`, seed 002
§3.2, Eq. 12–20, and the §4 experiment, Eq. 21–26) with its simulation gate
and base-relocation proposal, in the stored form — the scene (guardrail,
cuboids, base pose, work stance), the gate's checks and violations, the
proposal as a failed ``base_position`` check, the clearance / tracking /
joint plots, the run's arrays and the flat metrics.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from planners.cmbot.experiment import ExperimentParams
from planners.cmbot.guardrail import Guardrail
from planners.cmbot.manipulation import ManipulationPlan, plan_manipulation
from planners.cmbot.report import (
    PLOT_SAMPLES,
    boxes_summary,
    finite_metrics,
    gate_checks,
    gate_summary,
    guardrail_summary,
    violations_summary,
)
from planners.cmbot.scene import work_stance
from planners.result import Check, PlanResult
from planners.summary import json_safe, plot, thin

#: the arm's joints J6…J12 (the climbing chain is J1…J5)
ARM_JOINT_NAMES = [f"J{i}" for i in range(6, 13)]


def plan_manipulation_result(
    robot: Any,
    *,
    guardrail: Guardrail,
    rear_foot_x: float,
    params: ExperimentParams,
    avoidance: bool = True,
    compare: bool = True,
    relocate: bool = True,
    max_shift_m: float = 0.5,
    shift_step_m: float = 0.1,
    progress: Callable[[float, str], None] | None = None,
) -> PlanResult:
    """Plan, simulate and (if the gate fails and ``relocate``) relocate the §4
    arm motion from the work stance with the rear sole at ``rear_foot_x``,
    and shape it for storage (arguments as
    :func:`~planners.cmbot.manipulation.plan_manipulation`).

    Summary keys: guardrail, rear_foot_x_m, T_world_base, q_climb,
    boxes_base_frame, q_start_deg, proposal, violations,
    comparison_violations, gate, comparison_gate, plots, joint_names.
    Arrays: times (T,), q (T,7), tool_pos and desired_pos (T,3), clearance
    and pos_error (T,), and with ``compare`` q_compare and clearance_compare.
    Checks: the gate's, then ``base_position`` (always failed: re-plan at the
    proposed base) when a relocation was searched.
    """
    plan = plan_manipulation(
        robot,
        guardrail=guardrail,
        rear_foot_x=rear_foot_x,
        params=params,
        avoidance=avoidance,
        compare=compare,
        relocate=relocate,
        max_shift_m=max_shift_m,
        shift_step_m=shift_step_m,
        progress=progress,
    )
    if progress is not None:
        progress(0.97, "storing")
    return manipulation_result(
        plan, guardrail, work_stance(robot), avoidance=avoidance, max_shift_m=max_shift_m
    )


def _plots(plan: ManipulationPlan, avoidance: bool) -> list[dict[str, Any]]:
    run = plan.run
    k = thin(len(run.times), PLOT_SAMPLES)
    label = "with avoidance" if avoidance else "without avoidance"
    series = {label: run.clearance[k]}
    if plan.comparison is not None:
        other = "without avoidance" if avoidance else "with avoidance"
        series[other] = plan.comparison.clearance[k]
    series["required clearance"] = np.full(len(k), plan.params.min_clearance_m)
    series["Eq. 15 d_s"] = np.full(len(k), plan.params.avoidance.d_s)
    t = run.times[k]
    return [
        plot(
            "minimum clearance of the arm's spheres to the cuboids",
            t, series, x_label="s", y_label="m",
        ),
        plot("tool tracking error", t, {label: run.pos_error[k] * 1e3}, x_label="s", y_label="mm"),
        plot(
            "arm joints J6–J12",
            t, {f"J{j + 6}": np.degrees(run.q[k, j]) for j in range(7)},
            x_label="s", y_label="deg",
        ),
    ]  # fmt: skip


def _proposal(plan: ManipulationPlan, max_shift_m: float) -> tuple[dict[str, Any], Check] | None:
    prop = plan.proposal
    if prop is None:
        return None
    summary = {
        "rear_foot_x_m": prop.rear_foot_x,
        "shift_m": prop.shift_m,
        "tried": [{"rear_foot_x_m": x, "outcome": s} for x, s in prop.tried],
    }
    msg = (
        f"the motion passes every check with the rear sole at {prop.rear_foot_x:.3f} m "
        f"(shift {prop.shift_m:+.3f} m): re-plan there"
        if prop.rear_foot_x is not None
        else f"no base position within ±{max_shift_m} m passes every check"
    )
    check = Check(
        name="base_position", passed=False, value=prop.rear_foot_x, limit=None, message=msg
    )
    return summary, check


def manipulation_result(
    plan: ManipulationPlan,
    guardrail: Guardrail,
    q_climb: np.ndarray,
    *,
    avoidance: bool,
    max_shift_m: float,
) -> PlanResult:
    """The stored form of a :class:`ManipulationPlan` on ``guardrail`` with the
    climbing joints ``q_climb`` (5,) of the work stance (see
    :func:`plan_manipulation_result`)."""
    run, gate, cgate = plan.run, plan.gate, plan.comparison_gate
    checks = gate_checks(gate)
    prop = _proposal(plan, max_shift_m)
    if prop is not None:
        checks.append(prop[1])
    summary = {
        "guardrail": guardrail_summary(guardrail),
        "rear_foot_x_m": plan.rear_foot_x,
        "T_world_base": plan.scene.T_world_base.tolist(),
        "q_climb": q_climb.tolist(),
        "boxes_base_frame": boxes_summary(plan.scene.boxes),
        "q_start_deg": np.degrees(plan.q_start).tolist(),
        "proposal": prop[0] if prop is not None else None,
        "violations": violations_summary(gate),
        "comparison_violations": violations_summary(cgate) if cgate else [],
        "gate": gate_summary(gate),
        "comparison_gate": cgate.summary() if cgate else None,
        "plots": _plots(plan, avoidance),
        "joint_names": list(ARM_JOINT_NAMES),
    }
    arrays = {
        "times": run.times,
        "q": run.q,
        "tool_pos": run.tool_pos,
        "desired_pos": run.desired_pos,
        "clearance": run.clearance,
        "pos_error": run.pos_error,
    }
    if plan.comparison is not None:
        arrays["q_compare"] = plan.comparison.q
        arrays["clearance_compare"] = plan.comparison.clearance
    return PlanResult(json_safe(summary), arrays, checks, finite_metrics(plan.metrics))
