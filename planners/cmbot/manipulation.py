"""Arm maintenance motions: the §4 experiment, the simulation gate and the
base relocation remedy (seed §3.2, §4).

:func:`plan_manipulation` tracks the Eq. 21–26 trajectory from the robot's
work stance, simulates the result (:func:`~planners.cmbot.simulate.simulate_arm`)
and, when a check fails, proposes the nearest base position along the
guardrail for which the whole motion passes — the seed's remedy ("the
operator will adjust the position of the base by the climbing mechanism").
The task stays fixed on the structure, so a base shift Δ along the bar moves
the trajectory by −Δ along y of frame (6).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from planners.cmbot.arm import ArmKinematics
from planners.cmbot.experiment import ArmRun, ExperimentParams, start_configuration, track
from planners.cmbot.guardrail import Guardrail, seed_guardrail
from planners.cmbot.scene import ArmScene, arm_scene
from planners.cmbot.simulate import GateReport, simulate_arm
from planners.errors import InvalidInputError, PlannerError

#: Rear-foot position [m] of the §4 work stance on :func:`seed_guardrail` (chosen).
SEED_WORK_REAR_X = 8.0


@dataclass
class BaseProposal:
    """Nearest base position whose motion passes every check (or none found)."""

    rear_foot_x: float | None
    shift_m: float | None
    run: ArmRun | None
    gate: GateReport | None
    tried: list[tuple[float, str]] = field(default_factory=list)


@dataclass
class ManipulationPlan:
    """One planned arm motion with its simulation-gate report."""

    rear_foot_x: float
    scene: ArmScene
    params: ExperimentParams
    q_start: np.ndarray
    run: ArmRun
    gate: GateReport
    proposal: BaseProposal | None = None
    comparison: ArmRun | None = None  # the same motion without the avoidance term
    comparison_gate: GateReport | None = None
    metrics: dict[str, float] = field(default_factory=dict)


def _plan_at(
    model: Any,
    arm: ArmKinematics,
    guardrail: Guardrail,
    rear_x: float,
    params: ExperimentParams,
    shift: float,
    avoidance: bool,
    dt: float,
    progress: Callable[[float, str], None] | None = None,
) -> tuple[ArmScene, ExperimentParams, np.ndarray, ArmRun, GateReport]:
    traj = replace(params.trajectory, offset_m=(0.0, -shift, 0.0))
    p = replace(params, trajectory=traj)
    scene = arm_scene(model, guardrail, rear_x)
    q0 = start_configuration(model, traj, p.q_ready_deg)
    run = track(
        arm,
        scene.boxes,
        traj,
        q0,
        avoidance=p.avoidance if avoidance else None,
        dt=dt,
        gain=p.gain,
        progress=progress,
    )
    gate = simulate_arm(
        arm,
        scene.boxes,
        traj,
        run.times,
        run.q,
        gravity=scene.gravity,
        payload_kg=p.payload_kg,
        min_clearance_m=p.min_clearance_m,
    )
    return scene, p, q0, run, gate


def run_metrics(run: ArmRun, gate: GateReport, prefix: str = "") -> dict[str, float]:
    """Flat metrics (units in the names) of one run and its gate."""
    v = np.linalg.norm(np.gradient(run.tool_pos, run.times, axis=0), axis=1)
    by = {c.name: c for c in gate.checks}
    out = {
        "max_tracking_error_mm": float(by["tracking"].value)
        if "tracking" in by
        else float(run.pos_error.max() * 1e3),
        "min_clearance_m": float(by["clearance"].value)
        if "clearance" in by
        else float(run.clearance.min()),
        "max_tool_speed_m_s": float(v.max()),
        "max_joint_speed_ratio": float(by["joint_speeds"].value)
        if "joint_speeds" in by
        else float("nan"),
        "max_joint_torque_Nm": float(by["joint_torque"].value)
        if "joint_torque" in by
        else float("nan"),
        "duration_s": float(run.times[-1]),
        "failed_checks": float(len(gate.failed())),
    }
    return {prefix + k: val for k, val in out.items()}


def plan_manipulation(
    robot: Any,
    *,
    guardrail: Guardrail | None = None,
    rear_foot_x: float = SEED_WORK_REAR_X,
    params: ExperimentParams | None = None,
    avoidance: bool = True,
    compare: bool = False,
    relocate: bool = True,
    max_shift_m: float = 1.0,
    shift_step_m: float = 0.05,
    progress: Callable[[float, str], None] | None = None,
) -> ManipulationPlan:
    """Plan, simulate and (if needed) relocate the §4 arm motion (seed §3.2, §4).

    ``robot`` is the CMBOT model (``robots.load_robot("cmbot")``); the robot
    stands in its work stance with the rear sole at ``rear_foot_x`` on
    ``guardrail`` (default: the seed sample scene).  ``compare`` also runs the
    motion without the avoidance term (Eq. 14 with Z = 0).  When the gate
    fails and ``relocate`` is set, base positions up to ``max_shift_m`` away
    (valid stances only, nearest first) are simulated until one passes.
    """
    g = guardrail or seed_guardrail()
    p = params or ExperimentParams()
    if not (np.isfinite(rear_foot_x) and max_shift_m >= 0 and shift_step_m > 0):
        raise InvalidInputError("rear_foot_x must be finite, max_shift_m ≥ 0 and shift_step_m > 0")
    L = robot.params["climber"]["foot_length_m"]
    d0 = robot.params["climber"]["work_foot_distance_m"]
    for x in (rear_foot_x, rear_foot_x + d0):
        why = g.why_invalid(x, L)
        if why:
            raise InvalidInputError(
                f"rear_foot_x = {rear_foot_x:.3f} m is not a valid work stance: {why}"
            )
    arm = ArmKinematics.from_model(robot)

    def prog(f: float, stage: str) -> None:
        if progress is not None:
            progress(f, stage)

    prog(0.0, "tracking")
    scene, pp, q0, run, gate = _plan_at(
        robot,
        arm,
        g,
        rear_foot_x,
        p,
        0.0,
        avoidance,
        p.dt_s,
        progress=lambda f, s: prog(0.4 * f, s),
    )
    plan = ManipulationPlan(rear_foot_x, scene, pp, q0, run, gate)
    plan.metrics.update(run_metrics(run, gate))
    if compare:
        prog(0.45, "comparison without avoidance")
        _, _, _, run0, gate0 = _plan_at(robot, arm, g, rear_foot_x, p, 0.0, not avoidance, p.dt_s)
        plan.comparison, plan.comparison_gate = run0, gate0
        plan.metrics.update(
            run_metrics(run0, gate0, "without_avoidance_" if avoidance else "with_avoidance_")
        )
    if not gate.passed and relocate:
        prog(0.6, "relocating base")
        plan.proposal = propose_base(
            robot, arm, g, rear_foot_x, p, avoidance, max_shift_m, shift_step_m, prog
        )
        if plan.proposal.rear_foot_x is not None:
            plan.metrics["proposed_rear_foot_x_m"] = plan.proposal.rear_foot_x
            plan.metrics["proposed_shift_m"] = float(plan.proposal.shift_m or 0.0)
    prog(1.0, "done")
    return plan


def propose_base(
    robot: Any,
    arm: ArmKinematics,
    guardrail: Guardrail,
    rear_x: float,
    params: ExperimentParams,
    avoidance: bool,
    max_shift_m: float,
    step_m: float,
    progress: Callable[[float, str], None],
) -> BaseProposal:
    """Nearest valid work stance whose whole motion passes the gate (seed §4 remedy)."""
    L = robot.params["climber"]["foot_length_m"]
    d0 = robot.params["climber"]["work_foot_distance_m"]
    n = int(np.floor(max_shift_m / step_m + 1e-9))
    shifts = sorted(
        {round(k * step_m, 9) for k in range(-n, n + 1) if k != 0}, key=lambda s: (abs(s), s)
    )
    tried: list[tuple[float, str]] = []
    for i, s in enumerate(shifts):
        x = rear_x + s
        if not guardrail.valid_foothold(np.array([x, x + d0]), L).all():
            continue
        progress(0.6 + 0.4 * i / max(len(shifts), 1), f"trying base at {x:.2f} m")
        try:
            _, _, _, run, gate = _plan_at(
                robot, arm, guardrail, x, params, s, avoidance, params.dt_s
            )
        except PlannerError as exc:
            tried.append((x, str(exc)))
            continue
        tried.append((x, gate.summary()))
        if gate.passed:
            return BaseProposal(x, s, run, gate, tried)
    return BaseProposal(None, None, None, None, tried)
