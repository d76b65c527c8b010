"""Box-girder wall-climber inspection pipeline (seed 003): the boustrophedon
path (§3, Fig. 4, 9) → closed-loop simulation of the corner (Eq. 1–4),
trilateration (Eq. 5), preview-follow (Eq. 6–9) and dead-reckoning
(Eq. 10–11) controllers → per-segment commands and plan checks against
:class:`Limits`.  Entry point :func:`plan_inspection`, re-exported by
:mod:`planners.sbg`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from planners.errors import InvalidInputError
from planners.result import Check, check_ge, check_le
from planners.sbg.girder import Girder, sample_girders
from planners.sbg.path import CORNER_DOWN, CORNER_UP, TURN, InspectionPath, plan_path
from planners.sbg.robot import ClimberParams
from planners.sbg.simulator import ControllerConfig, NoiseModel, SimResult, simulate

__all__ = ["InspectionPlan", "Limits", "SegmentCommand", "plan_inspection"]

DEG = math.pi / 180.0


@dataclass(frozen=True)
class Limits:
    """Acceptance limits of the checks.

    Seed figures: final centreline deviation 0.33 mm and 0.06° (§4.2).
    Chosen: camera margin ≥ 0, wheel-to-rib clearance ≥ 0, pitch
    acceleration while crossing ≤ 20°/s² (a continuous pitch rate sampled
    every 50 ms then changes by ≤ 1°/s per sample), yaw on reaching the roof
    after a U-turn ≤ 1.5° — the yaw the lane controller can take without
    swinging the camera off the welds.  The seed's §4.3 figure (< 0.1°) is
    reported beside it in the metrics, not gated on: under the stated noise
    model about a third of simulated U-turns exceed it while the lane entry
    stays safe (docs/sbg.md)."""

    final_d_m: float = 0.33e-3
    final_delta_rad: float = 0.06 * DEG
    uturn_yaw_rad: float = 1.5 * DEG
    camera_margin_m: float = 0.0
    rib_clearance_m: float = 0.0
    pitch_accel_deg_s2: float = 20.0


@dataclass(frozen=True)
class SegmentCommand:
    """What the robot is commanded over one path segment (from the
    simulation): time span, distance driven, wheel-speed range (m/s; front
    and rear for crossings), lift-arm range (rad), pitch and turn."""

    index: int
    kind: str
    lane: int
    to_lane: int
    t_start_s: float
    t_end_s: float
    distance_m: float
    v_left_mean_m_s: float
    v_right_mean_m_s: float
    wheel_speed_max_m_s: float
    arm_min_rad: float
    arm_max_rad: float
    pitch_change_rad: float
    turn_rad: float


@dataclass
class InspectionPlan:
    """Result of :func:`plan_inspection`: the planned path, the simulated run,
    per-segment commands, checks and flat metrics (units in the names)."""

    path: InspectionPath
    sim: SimResult
    commands: list[SegmentCommand]
    checks: list[Check]
    metrics: dict[str, float]
    limits: Limits = field(default_factory=Limits)

    @property
    def passed(self) -> bool:
        return all(c.passed for c in self.checks)


def _commands(path: InspectionPath, sim: SimResult) -> list[SegmentCommand]:
    A = sim.arrays
    seg = A["segment"]
    out = []
    for i, s in enumerate(path.segments):
        idx = np.flatnonzero(seg == i)
        if idx.size == 0:
            continue
        pos = A["pos"][idx]
        vl, vr = A["v_left"][idx], A["v_right"][idx]
        vf, vb = A["v_front"][idx], A["v_rear"][idx]
        wheels = np.concatenate([np.abs(v[np.isfinite(v)]) for v in (vl, vr, vf, vb)])
        pitch = A["pitch_rad"][idx]
        out.append(
            SegmentCommand(
                index=i,
                kind=s.kind,
                lane=s.lane,
                to_lane=s.to_lane,
                t_start_s=float(A["t_s"][idx[0]]),
                t_end_s=float(A["t_s"][idx[-1]] + sim.dt_s),
                distance_m=float(np.linalg.norm(np.diff(pos, axis=0), axis=1).sum()),
                v_left_mean_m_s=float(np.nanmean(vl)) if np.isfinite(vl).any() else math.nan,
                v_right_mean_m_s=float(np.nanmean(vr)) if np.isfinite(vr).any() else math.nan,
                wheel_speed_max_m_s=float(wheels.max()) if wheels.size else 0.0,
                arm_min_rad=float(A["arm_rad"][idx].min()),
                arm_max_rad=float(A["arm_rad"][idx].max()),
                pitch_change_rad=float(pitch[-1] - pitch[0])
                if s.kind in (CORNER_DOWN, CORNER_UP)
                else 0.0,
                turn_rad=s.turn_rad if s.kind == TURN else 0.0,
            )
        )
    return out


def _evaluate(
    path: InspectionPath, sim: SimResult, limits: Limits
) -> tuple[list[Check], dict[str, float]]:
    lanes, corners, uturns = sim.lanes, sim.corners, sim.uturns
    covered = sum(ln.covered for ln in lanes)
    n_lanes = path.girder.n_lanes
    margin = min((ln.worst_margin_m for ln in lanes), default=math.nan)
    clearance = min((ln.min_rib_clearance_m for ln in lanes), default=math.nan)
    fd = max((abs(ln.final_d_m) for ln in lanes), default=math.nan)
    fa = max((abs(ln.final_delta_rad) for ln in lanes), default=math.nan)
    pitch_acc = max((c.max_accel_deg_s2 for c in corners), default=0.0)
    yaw = max((abs(u.roof_yaw_rad) for u in uturns), default=0.0)
    checks = [
        Check(
            "lanes_covered",
            covered == n_lanes,
            float(covered),
            float(n_lanes),
            f"{covered} of {n_lanes} lanes driven from crossbeam to crossbeam",
        ),
        check_ge(
            "camera_margin",
            margin,
            limits.camera_margin_m,
            "worst weld margin in the camera view",
            " mm",
            scale=1e3,
        ),
        check_ge(
            "rib_clearance",
            clearance,
            limits.rib_clearance_m,
            "smallest wheel-to-rib clearance",
            " mm",
            scale=1e3,
        ),
        check_le(
            "corner_pitch_smooth",
            pitch_acc,
            limits.pitch_accel_deg_s2,
            "largest pitch acceleration while crossing a corner",
            " deg/s²",
        ),
        check_le(
            "final_centreline_offset",
            fd,
            limits.final_d_m,
            "largest final |d| at a lane end",
            " mm",
            scale=1e3,
        ),
        check_le(
            "final_yaw_deviation",
            fa,
            limits.final_delta_rad,
            "largest final |δ| at a lane end",
            " deg",
            scale=1 / DEG,
        ),
        check_le(
            "uturn_roof_yaw",
            yaw,
            limits.uturn_yaw_rad,
            "largest |yaw| on reaching the roof after a U-turn",
            " deg",
            scale=1 / DEG,
        ),
    ]
    A = sim.arrays
    metrics = {
        "lanes": float(n_lanes),
        "lanes_covered": float(covered),
        "path_length_m": path.total_length_m,
        "lane_length_total_m": path.lengths_by_kind()["lane"],
        "uturn_depth_m": path.turn_depth_m,
        "duration_s": sim.duration_s,
        "samples": float(len(A["t_s"])),
        "worst_camera_margin_mm": margin * 1e3,
        "min_weld_seen_fraction": min((ln.weld_seen_fraction for ln in lanes), default=math.nan),
        "min_rib_clearance_mm": clearance * 1e3,
        "max_final_d_mm": fd * 1e3,
        "max_final_delta_deg": fa / DEG,
        "max_abs_d_mm": max((ln.max_abs_d_m for ln in lanes), default=math.nan) * 1e3,
        "max_uturn_roof_yaw_deg": yaw / DEG,
        "uturns_under_seed_0p1deg": float(sum(abs(u.roof_yaw_rad) < 0.1 * DEG for u in uturns)),
        "uturns": float(len(uturns)),
        "max_uturn_entry_offset_mm": max((abs(u.roof_d_m) for u in uturns), default=0.0) * 1e3,
        "corner_delta_theta_deg": (corners[0].delta_theta_rad / DEG) if corners else math.nan,
        "corner_max_pitch_rate_deg_s": max((c.max_rate_deg_s for c in corners), default=0.0),
        "corner_max_pitch_rate_jump_deg_s": max(
            (c.max_rate_jump_deg_s for c in corners), default=0.0
        ),
        "corner_max_pitch_accel_deg_s2": pitch_acc,
        "corner_duration_mean_s": float(np.mean([c.duration_s for c in corners]))
        if corners
        else 0.0,
        "preview_episodes": float(sum(ln.episodes for ln in lanes)),
        "preview_m": sim.config.preview_m,
    }
    return checks, metrics


def plan_inspection(
    girder: Girder | None = None,
    robot: Any = None,
    *,
    start_lane: int = 0,
    direction: int = 1,
    start_end: int = 0,
    preview_m: float = 0.020,
    noise: NoiseModel | None = None,
    config: ControllerConfig | None = None,
    seed: int = 0,
    limits: Limits | None = None,
    progress: Callable[[float, str], None] | None = None,
) -> InspectionPlan:
    """Plan and verify a full-girder inspection (seed 003 §3–§4).

    ``girder`` defaults to ``sample_girders()["seed_lab"]``; ``robot`` is
    ``None`` (defaults), a :class:`ClimberParams`, a params dict or the
    ``sbg_climber`` ``RobotModel``.  The path (:func:`plan_path`) is driven in
    the closed-loop simulator (:func:`simulate`) with Lx = ``preview_m``
    under ``noise`` and ``seed``; the result carries the path, the simulated
    trajectory and error series, per-segment commands, checks and metrics.
    Raises :class:`planners.errors.InvalidInputError` /
    :class:`~planners.errors.InfeasibleError` naming the bad input.
    """
    girder = girder if girder is not None else sample_girders()["seed_lab"]
    if not isinstance(girder, Girder):
        raise InvalidInputError(
            f"girder must be a planners.sbg.Girder, got {type(girder).__name__}"
        )
    if not isinstance(preview_m, int | float) or not math.isfinite(preview_m) or preview_m < 0:
        raise InvalidInputError(f"preview_m (Lx) must be a finite number ≥ 0, got {preview_m!r}")
    if noise is not None and not isinstance(noise, NoiseModel):
        raise InvalidInputError(f"noise must be a NoiseModel, got {type(noise).__name__}")
    cfg = replace(config or ControllerConfig(), preview_m=float(preview_m))
    limits = limits or Limits()
    if progress is not None:
        progress(0.0, "planning path")
    path = plan_path(
        girder,
        ClimberParams.coerce(robot),
        start_lane=start_lane,
        direction=direction,
        start_end=start_end,
    )
    if progress is not None:
        progress(0.05, "simulating")
    sim = simulate(path, noise=noise, config=cfg, seed=seed, progress=progress)
    if progress is not None:
        progress(0.97, "checking")
    checks, metrics = _evaluate(path, sim, limits)
    return InspectionPlan(
        path=path,
        sim=sim,
        commands=_commands(path, sim),
        checks=checks,
        metrics=metrics,
        limits=limits,
    )
