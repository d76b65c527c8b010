"""planners.sbg.inspection_report.plan_inspection_result: the ``sbg.inspect``
kind's one entry point returns the plan in the stored form; its checks and
metrics are recomputed here from the returned arrays and an independently
planned path, on a short 2-lane girder."""

from __future__ import annotations

import json
import math
import re
from dataclasses import replace

import numpy as np
import pytest

from planners.result import PlanResult
from planners.sbg import ControllerConfig, Limits, NoiseModel, plan_path, sample_girders
from planners.sbg.inspection_report import plan_inspection_result
from planners.sbg.robot import ClimberParams

GIRDER = replace(sample_girders()["seed_lab"], length_m=1.0, n_ribs=3)
ROBOT = ClimberParams()
DEG = math.pi / 180.0


def _plan(**kw) -> PlanResult:
    args = dict(
        start_lane=0, direction=1, start_end=0, noise=NoiseModel(),
        config=ControllerConfig(preview_m=0.02), seed=1, limits=Limits(),
    )  # fmt: skip
    args.update(kw)
    return plan_inspection_result(GIRDER, ROBOT, **args)  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def swept() -> tuple[PlanResult, list[tuple[float, str]]]:
    seen: list[tuple[float, str]] = []
    r = _plan(
        sweep_lx_m=[0.04, 0.01, 0.04], sweep_seeds=1, progress=lambda f, s: seen.append((f, s))
    )
    return r, seen


def test_stored_form(swept) -> None:
    r, seen = swept
    s = json.loads(json.dumps(r.summary, allow_nan=False))  # strict JSON
    assert list(s) == [
        "girder", "robot", "lane_order", "lane_dirs", "segments", "total_length_m", "lanes",
        "corners", "uturns", "commands", "noise", "plots", "lx_sweep",
    ]  # fmt: skip
    assert s["girder"]["n_ribs"] == 3 and s["lane_order"] == [0, 1]
    assert "camera" not in s["robot"] and s["robot"]["track_m"] == ROBOT.track_m
    # the path is the one plan_path gives (planned again here)
    path = plan_path(GIRDER, ROBOT, start_lane=0, direction=1, start_end=0)
    assert [g["kind"] for g in s["segments"]] == [g.kind for g in path.segments]
    assert s["total_length_m"] == pytest.approx(path.total_length_m)
    xyz, seg = r.arrays["path_xyz"], r.arrays["path_segment"]
    assert np.array_equal(xyz, np.concatenate([g.points for g in path.segments]))
    assert seg.dtype == np.int32 and np.array_equal(
        seg, np.repeat(np.arange(len(path.segments)), [len(g.points) for g in path.segments])
    )
    t = r.arrays["traj_t"]
    T = len(t)
    assert (np.diff(t) > 0).all()
    shapes = {k: a.shape for k, a in r.arrays.items() if k.startswith("traj_")}
    assert shapes == {
        "traj_t": (T,), "traj_pos": (T, 3), "traj_quat": (T, 4), "traj_segment": (T,),
        "traj_mode": (T,), "traj_pitch": (T,), "traj_d": (T,), "traj_delta": (T,),
        "traj_wheels": (T, 4), "traj_arm": (T,), "traj_margin": (T,),
    }  # fmt: skip
    assert r.arrays["traj_mode"].dtype == np.int8 and r.arrays["traj_segment"].dtype == np.int32
    titles = [p["title"] for p in s["plots"]]
    assert titles[0].startswith("Fig. 14 style") and titles[1].startswith("Fig. 12 style")
    assert titles[-1].startswith("Lx sweep (Fig. 14 set-up, 1 seeds)")
    # sorted, de-duplicated sweep; its plot's x is the rows' Lx in mm
    assert [row["preview_mm"] for row in s["lx_sweep"]["rows"]] == [10.0, 40.0]
    assert s["plots"][-1]["x"] == [10.0, 40.0]
    best = s["lx_sweep"]["best_preview_mm"]
    assert best in (10.0, 40.0) and r.metrics["lx_sweep_best_mm"] == best
    assert seen[-1] == (0.99, "storing") and [f for f, _ in seen] == sorted(f for f, _ in seen)


def test_checks_and_metrics_recomputed_from_the_arrays(swept) -> None:
    r, _ = swept
    a, m = r.arrays, r.metrics
    checks = {c.name: c for c in r.checks}
    assert list(checks) == [
        "lanes_covered", "camera_margin", "rib_clearance", "corner_pitch_smooth",
        "final_centreline_offset", "final_yaw_deviation", "uturn_roof_yaw",
    ]  # fmt: skip
    lane_segs = [ln["segment"] for ln in r.summary["lanes"]]
    on_lane = np.isin(a["traj_segment"], lane_segs) & np.isfinite(a["traj_d"])
    worst = np.nanmin(a["traj_margin"][on_lane])
    c = checks["camera_margin"]
    assert c.value == pytest.approx(worst * 1e3) and c.limit == 0.0
    assert c.passed == (worst >= 0) and m["worst_camera_margin_mm"] == pytest.approx(worst * 1e3)
    assert c.message == f"worst weld margin in the camera view {worst * 1e3:.6g} mm ≥ 0 mm"
    assert m["max_abs_d_mm"] == pytest.approx(1e3 * np.abs(a["traj_d"][on_lane]).max())
    fd = checks["final_centreline_offset"]
    assert fd.limit == pytest.approx(0.33) and fd.value == pytest.approx(m["max_final_d_mm"])
    assert fd.value <= m["max_abs_d_mm"] + 1e-9
    yaw = checks["final_yaw_deviation"]
    assert yaw.limit == pytest.approx(0.06)
    assert yaw.value == pytest.approx(
        max(abs(ln["final_delta_rad"]) for ln in r.summary["lanes"]) / DEG
    )
    assert checks["lanes_covered"].value == 2.0 == m["lanes_covered"]
    assert m["samples"] == len(a["traj_t"]) and m["path_length_m"] == r.summary["total_length_m"]
    assert all(math.isfinite(v) for v in m.values())
    for ch in r.checks[1:]:  # each message states the value against the limit
        assert isinstance(ch.value, float) and isinstance(ch.limit, float)
        lim = re.escape(f"{ch.limit:.6g}")
        assert f" {ch.value:.6g} " in ch.message and re.search(f" [≤≥<>] {lim} ", ch.message)
        assert ch.passed == any(rel in ch.message for rel in (" ≤ ", " ≥ "))


def test_limits_fail_their_checks_and_no_sweep() -> None:
    r = _plan(limits=Limits(camera_margin_m=1.0, final_d_m=1e-9), progress=None)
    checks = {c.name: c for c in r.checks}
    assert not checks["camera_margin"].passed and checks["camera_margin"].limit == 1000.0
    assert " < 1000 mm" in checks["camera_margin"].message
    assert not checks["final_centreline_offset"].passed and " > " in (
        checks["final_centreline_offset"].message
    )
    assert r.summary["lx_sweep"] == {"rows": [], "best_preview_mm": None}
    assert "lx_sweep_best_mm" not in r.metrics
    assert not any(p["title"].startswith("Lx sweep") for p in r.summary["plots"])
    json.dumps(r.summary, allow_nan=False)
