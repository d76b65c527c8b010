"""One entry point for the ``sbg.inspect`` kind (issue #13 §2): the planned and
simulated inspection (:func:`planners.sbg.pipeline.plan_inspection`, seed 003
§3–§4: path, trilateration Eq. 5, preview-follow Eq. 6–9, corner law Eq. 1–4,
dead reckoning Eq. 10–11), the corner pitch of Eq. 4 *as printed* beside the
plan's own profile (Fig. 12), and the optional Lx sweep of the Fig. 14 set-up
(:func:`planners.sbg.experiments.lx_sweep`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from planners.sbg import corner as corner_mod
from planners.sbg.experiments import LxSweep, lx_sweep
from planners.sbg.girder import Girder
from planners.sbg.pipeline import InspectionPlan, Limits, plan_inspection
from planners.sbg.robot import ClimberParams
from planners.sbg.simulator import ControllerConfig, NoiseModel

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
