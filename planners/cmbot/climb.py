"""Climbing plans: footholds, joint trajectories and their simulation gate (seed §3.1, §4)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from planners.cmbot.gait import (
    ChainLimits,
    GaitParams,
    GaitTrajectory,
    Phase,
    build_trajectory,
    chain_limits,
    plan_footholds,
)
from planners.cmbot.guardrail import Guardrail, seed_guardrail
from planners.cmbot.simulate import GateReport, simulate_climb
from planners.errors import InvalidInputError

#: Default walk on :func:`seed_guardrail`: across the 10 cm gap and past two posts (chosen).
SEED_CLIMB_START_X = 4.6
SEED_CLIMB_GOAL_X = 6.1


@dataclass
class ClimbPlan:
    """A walk along the guardrail: phases with their command sequences, the
    sampled joint trajectory, flip moments and the simulation-gate report."""

    guardrail: Guardrail
    start_rear_x: float
    goal_rear_x: float
    limits: ChainLimits
    params: GaitParams
    phases: list[Phase]
    trajectory: GaitTrajectory
    gate: GateReport | None
    metrics: dict[str, float] = field(default_factory=dict)

    @property
    def footholds(self) -> list[tuple[float, float]]:
        """(rear x, front x) of every stance, start included."""
        d0 = self.limits.d_work
        rear, front = self.start_rear_x, self.start_rear_x + d0
        out = [(rear, front)]
        for ph in self.phases:
            if ph.swing == "front":
                front = ph.x_to
            else:
                rear = ph.x_to
            out.append((rear, front))
        return out


def plan_climb(
    robot: Any,
    *,
    guardrail: Guardrail | None = None,
    start_rear_x: float = SEED_CLIMB_START_X,
    goal_rear_x: float = SEED_CLIMB_GOAL_X,
    params: GaitParams | None = None,
    simulate: bool = True,
    progress: Callable[[float, str], None] | None = None,
) -> ClimbPlan:
    """Walk from the contracted stance at ``start_rear_x`` to the one at
    ``goal_rear_x`` (rear-sole positions along the bar, metres).

    Raises :class:`~planners.errors.UnreachableError` when a start or goal
    foothold is invalid and :class:`~planners.errors.InfeasibleError` when no
    foothold sequence exists (the message says where the walk is blocked).
    """
    g = guardrail or seed_guardrail()
    p = params or GaitParams()
    for name, v in (("start_rear_x", start_rear_x), ("goal_rear_x", goal_rear_x)):
        if not np.isfinite(v):
            raise InvalidInputError(f"{name} must be a finite position in metres, got {v}")
    if progress:
        progress(0.0, "footholds")
    lim = chain_limits(robot, p)
    moves = plan_footholds(g, start_rear_x, goal_rear_x, lim, p.grid_m)
    if progress:
        progress(0.2, "trajectories")
    phases, traj = build_trajectory(robot, moves, start_rear_x, p)
    gate = None
    if simulate:
        if progress:
            progress(0.4, "simulation gate")
        gate = simulate_climb(robot, g, traj)
    sup = traj.support > 0
    M = np.abs(traj.flip_Nm[sup, 1]) if sup.any() else np.zeros(1)
    M0 = np.abs(traj.flip_no_cw_Nm[sup, 1]) if sup.any() else np.zeros(1)
    hold = robot.params["magnet"]["holding_force_N"] * robot.params["climber"]["foot_length_m"] / 2
    dist = abs(goal_rear_x - start_rear_x)
    metrics = {
        "walk_length_m": float(dist),
        "phases": float(len(phases)),
        "duration_s": float(traj.times[-1]),
        "max_step_m": float(max((abs(ph.step_m) for ph in phases), default=0.0)),
        "climb_speed_m_s": float(dist / traj.times[-1]) if traj.times[-1] > 0 else 0.0,
        "max_flip_torque_Nm": float(M.max()),
        "max_flip_torque_without_counterweight_Nm": float(M0.max()),
        "magnet_holding_moment_Nm": float(hold),
    }
    if progress:
        progress(1.0, "done")
    return ClimbPlan(g, start_rear_x, goal_rear_x, lim, p, phases, traj, gate, metrics)
