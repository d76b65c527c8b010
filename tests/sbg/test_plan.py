"""Public entry point planners.sbg.plan_inspection."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from planners.errors import InvalidInputError, PlannerError
from planners.sbg import Girder, Limits, NoiseModel, plan_inspection, sample_girders
from robots import load_robot


@pytest.fixture(scope="module")
def plan():
    return plan_inspection()


def test_default_plan_passes_its_checks(plan) -> None:
    names = [c.name for c in plan.checks]
    assert names == [
        "lanes_covered",
        "camera_margin",
        "rib_clearance",
        "corner_pitch_smooth",
        "final_centreline_offset",
        "final_yaw_deviation",
        "uturn_roof_yaw",
    ]
    assert plan.passed, [c.message for c in plan.checks if not c.passed]
    assert plan.metrics["lanes_covered"] == 3
    assert plan.metrics["worst_camera_margin_mm"] > 0
    assert plan.metrics["corner_delta_theta_deg"] == pytest.approx(18.3791, abs=1e-3)
    assert all(isinstance(v, float) and math.isfinite(v) for v in plan.metrics.values())


def test_commands_cover_every_segment(plan) -> None:
    assert [c.index for c in plan.commands] == list(range(len(plan.path.segments)))
    for c in plan.commands:
        assert c.t_end_s > c.t_start_s
        assert c.wheel_speed_max_m_s <= 0.02 + 1e-12
        if c.kind in ("corner_down", "corner_up"):
            assert c.pitch_change_rad == pytest.approx(math.pi / 2)
            assert c.arm_min_rad < c.arm_max_rad  # the lifting arm moved
        if c.kind == "turn":
            assert abs(c.turn_rad) == pytest.approx(math.pi / 2)
    times = [(c.t_start_s, c.t_end_s) for c in plan.commands]
    assert all(b[0] <= a[1] + 1e-9 for a, b in itertools.pairwise(times))


def test_time_series_shapes(plan) -> None:
    A = plan.sim.arrays
    T = len(A["t_s"])
    assert A["pos"].shape == (T, 3) and A["quat"].shape == (T, 4) and A["dr"].shape == (T, 3)
    assert np.all(np.diff(A["t_s"]) > 0)
    on_lane = np.isfinite(A["d_m"])
    assert on_lane.any() and np.isfinite(A["margin_m"][on_lane]).mean() > 0.9


def test_robot_model_is_accepted() -> None:
    p = plan_inspection(
        Girder(length_m=1.0, n_ribs=2), load_robot("sbg_climber"), noise=NoiseModel.none()
    )
    assert p.passed and p.metrics["lanes"] == 1


def test_limits_are_applied() -> None:
    p = plan_inspection(
        Girder(length_m=1.0, n_ribs=2), limits=Limits(camera_margin_m=1.0), noise=NoiseModel.none()
    )
    check = next(c for c in p.checks if c.name == "camera_margin")
    assert not check.passed and "<" in check.message


def test_progress_and_cancel() -> None:
    seen = []
    plan_inspection(Girder(length_m=1.0, n_ribs=2), progress=lambda f, s: seen.append((f, s)))
    assert seen[0][0] == 0.0 and all(0 <= f <= 1 for f, _ in seen)

    from planners.errors import CancelledError

    def cancel(f: float, s: str) -> None:
        if f > 0.01:
            raise CancelledError("stop")

    with pytest.raises(CancelledError):
        plan_inspection(Girder(length_m=1.0, n_ribs=2), progress=cancel)


def test_bad_inputs_name_the_parameter() -> None:
    with pytest.raises(InvalidInputError, match="preview_m"):
        plan_inspection(preview_m=-1)
    with pytest.raises(InvalidInputError, match="girder"):
        plan_inspection({"length_m": 2})  # type: ignore[arg-type]
    with pytest.raises(PlannerError, match="start_lane"):
        plan_inspection(sample_girders()["seed_lab"], start_lane=9)
