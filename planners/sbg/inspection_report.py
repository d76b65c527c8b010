"""One entry point for the ``sbg.inspect`` kind: the planned and
simulated inspection (:func:`planners.sbg.pipeline.plan_inspection`, seed 003
§3–§4: path, trilateration Eq. 5, preview-follow Eq. 6–9, corner law Eq. 1–4,
dead reckoning Eq. 10–11), the corner pitch of Eq. 4 *as printed* beside the
plan's own profile (Fig. 12), and the optional Lx sweep of the Fig. 14 set-up
(:func:`planners.sbg.experiments.lx_sweep`).

:func:`plan_inspection_result` is the kind's one call: the report in the
stored form (:class:`planners.result.PlanResult`: girder, path segments,
lanes, corners, U-turns, commands and the console plots in the summary; the
path and the simulated trajectory in the arrays that
``server/scene/sbg_inspect.py`` and the kind's ``compile`` read; the plan's
checks and metrics).  :func:`plan_inspection_report` returns the planner's
own objects.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from planners.result import PlanResult
from planners.sbg import corner as corner_mod
from planners.sbg.experiments import LxSweep, lx_sweep
from planners.sbg.girder import Girder
from planners.sbg.pipeline import InspectionPlan, Limits, plan_inspection
from planners.sbg.robot import ClimberParams
from planners.sbg.simulator import ControllerConfig, NoiseModel
from planners.summary import json_safe, plot, thin

__all__ = ["InspectionReport", "plan_inspection_report", "plan_inspection_result"]

#: share of the progress bar the sweep takes when there is one
SWEEP_SHARE = 0.25
#: chosen: a sweep run that has not finished the lane by then never settles
SWEEP_TIME_LIMIT_S = 300.0


@dataclass(frozen=True)
class InspectionReport:
    """The plan, the as-printed corner pitch (rad per ``plan.sim.dt_s``
    sample; None without a crossing) and the sweep (None without values)."""

    plan: InspectionPlan
    printed_pitch: np.ndarray | None
    sweep: LxSweep | None


def plan_inspection_report(
    girder: Girder,
    robot: ClimberParams,
    *,
    start_lane: int,
    direction: int,
    start_end: int,
    noise: NoiseModel,
    config: ControllerConfig,
    seed: int,
    limits: Limits,
    sweep_lx_m: Sequence[float] = (),
    sweep_seeds: int = 2,
    progress: Callable[[float, str], None] | None = None,
) -> InspectionReport:
    """Plan the inspection with Lx = ``config.preview_m``, compare its first
    corner crossing with Eq. 4 as printed, and sweep Lx over the sorted,
    de-duplicated ``sweep_lx_m`` × seeds 0 … ``sweep_seeds``−1."""
    share = SWEEP_SHARE if sweep_lx_m else 0.0

    def prog(f: float, stage: str) -> None:
        if progress is not None:
            progress(f * (1.0 - share), stage)

    plan = plan_inspection(
        girder,
        robot,
        start_lane=start_lane,
        direction=direction,
        start_end=start_end,
        preview_m=config.preview_m,
        noise=noise,
        config=config,
        seed=seed,
        limits=limits,
        progress=prog,
    )
    printed = None
    if plan.sim.crossing_pitch:
        printed = corner_mod.cross_corner(robot, profile=corner_mod.PRINTED, dt=plan.sim.dt_s).theta
    sweep = None
    if sweep_lx_m:
        if progress is not None:
            progress(1.0 - share, "Lx sweep")
        sweep = lx_sweep(
            sorted({float(v) for v in sweep_lx_m}),
            range(sweep_seeds),
            robot,
            noise=noise,
            time_limit_s=SWEEP_TIME_LIMIT_S,
        )
    return InspectionReport(plan=plan, printed_pitch=printed, sweep=sweep)


def plan_inspection_result(
    girder: Girder,
    robot: ClimberParams,
    *,
    start_lane: int,
    direction: int,
    start_end: int,
    noise: NoiseModel,
    config: ControllerConfig,
    seed: int,
    limits: Limits,
    sweep_lx_m: Sequence[float] = (),
    sweep_seeds: int = 2,
    progress: Callable[[float, str], None] | None = None,
) -> PlanResult:
    """:func:`plan_inspection_report` (same arguments) in the stored form.

    Summary: ``girder``, ``robot`` (less its camera), ``lane_order``,
    ``lane_dirs``, ``segments``, ``total_length_m``, ``lanes``, ``corners``,
    ``uturns``, ``commands``, ``noise``, ``plots`` (Fig. 14 tracking error
    on the first lane, Fig. 12 corner pitch beside Eq. 4 as printed, the
    camera's weld margin, the Lx sweep) and ``lx_sweep`` (rows in mm / deg,
    ``best_preview_mm``); non-finite numbers become ``null``.  Arrays:
    ``path_xyz``/``path_segment`` and the ``traj_*`` series.  Metrics: the
    plan's finite ones and ``lx_sweep_best_mm`` when a setting settled.
    """
    report = plan_inspection_report(
        girder, robot, start_lane=start_lane, direction=direction, start_end=start_end,
        noise=noise, config=config, seed=seed, limits=limits, sweep_lx_m=sweep_lx_m,
        sweep_seeds=sweep_seeds, progress=progress,
    )  # fmt: skip
    plots = _plots(report, config.corner_profile)
    sweep_rows = _sweep_rows(report.sweep)
    best = None if report.sweep is None else report.sweep.best_preview_m
    if report.sweep is not None:
        plots.append(
            plot(
                f"Lx sweep (Fig. 14 set-up, {sweep_seeds} seeds): time until |d| stays < 1 mm",
                [r["preview_mm"] for r in sweep_rows],
                {"settle_time_s": [r["settle_time_mean_s"] for r in sweep_rows]},
                x_label="Lx mm",
                y_label="s (missing: never)",
            )
        )
    if progress is not None:
        progress(0.99, "storing")
    plan = report.plan
    sim, path = plan.sim, plan.path
    summary = {
        "girder": asdict(girder),
        "robot": {k: v for k, v in asdict(robot).items() if k != "camera"},
        "lane_order": path.lane_order,
        "lane_dirs": {str(k): v for k, v in path.lane_dirs.items()},
        "segments": [
            {
                "kind": s.kind,
                "lane": s.lane,
                "to_lane": s.to_lane,
                "wall": s.wall,
                "length_m": s.length_m,
                "turn_deg": math.degrees(s.turn_rad),
                "start": s.start.tolist(),
                "end": s.end.tolist(),
            }
            for s in path.segments
        ],
        "total_length_m": path.total_length_m,
        "lanes": [asdict(ln) for ln in sim.lanes],
        "corners": [asdict(c) for c in sim.corners],
        "uturns": [asdict(u) for u in sim.uturns],
        "commands": [asdict(c) for c in plan.commands],
        "noise": asdict(noise),
        "plots": plots,
        "lx_sweep": {"rows": sweep_rows, "best_preview_mm": None if best is None else best * 1e3},
    }
    metrics = {k: float(v) for k, v in plan.metrics.items() if math.isfinite(v)}
    if best is not None:
        metrics["lx_sweep_best_mm"] = best * 1e3
    return PlanResult(
        summary=json_safe(summary), arrays=_arrays(plan), checks=list(plan.checks), metrics=metrics
    )


def _plots(report: InspectionReport, corner_profile: str) -> list[dict[str, Any]]:
    """The console plots of the simulated run (the sweep's is added after)."""
    sim = report.plan.sim
    A = sim.arrays
    plots: list[dict[str, Any]] = []
    # Fig. 14 style: d and δ over time on the first lane.
    seg0 = next(ln.segment for ln in sim.lanes)
    i0 = np.flatnonzero((A["segment"] == seg0) & np.isfinite(A["d_m"]))
    if i0.size:
        k = i0[thin(i0.size)]
        plots.append(
            plot(
                f"Fig. 14 style: lane {sim.lanes[0].lane} tracking error",
                A["t_s"][k] - A["t_s"][i0[0]],
                {"d_mm": A["d_m"][k] * 1e3, "delta_deg": np.degrees(A["delta_rad"][k])},
                x_label="s",
                y_label="d (mm), δ (deg)",
            )
        )
    # Fig. 12 style: pitch over the first crossing, and the as-printed law beside it.
    if sim.crossing_pitch and report.printed_pitch is not None:
        th, printed = sim.crossing_pitch[0], report.printed_pitch
        n = max(len(th), len(printed))
        t = np.arange(n) * sim.dt_s

        def pad(a: np.ndarray) -> np.ndarray:
            return np.r_[a, np.full(n - len(a), a[-1])]

        k = thin(n)
        plots.append(
            plot(
                "Fig. 12 style: pitch while crossing a corner",
                t[k],
                {
                    f"{corner_profile} (this plan)": np.degrees(pad(th))[k],
                    "Eq. 4 as printed": np.degrees(pad(printed))[k],
                },
                x_label="s",
                y_label="deg",
            )
        )
    # Camera margin over the lanes.
    im = np.flatnonzero(np.isfinite(A["margin_m"]))
    if im.size:
        k = im[thin(im.size)]
        plots.append(
            plot(
                "weld margin in the camera view (lanes)",
                A["t_s"][k],
                {"margin_mm": A["margin_m"][k] * 1e3},
                x_label="s",
                y_label="mm",
            )
        )
    return plots


def _sweep_rows(sweep: LxSweep | None) -> list[dict[str, Any]]:
    """The sweep's rows in display units (mm, deg), in increasing Lx."""
    if sweep is None:
        return []
    return [
        {
            "preview_mm": r.preview_m * 1e3,
            "finished_fraction": r.finished_fraction,
            "settle_time_mean_s": r.settle_time_mean_s,
            "final_d_mean_mm": r.final_d_mean_m * 1e3,
            "final_delta_mean_deg": math.degrees(r.final_delta_mean_rad),
        }
        for r in sweep.rows
    ]


def _arrays(plan: InspectionPlan) -> dict[str, np.ndarray]:
    """The planned path and the simulated trajectory, under the names the
    scene drawer and the kind's ``compile`` read."""
    path, A = plan.path, plan.sim.arrays
    seg_index = np.concatenate([np.full(len(s.points), i) for i, s in enumerate(path.segments)])
    return {
        "path_xyz": np.concatenate([s.points for s in path.segments]),
        "path_segment": seg_index.astype(np.int32),
        "traj_t": A["t_s"],
        "traj_pos": A["pos"],
        "traj_quat": A["quat"],
        "traj_segment": A["segment"].astype(np.int32),
        "traj_mode": A["mode"].astype(np.int8),
        "traj_pitch": A["pitch_rad"],
        "traj_d": A["d_m"],
        "traj_delta": A["delta_rad"],
        "traj_wheels": np.stack([A["v_left"], A["v_right"], A["v_front"], A["v_rear"]], axis=1),
        "traj_arm": A["arm_rad"],
        "traj_margin": A["margin_m"],
    }
