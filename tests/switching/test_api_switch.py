"""``ara.switch`` through the REST API and the scene."""

from __future__ import annotations

import socket
import time

import numpy as np
import pytest


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow
def test_defaults_plan_the_perpendicular_slab_experiment(api) -> None:
    """Fig. 5.4: inch-worm onto the perpendicular slab, every check passing."""
    plan = api.wait(api.submit("ara.switch")["id"], timeout=400)
    assert plan["state"] == "planned", (plan.get("error"), plan.get("checks"))
    checks = {c["name"]: c for c in plan["checks"]}
    assert set(checks) >= {
        "safe_surface",
        "jump_planned",
        "joint_limits",
        "joint_speeds",
        "clearance",
        "self_clearance",
        "foothold_inside_surface",
    }
    assert all(c["passed"] for c in checks.values())
    res = plan["result"]
    assert res["decision"]["mode"] == "inchworm"
    assert [p["name"] for p in res["jump"]["phases"]] == ["A", "B", "C", "D", "E", "F"]
    m = plan["metrics"]
    assert m["jump_min_clearance_m"] >= 0.01
    assert m["jump_max_speed_ratio"] <= 1.0
    r = api.get(f"/api/v1/plans/{plan['id']}/arrays/joint_trajectory")
    assert r.status_code == 200
    # The compiled program: J1-J6 way-points with the magnet commands in the
    # order of the phases; foot 2 lets go only after foot 1 holds.
    assert checks["command_program"]["passed"]
    prog = plan["program"]
    joints = [c for c in prog if c["op"] == "joints"]
    assert joints and all(len(c["q_rad"]) == 6 for c in joints)
    q = np.array(
        api.get(f"/api/v1/plans/{plan['id']}/arrays/joint_trajectory?format=json").json()["data"]
    )
    np.testing.assert_allclose(joints[0]["q_rad"], q[0])
    np.testing.assert_allclose(joints[-1]["q_rad"], q[-1])
    mags = [(c["magnet"], c["touched"]) for c in prog if c["op"] == "magnet"]
    assert mags == [(1, True), (0, True), (1, False), (0, False)]
    assert prog[-1]["op"] == "stop"
    t = np.array(api.get(f"/api/v1/plans/{plan['id']}/arrays/times?format=json").json()["data"])
    assert abs(sum(c["duration_s"] for c in joints) - (t[-1] - t[0])) < 1e-6


def test_sample_clouds_give_their_verdicts(api) -> None:
    r = api.post("/api/v1/clouds", json={"sample": "switch_same_height"})
    assert r.status_code in (200, 201), r.text
    cloud = r.json()["id"]
    plan = api.wait(api.submit("ara.switch", {"cloud_id": cloud})["id"])
    assert plan["state"] == "planned", plan.get("error")
    assert plan["result"]["decision"]["mode"] == "mobile"
    assert abs(plan["metrics"]["height_error_m"]) <= 0.005
    # Mobile: the robot keeps driving, so there is no arm program to dispatch.
    assert plan["program"] is None and "command_program" not in {c["name"] for c in plan["checks"]}
    assert api.post(f"/api/v1/plans/{plan['id']}/approve").status_code == 200
    r = api.post(f"/api/v1/plans/{plan['id']}/dispatch", json={"robot": "ara"})
    assert r.status_code == 409 and "no compiled command program" in r.json()["detail"]
    # No surface: the robot must not move, so the plan cannot be approved.
    plan = api.wait(api.submit("ara.switch", {"sample": "no_surface"})["id"])
    assert plan["state"] == "rejected"
    failed = {c["name"] for c in plan["checks"] if not c["passed"]}
    assert failed == {"safe_surface"}


def test_bad_params_are_refused(api) -> None:
    r = api.post("/api/v1/plans", json={"kind": "ara.switch", "params": {"sample": "nowhere"}})
    assert r.status_code == 422 and "nowhere" in r.text
    r = api.post(
        "/api/v1/plans", json={"kind": "ara.switch", "params": {"camera_to_base": [[1, 0], [0, 1]]}}
    )
    assert r.status_code == 422
    r = api.post("/api/v1/plans", json={"kind": "ara.switch", "params": {"height_tolerance_m": -1}})
    assert r.status_code == 422


def test_scene_draws_planes_rectangles_and_animated_robot(make_api) -> None:
    sapi = make_api(scene_port=free_port())
    pid = sapi.wait(sapi.submit("ara.switch", {"sample": "step_down_7cm"})["id"], timeout=300)["id"]
    r = sapi.post("/api/v1/scene/show", json={"plan_id": pid})
    assert r.status_code == 200 and r.json()["shown"] == pid
    scene = sapi.services.scene.server.scene
    for name in (
        "/plan/cloud/plane0",
        "/plan/boundary",
        "/plan/rectangles/0",
        "/plan/foothold",
        "/plan/robot",
    ):
        assert scene.get_handle_by_name(name) is not None, name
    robot = scene.get_handle_by_name("/plan/robot")
    p0 = np.array(robot.position)
    moved = False
    for _ in range(40):  # the base frame jumps when foot 1 takes over
        time.sleep(0.25)
        moved = moved or not np.allclose(np.array(robot.position), p0)
    assert moved
