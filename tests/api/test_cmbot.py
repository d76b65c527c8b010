"""``cmbot.climb`` and ``cmbot.manipulate`` through the REST API and the scene."""

from __future__ import annotations

import socket
import time

import numpy as np
import pytest

SHORT_CLIMB = {"start_rear_x_m": 4.6, "goal_rear_x_m": 4.84}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow  # the seed experiment through the API (tests/cmbot covers the planner)
def test_climb_defaults_cross_the_gap_and_pass_the_gate(api) -> None:
    plan = api.wait(api.submit("cmbot.climb")["id"], timeout=300)
    assert plan["state"] == "planned", plan.get("error") or [
        c for c in plan["checks"] if not c["passed"]
    ]
    names = {c["name"] for c in plan["checks"]}
    assert names >= {
        "footholds",
        "joint_limits",
        "joint_speeds",
        "foot_placement",
        "flip_torque",
        "arm_env_clearance",
        "self_clearance",
    }
    m = plan["metrics"]
    assert m["max_flip_torque_Nm"] < m["max_flip_torque_without_counterweight_Nm"]
    assert m["max_step_m"] <= 0.24 + 1e-9
    res = plan["result"]
    gaps = res["guardrail"]["gaps"]
    assert any(abs((b - a) - 0.10) < 1e-9 for a, b in gaps)
    first = res["phases"][0]
    actions = [(c["device"], c["action"]) for c in first["commands"]]
    assert ("plate_front", "release") in actions and ("magnet_front", "on") in actions
    assert any("flip torque" in p["title"] for p in res["plots"])


def test_climb_refusals_name_the_reason(api) -> None:
    r = api.post("/api/v1/plans", json={"kind": "cmbot.climb", "params": {"goal_rear_x_m": 5.9}})
    assert r.status_code == 422 and "post" in r.text
    wide = {
        "guardrail": {"segments_m": [[0, 3], [3.4, 6]], "posts_m": []},
        "start_rear_x_m": 1.0,
        "goal_rear_x_m": 4.5,
    }
    r = api.post("/api/v1/plans", json={"kind": "cmbot.climb", "params": wide})
    assert r.status_code == 422 and "gap" in r.text


def test_weak_counterweightless_fast_climb_is_rejected_with_where_and_when(api) -> None:
    params = {**SHORT_CLIMB, "phase_time_s": 0.4, "counterweight": False}
    plan = api.wait(api.submit("cmbot.climb", params)["id"], timeout=120)
    assert plan["state"] == "rejected"
    failed = [c for c in plan["checks"] if not c["passed"]]
    assert failed and all("t =" in c["message"] for c in failed)


@pytest.mark.slow  # the seed experiment through the API (tests/cmbot covers the planner)
def test_manipulate_defaults_plan_the_seed_experiment(api) -> None:
    plan = api.wait(api.submit("cmbot.manipulate")["id"], timeout=300)
    assert plan["state"] == "planned", [c["message"] for c in plan["checks"] if not c["passed"]]
    m = plan["metrics"]
    assert m["max_tracking_error_mm"] < 1.0
    assert m["min_clearance_m"] > 0.05
    assert m["without_avoidance_min_clearance_m"] < 0.0  # the term matters
    titles = [p["title"] for p in plan["result"]["plots"]]
    assert any("clearance" in t for t in titles)


def test_manipulate_without_avoidance_is_rejected(api) -> None:
    params = {"avoidance": False, "compare_without_avoidance": False, "relocate": False}
    plan = api.wait(api.submit("cmbot.manipulate", params)["id"], timeout=300)
    assert plan["state"] == "rejected"
    clear = next(c for c in plan["checks"] if c["name"] == "clearance")
    assert not clear["passed"] and "↔" in clear["message"]
    r = api.post(f"/api/v1/plans/{plan['id']}/approve")
    assert r.status_code == 409


def test_manipulate_refuses_a_stance_on_a_post(api) -> None:
    r = api.post(
        "/api/v1/plans", json={"kind": "cmbot.manipulate", "params": {"rear_foot_x_m": 7.3}}
    )
    assert r.status_code == 422 and "post" in r.text


def test_scene_draws_guardrail_robot_and_spheres(make_api) -> None:
    sapi = make_api(scene_port=free_port())
    pid = sapi.wait(sapi.submit("cmbot.climb", SHORT_CLIMB)["id"], timeout=120)["id"]
    r = sapi.post("/api/v1/scene/show", json={"plan_id": pid})
    assert r.status_code == 200
    scene = sapi.services.scene.server.scene
    for name in ("/plan/robot", "/plan/footholds", "/plan/front_path"):
        assert scene.get_handle_by_name(name) is not None, name
    assert any(
        scene.get_handle_by_name(f"/plan/guardrail/{i:03d}_bar0") is not None for i in range(3)
    )
    robot = scene.get_handle_by_name("/plan/robot")
    p0 = np.array(robot.position)
    time.sleep(1.0)
    assert np.isfinite(np.array(robot.position)).all() and p0 is not None


def test_scene_draws_arm_motion_tool_path_and_sphere_toggle(make_api) -> None:
    sapi = make_api(scene_port=free_port())
    params = {"compare_without_avoidance": False, "relocate": False}
    plan = sapi.wait(sapi.submit("cmbot.manipulate", params)["id"], timeout=300)
    r = sapi.post("/api/v1/scene/show", json={"plan_id": plan["id"]})
    assert r.status_code == 200
    scene = sapi.services.scene.server.scene
    for name in ("/plan/robot", "/plan/tool_path", "/plan/desired_path", "/plan/spheres"):
        assert scene.get_handle_by_name(name) is not None, name
    spheres = scene.get_handle_by_name("/plan/spheres")
    assert spheres.visible is False  # off until the operator ticks the toggle
