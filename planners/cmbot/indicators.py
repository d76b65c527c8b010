"""Checks of the seed's §2.1 design indicators against the chosen CMBOT design.

* mass < 100 kg — sum of the URDF link masses;
* crosses a 10 cm gap — a walk across a 10 cm gap with posts beside it passes the gate;
* the arm's workspace covers a 1540 × 1100 × 1500 mm cuboid — position IK on a grid;
* 5 kg at the end — static joint torques within 150 N·m over that cuboid;
* climbing ≥ 0.1 m/s — the fastest walk on a plain bar that passes the gate;
* end effector ≥ 0.3 m/s — the §4 motion's tool speed with every joint within its limit.

The cuboid's placement is chosen (the seed gives only its size): 1540 mm
along the bar centred on the arm base, 1100 mm across from 0.05 m to 1.15 m
inboard of the arm base, 1500 mm high from the walkway up; i.e. the guardrail
bay on the work side.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from planners.cmbot.arm import ArmKinematics
from planners.cmbot.gait import GaitParams, build_trajectory, chain_limits, plan_footholds
from planners.cmbot.guardrail import Guardrail, GuardrailParams
from planners.cmbot.scene import arm_scene
from planners.cmbot.simulate import simulate_climb


def robot_mass(model: Any) -> float:
    """Total robot mass [kg] (URDF inertials, payload excluded)."""
    return float(model.total_mass)


def workspace_cuboid(model: Any, n: tuple[int, int, int] = (5, 4, 5)) -> np.ndarray:
    """Grid points (N,3) of the §2.1 cuboid in the arm base frame (6) (placement: module doc)."""
    dims = np.asarray(model.params["indicators"]["workspace_cuboid_m"], dtype=float)
    gp = GuardrailParams()
    scene = arm_scene(model, Guardrail(np.array([[-5.0, 5.0]]), np.array([])), 0.0)
    T = scene.T_world_base
    # world ranges: along the bar around the base, across inboard (−y), up from the walkway
    x0 = T[0, 3]
    y0 = T[1, 3]
    xs = np.linspace(x0 - dims[0] / 2, x0 + dims[0] / 2, n[0])
    ys = np.linspace(y0 - 0.05 - dims[1], y0 - 0.05, n[1])
    zs = np.linspace(-gp.rail_height_m, -gp.rail_height_m + dims[2], n[2])
    W = np.stack(np.meshgrid(xs, ys, zs, indexing="ij"), axis=-1).reshape(-1, 3)
    Tinv = np.linalg.inv(T)
    return W @ Tinv[:3, :3].T + Tinv[:3, 3]


def position_ik(
    arm: ArmKinematics,
    points: np.ndarray,
    *,
    seeds: int = 12,
    iters: int = 300,
    seed: int = 0,
    tol: float = 1e-4,
) -> tuple[np.ndarray, np.ndarray]:
    """Position-only damped-least-squares IK, batched over points × random seeds.

    Returns every converged joint vector (N,seeds,7) and the mask (N,seeds).
    """
    rng = np.random.default_rng(seed)
    lo, hi = arm.limits[:, 0], arm.limits[:, 1]
    N = len(points)
    q = rng.uniform(np.maximum(lo, -np.pi), np.minimum(hi, np.pi), size=(N, seeds, arm.dof))
    target = np.repeat(points[:, None, :], seeds, axis=1)
    lam2 = 1e-4
    for _ in range(iters):
        F = arm.frames(q)
        e = target - F[..., -1, :3, 3]
        J = arm.jacobian_from_frames(F)[..., :3, :]
        JJt = J @ np.swapaxes(J, -1, -2) + lam2 * np.eye(3)
        dq = np.einsum("...ji,...j->...i", J, np.linalg.solve(JJt, e[..., None])[..., 0])
        norm = np.linalg.norm(dq, axis=-1, keepdims=True)
        dq *= np.minimum(1.0, 0.3 / np.maximum(norm, 1e-12))
        q = np.clip(q + dq, lo, hi)
    err = np.linalg.norm(target - arm.tool_pose(q)[..., :3, 3], axis=-1)
    return q, err < tol


@dataclass(frozen=True)
class WorkspaceResult:
    """Cuboid points, whether each is reachable, and the payload capacity [kg]
    (largest tool load with every static joint torque ≤ the limit) of the best
    reaching configuration."""

    points: np.ndarray
    reachable: np.ndarray
    capacity_kg: np.ndarray


def workspace_and_payload(
    model: Any, n: tuple[int, int, int] = (5, 4, 5), seeds: int = 12
) -> WorkspaceResult:
    """Reachability and payload capacity over the cuboid grid (gravity of the work stance)."""
    arm = ArmKinematics.from_model(model)
    pts = workspace_cuboid(model, n)
    q, ok = position_ik(arm, pts, seeds=seeds)
    g = arm_scene(model, Guardrail(np.array([[-5.0, 5.0]]), np.array([])), 0.0).gravity
    limit = model.params["indicators"]["joint_torque_Nm"]
    tau0 = arm.gravity_torques(q, g, 0.0)
    tau1 = arm.gravity_torques(q, g, 1.0) - tau0  # torque per kg at the tool
    with np.errstate(divide="ignore", invalid="ignore"):
        # largest m with |τ0 + m·τ1| ≤ limit for every joint
        cap_j = np.where(
            np.abs(tau1) > 1e-12, (limit - np.sign(tau1) * tau0) / np.abs(tau1), np.inf
        )
    cap_j = np.where(np.abs(tau0) > limit, -np.inf, cap_j)
    cap = np.where(ok, cap_j.min(axis=-1), -np.inf).max(axis=1)
    return WorkspaceResult(pts, np.asarray(ok.any(axis=1)), cap)


@dataclass(frozen=True)
class ClimbSpeedResult:
    speed_m_s: float
    step_m: float
    phase_time_s: float
    counterweight: bool
    tried: list[tuple[float, float, bool, float, bool]]


def fastest_climb(
    model: Any,
    steps: int = 6,
    step_m: tuple[float, ...] = (0.30, 0.33),
    phase_time_s: tuple[float, ...] = (1.2, 1.1, 1.0, 0.95),
    switch_time_s: float = 0.1,
) -> ClimbSpeedResult:
    """The fastest straight walk on a plain bar that passes the simulation gate.

    Speed = distance / duration of a ``steps``-step walk (start and end in the
    work stance, all magnet, plate and counterweight actions included).
    """
    best = ClimbSpeedResult(0.0, 0.0, 0.0, False, [])
    tried = []
    for S in step_m:
        for cw in (True, False):
            for Tb in phase_time_s:
                p = GaitParams(
                    max_step_m=S,
                    phase_time_s=Tb,
                    switch_time_s=switch_time_s,
                    counterweight=cw,
                    dt_s=0.01,
                )
                g = Guardrail(np.array([[0.0, 2.0 + steps * S]]), np.array([]))
                lim = chain_limits(model, p)
                moves = plan_footholds(g, 0.5, 0.5 + steps * S, lim, 0.005)
                _, tr = build_trajectory(model, moves, 0.5, p)
                ok = simulate_climb(model, g, tr).passed
                v = steps * S / float(tr.times[-1])
                tried.append((S, Tb, cw, v, ok))
                if ok and v > best.speed_m_s:
                    best = ClimbSpeedResult(v, S, Tb, cw, [])
    return ClimbSpeedResult(
        best.speed_m_s, best.step_m, best.phase_time_s, best.counterweight, tried
    )
