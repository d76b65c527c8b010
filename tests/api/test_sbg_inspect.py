"""``sbg.inspect`` through the REST API and the scene."""

from __future__ import annotations

import socket
import time

import numpy as np
import pytest


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


FAST = {"girder": {"length_m": 1.0, "n_ribs": 3}, "sweep_lx_mm": [10.0, 40.0], "sweep_seeds": 1}


def test_defaults_plan_the_seed_experiment(api) -> None:
    plan = api.wait(api.submit("sbg.inspect")["id"], timeout=240)
    assert plan["state"] == "planned", plan.get("error")
    checks = {c["name"]: c for c in plan["checks"]}
    assert set(checks) >= {
        "lanes_covered",
        "camera_margin",
        "corner_pitch_smooth",
        "final_centreline_offset",
    }
    assert all(c["passed"] for c in checks.values()), [
        c["message"] for c in checks.values() if not c["passed"]
    ]
    m = plan["metrics"]
    assert m["lanes"] == 3 and m["lanes_covered"] == 3
    assert m["worst_camera_margin_mm"] > 0
    assert m["max_final_d_mm"] <= 0.33
    assert m["corner_delta_theta_deg"] == pytest.approx(18.379, abs=1e-3)
    res = plan["result"]
    assert res["lane_order"] == [0, 1, 2]
    assert [s["kind"] for s in res["segments"]][:8] == [
        "lane", "corner_down", "s1", "turn", "s2", "turn", "s3", "corner_up",
    ]  # fmt: skip
    titles = [p["title"] for p in res["plots"]]
    assert any("Fig. 14" in t for t in titles) and any("Fig. 12" in t for t in titles)
    assert any("Lx sweep" in t for t in titles)
    assert len(res["lx_sweep"]["rows"]) == 5
    # Arrays are served: the trajectory has one pose per sample.
    r = api.get(
        plan["arrays"]["traj_pos"]
        if "arrays" in plan
        else f"/api/v1/plans/{plan['id']}/arrays/traj_pos"
    )
    assert r.status_code == 200


def test_params_change_the_plan_and_bad_ones_are_refused(api) -> None:
    plan = api.wait(
        api.submit("sbg.inspect", {**FAST, "start_lane": 1, "direction": -1, "seed": 3})["id"]
    )
    assert plan["state"] == "planned", plan.get("error")
    assert plan["result"]["lane_order"] == [1, 0]
    assert plan["metrics"]["lanes"] == 2
    # Infeasible geometry: ribs too close for the 210 mm robot → 422 at submission.
    r = api.post(
        "/api/v1/plans", json={"kind": "sbg.inspect", "params": {"girder": {"rib_spacing_m": 0.45}}}
    )
    assert r.status_code == 422 and "lane width" in r.text
    r = api.post("/api/v1/plans", json={"kind": "sbg.inspect", "params": {"start_lane": 7}})
    assert r.status_code == 422 and "start_lane" in r.text
    r = api.post("/api/v1/plans", json={"kind": "sbg.inspect", "params": {"preview_mm": -1}})
    assert r.status_code == 422


def test_encoder_only_baseline_is_rejected_by_its_checks(api) -> None:
    plan = api.wait(
        api.submit("sbg.inspect", {**FAST, "dr_yaw": "encoder", "sweep_lx_mm": []})["id"]
    )
    assert plan["state"] in ("planned", "rejected")
    failed = {c["name"] for c in plan["checks"] if not c["passed"]}
    assert "uturn_roof_yaw" in failed  # slip in the turns: degrees of yaw error


def test_scene_draws_girder_path_and_animated_robot(make_api) -> None:
    sapi = make_api(scene_port=free_port())
    pid = sapi.wait(sapi.submit("sbg.inspect", {**FAST, "sweep_lx_mm": []})["id"])["id"]
    r = sapi.post("/api/v1/scene/show", json={"plan_id": pid})
    assert r.status_code == 200 and r.json()["shown"] == pid
    scene = sapi.services.scene.server.scene
    for name in (
        "/plan/girder/deck",
        "/plan/girder/rib0",
        "/plan/girder/crossbeam1",
        "/plan/girder/welds",
        "/plan/path",
        "/plan/trajectory",
        "/plan/robot",
    ):
        assert scene.get_handle_by_name(name) is not None, name
    robot = scene.get_handle_by_name("/plan/robot")
    p0 = np.array(robot.position)
    time.sleep(0.5)
    assert not np.allclose(np.array(robot.position), p0)
