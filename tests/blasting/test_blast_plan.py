"""planners.blasting.blast_plan: the ``blast`` kind's one entry point returns the
plan in the stored form; its numbers are recomputed here from the returned
arrays and the robot model (not read back from the planner's statistics)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from planners.blasting import Box, scenes
from planners.blasting.blast_plan import BlastLimits, BlastOptions, PlanePick, plan_blast_result
from planners.blasting.sample_clouds import under_deck_cloud
from planners.errors import InvalidInputError, NoPlaneError
from planners.result import PlanResult
from robots import load_robot

ARM = load_robot("denso_vm6083")
BASE_M = [v / 1000.0 for v in scenes.ROBOT_BASE_MM]
BOXES = list(scenes.bridge_obstacles())
ARRAYS = {
    "disc_centers": np.float64,
    "disc_radii": np.float64,
    "disc_classes": np.int8,
    "disc_stream_mm": np.float64,
    "disc_tilt_deg": np.float64,
    "order": np.int32,
    "q": np.float64,
    "times": np.float64,
    "clearance": np.float64,
    "segment": np.int8,
    "waypoint_spot": np.int32,
    "nozzle_tip": np.float64,
    "nozzle_axis": np.float64,
}


@pytest.fixture(scope="module")
def surface3() -> tuple[PlanResult, list[tuple[float, str]]]:
    seen: list[tuple[float, str]] = []
    r = plan_blast_result(
        scenes.bridge_surface(3), ARM, robot_base_m=BASE_M, boxes=BOXES,
        progress=lambda f, s: seen.append((f, s)),
    )  # fmt: skip
    return r, seen


def test_stored_form_of_surface_3(surface3) -> None:
    r, seen = surface3
    s = json.loads(json.dumps(r.summary, allow_nan=False))  # strict JSON
    assert set(s) == {
        "surface", "robot_base", "boxes", "disc_radius_m", "params_used", "skipped",
        "timings_s", "plots",
    }  # fmt: skip
    surf = scenes.bridge_surface(3)
    assert np.allclose(s["surface"]["origin"], surf.origin)
    assert s["surface"]["area_m2"] == pytest.approx(surf.area)
    assert np.allclose(np.asarray(s["robot_base"])[:3, 3], BASE_M)
    assert [b["name"] for b in s["boxes"]] == [b.name for b in BOXES]
    assert s["disc_radius_m"] == scenes.DISC_RADIUS_M
    assert {k: np.dtype(v) for k, v in ARRAYS.items()} == {k: a.dtype for k, a in r.arrays.items()}
    q, t = r.arrays["q"], r.arrays["times"]
    assert q.shape == (len(t), 6) and len(r.arrays["clearance"]) == len(t)
    assert [p["title"].split(":")[0] for p in s["plots"]] == ["Fig. 4.22 style", "Fig. 4.16 style"]
    assert s["plots"][0]["x"][-1] == pytest.approx(t[-1])
    # progress: the surface first, then plan_blasting's 0–1 in 0.05–0.95, then storing
    assert seen[0] == (0.02, "surface") and seen[-1] == (0.97, "storing")
    assert [f for f, _ in seen] == sorted(f for f, _ in seen)


def test_checks_and_metrics_recomputed_from_the_arrays(surface3) -> None:
    r, _ = surface3
    a, m = r.arrays, r.metrics
    checks = {c.name: c for c in r.checks}
    assert list(checks) == [
        "coverage", "overspray", "joint_limits", "joint_speed", "clearance", "ik_residual",
        "skipped_spots",
    ]  # fmt: skip
    assert r.passed, [c.message for c in r.checks if not c.passed]
    q, t, clr = a["q"], a["times"], a["clearance"]
    speed = np.degrees(np.abs(np.diff(q, axis=0)).max(axis=1) / np.diff(t))
    assert checks["joint_speed"].value == pytest.approx(speed.max())
    assert checks["joint_speed"].limit == pytest.approx(30.0)
    assert m["max_joint_speed_deg_s"] == pytest.approx(speed.max())
    assert checks["clearance"].value == pytest.approx(clr.min())
    assert m["min_clearance_mm"] == pytest.approx(1000.0 * clr.min())
    lo, hi = ARM.joint_limits[:, 0], ARM.joint_limits[:, 1]
    assert checks["joint_limits"].value is bool(np.all((q >= lo - 1e-9) & (q <= hi + 1e-9)))
    assert m["waypoints"] == len(t) and m["trajectory_duration_s"] == t[-1]
    order = a["order"]
    assert m["discs"] == len(a["disc_centers"]) == len(order) + len(r.summary["skipped"])
    legs = np.diff(a["disc_centers"][order], axis=0)
    assert m["distance_m"] == pytest.approx(np.linalg.norm(legs, axis=1).sum())
    assert checks["coverage"].value == pytest.approx(m["coverage_pct"] / 100.0)
    assert checks["coverage"].limit == 0.99 and checks["overspray"].limit == 0.005
    assert m["planning_time_s"] > 0
    assert {k for k in m if k.startswith("stage_")} == {
        f"stage_{k}" for k in r.summary["timings_s"] if k != "total_s"
    }


def test_nozzle_tip_is_the_flange_pose_of_the_arm_at_the_base(surface3) -> None:
    r, _ = surface3
    base = np.eye(4)
    base[:3, 3] = BASE_M
    robot = ARM.with_base(base)
    q, tip, axis = r.arrays["q"], r.arrays["nozzle_tip"], r.arrays["nozzle_axis"]
    for k in np.linspace(0, len(q) - 1, 7).astype(int):
        T = robot.fk(q[k])
        assert np.allclose(axis[k], T[:3, 2], atol=1e-9)
        assert np.allclose(tip[k], T[:3, 3] + 0.1 * T[:3, 2], atol=1e-9)
    # way-points at a spot name a visited disc
    spot = r.arrays["waypoint_spot"]
    at = np.flatnonzero(spot >= 0)
    assert at.size and set(spot[at]) <= set(r.arrays["order"].tolist())


def test_limits_and_options_are_passed_on() -> None:
    r = plan_blast_result(
        scenes.bridge_surface(3), ARM, robot_base_m=BASE_M, boxes=BOXES,
        options=BlastOptions(disc_radius_m=0.05, sequencer="ga", seed=2),
        limits=BlastLimits(coverage_min=1.0, overspray_max=0.0, ik_residual_max_mm=1e-9),
    )  # fmt: skip
    checks = {c.name: c for c in r.checks}
    assert r.summary["disc_radius_m"] == 0.05 and r.metrics["disc_radius_mm"] == 50.0
    assert r.summary["params_used"]["sequencer"] == "ga"
    cov = checks["coverage"]
    assert cov.limit == 1.0 and cov.passed == (cov.value >= 1.0)
    ov = checks["overspray"]
    assert ov.limit == 0.0 and ov.passed == (ov.value <= 0.0)
    assert checks["ik_residual"].limit == 1e-9
    assert not r.passed


def test_bad_inputs_raise_planner_errors() -> None:
    with pytest.raises(InvalidInputError, match="robot_base_m"):
        plan_blast_result(scenes.bridge_surface(3), ARM, robot_base_m=[0.0, np.inf, 0.0])
    rng = np.random.default_rng(0)
    ball = rng.normal(size=(500, 3))
    ball /= np.linalg.norm(ball, axis=1, keepdims=True)  # a sphere: no plane in it
    with pytest.raises(NoPlaneError):
        plan_blast_result(PlanePick(ball, threshold_m=0.001), ARM, robot_base_m=BASE_M)


def test_kind_names_the_cloud_without_a_plane() -> None:
    from server.kinds.blast import BlastParams, run

    rng = np.random.default_rng(0)
    ball = rng.normal(size=(500, 3))
    ball /= np.linalg.norm(ball, axis=1, keepdims=True)

    class Ctx:
        def progress(self, fraction: float, stage: str) -> None:
            pass

        def load_cloud(self, cloud_id: str) -> np.ndarray:
            assert cloud_id == "c-17"
            return ball

    p = BlastParams(cloud_id="c-17", plane_threshold_m=0.001)
    with pytest.raises(NoPlaneError, match=r"\(cloud c-17\)"):
        run(p, Ctx())


def test_plane_picked_from_the_sample_cloud() -> None:
    cloud = under_deck_cloud(0)
    r = plan_blast_result(
        PlanePick(cloud, plane_index=1), ARM, robot_base_m=BASE_M,
        boxes=[Box.from_bounds([-0.8, -0.8, 1.7], [1.8, 2.0, 1.9], "deck")],
    )  # fmt: skip
    s = json.loads(json.dumps(r.summary, allow_nan=False))
    assert s["plane_index"] == 1
    sizes = [pl["points"] for pl in s["planes"]]
    assert sizes == sorted(sizes, reverse=True) and len(sizes) >= 3
    assert [pl["index"] for pl in s["planes"]] == list(range(len(sizes)))
    # the web patch (Surface 2): normal +x, toward the robot base
    assert s["surface"]["normal"][0] == pytest.approx(1.0, abs=0.01)
    cp, lab = r.arrays["cloud_points"], r.arrays["cloud_label"]
    assert len(cp) == len(lab) == min(len(cloud), 60_000)
    rows = set(map(tuple, cloud.tolist()))
    assert all(tuple(p) in rows for p in cp.tolist())  # rows of the cloud
    assert set(np.unique(lab)) <= set(range(-1, len(sizes)))
    # the cloud's other points are the obstacle points
    obst = r.arrays["obstacle_points"]
    assert obst.ndim == 2 and obst.shape[1] == 3 and len(obst) > 0
    assert r.metrics["min_clearance_mm"] == pytest.approx(1000.0 * r.arrays["clearance"].min())
