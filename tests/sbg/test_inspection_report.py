"""planners.sbg.inspection_report: the kind's one entry point gives what the
separate planner calls give, on a short 2-lane girder."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from planners.sbg import ControllerConfig, Limits, NoiseModel, plan_inspection, sample_girders
from planners.sbg import corner as corner_mod
from planners.sbg.experiments import lx_sweep
from planners.sbg.inspection_report import SWEEP_SHARE, plan_inspection_report
from planners.sbg.robot import ClimberParams

GIRDER = replace(sample_girders()["seed_lab"], length_m=1.0, n_ribs=3)


def test_report_matches_the_separate_calls() -> None:
    robot, noise = ClimberParams(), NoiseModel()
    cfg = ControllerConfig(preview_m=0.02)
    seen: list[tuple[float, str]] = []
    rep = plan_inspection_report(
        GIRDER, robot, start_lane=0, direction=1, start_end=0, noise=noise, config=cfg,
        seed=3, limits=Limits(), sweep_lx_m=[0.04, 0.01, 0.04], sweep_seeds=1,
        progress=lambda f, s: seen.append((f, s)),
    )  # fmt: skip
    alone = plan_inspection(
        GIRDER, robot, start_lane=0, direction=1, start_end=0, preview_m=0.02, noise=noise,
        config=cfg, seed=3, limits=Limits(),
    )  # fmt: skip
    assert rep.plan.metrics == alone.metrics
    assert np.array_equal(rep.plan.sim.arrays["pos"], alone.sim.arrays["pos"], equal_nan=True)
    assert rep.plan.sim.crossing_pitch  # the 2-lane path crosses corners
    printed = corner_mod.cross_corner(robot, profile=corner_mod.PRINTED, dt=alone.sim.dt_s).theta
    assert rep.printed_pitch is not None and np.array_equal(rep.printed_pitch, printed)
    assert rep.sweep is not None
    assert [r.preview_m for r in rep.sweep.rows] == [0.01, 0.04]  # sorted, de-duplicated
    sweep = lx_sweep([0.01, 0.04], range(1), robot, noise=noise, time_limit_s=300.0)
    assert rep.sweep.best_preview_m == sweep.best_preview_m
    # the plan's progress fills the bar up to the sweep's share, then the sweep
    fr = [f for f, _ in seen]
    assert fr == sorted(fr) and fr[-1] == 1.0 - SWEEP_SHARE and seen[-1][1] == "Lx sweep"
    assert max(f for f, s in seen if s != "Lx sweep") <= 1.0 - SWEEP_SHARE


def test_no_sweep_when_no_values() -> None:
    rep = plan_inspection_report(
        GIRDER, ClimberParams(), start_lane=0, direction=1, start_end=0, noise=NoiseModel(),
        config=ControllerConfig(), seed=0, limits=Limits(),
    )  # fmt: skip
    assert rep.sweep is None
