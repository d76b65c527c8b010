"""The robot's reported joints drive its live URDF in the scene, for every robot.

A robot reports the joints it has (``RobotModel.joint_names``); CMBOT's arm
reports 7 of its URDF's 12, which are placed by name (they once were dropped
for not matching the URDF's count, so the live CMBOT never moved).
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from robots import ROBOT_NAMES, load_robot
from tests.api.test_scene_proposals import free_port


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    from server.scene.service import SceneService
    from server.store import Store

    store = Store(tmp_path_factory.mktemp("var"))
    s = SceneService(store, free_port(), lambda _p: None)
    s.start()
    yield s
    s.stop()


@pytest.mark.parametrize("robot", ROBOT_NAMES)
def test_a_report_moves_the_live_urdf_by_joint_name(scene, robot: str) -> None:
    model = load_robot(robot)
    lo, hi = np.asarray(model.joint_limits, dtype=float).T
    lo, hi = np.maximum(lo, -np.pi), np.minimum(hi, np.pi)  # wheels turn freely
    rng = np.random.default_rng(3)
    scene.current = {"robot": robot, "base_pose": None}
    scene._live.clear()
    scene._live_cfg.clear()
    for _ in range(2):  # two reports: the second moves it again
        q = lo + rng.random(len(lo)) * (hi - lo)
        scene.update_live_robot(robot, q)
        handle = scene._live[robot]
        names = list(handle.get_actuated_joint_names())
        cfg = np.asarray(handle._urdf.cfg, dtype=float)
        got = cfg[[names.index(n) for n in model.joint_names]]
        assert np.allclose(got, q), (robot, got, q)
        others = [i for i, n in enumerate(names) if n not in model.joint_names]
        assert np.all(cfg[others] == 0.0)  # not reported: left where they were


def test_a_report_for_another_robot_or_of_the_wrong_size_is_ignored(scene) -> None:
    scene.current = {"robot": "cmbot", "base_pose": None}
    scene._live.clear()
    scene._live_cfg.clear()
    scene.update_live_robot("ara", np.zeros(6))  # not the robot shown
    assert "ara" not in scene._live
    scene.update_live_robot("cmbot", np.full(5, 0.1))  # neither 7 nor 12 joints
    assert "cmbot" not in scene._live_cfg


def test_an_execution_drives_the_planned_ghost_and_the_live_robot_rides_on_it(make_api) -> None:
    """While the shown plan runs, its animation stands where the plan is after
    the commands acknowledged (by their planned durations) instead of
    looping, and the reported robot is drawn on the planned base."""
    sapi = make_api(scene_port=free_port())
    plan = sapi.wait(sapi.submit("sbg.inspect")["id"], timeout=120)
    sapi.post("/api/v1/scene/show", json={"plan_id": plan["id"]})
    scene = sapi.services.scene
    base = scene.server.scene.get_handle_by_name("/plan/robot")
    assert base is not None
    durations = np.array([c.get("duration_s", 0.0) for c in plan["program"]])
    n = len(durations)
    poses = {}
    for acked in (0, n // 2, n):
        scene.execution_progress(plan["id"], "ex_test", "running", acked)
        want = durations[:acked].sum() / durations.sum()
        assert scene.current["execution"]["fraction"] == pytest.approx(want, abs=1e-4)
        p0 = np.array(base.position)
        time.sleep(0.3)  # the loop no longer moves it
        np.testing.assert_allclose(base.position, p0)
        poses[acked] = p0
    assert np.linalg.norm(poses[n // 2] - poses[0]) > 0.05  # the climber moved on
    # A report: the live robot hangs under the planned robot's node.
    model = load_robot("sbg_climber")
    scene.update_live_robot("sbg_climber", np.zeros(len(model.joint_names)))
    assert scene.server.scene.get_handle_by_name("/plan/robot/live") is not None
    # Another plan's execution changes nothing here.
    scene.execution_progress("pl_other", "ex_2", "running", 0)
    assert scene.current["execution"]["id"] == "ex_test"


def test_a_real_run_on_the_emulator_moves_the_ghost_to_the_end_and_the_live_robot(
    make_api,
) -> None:
    """End to end: dispatch the shown plan to its robot's emulator; the
    execution's acks reach the scene (fraction 1 when completed) and the
    robot's reports draw the live robot under the planned one."""
    from tests.api.test_dispatch import wait_execution

    sapi = make_api(scene_port=free_port(), emulators=True, emulator_time_scale=40.0)
    assert sapi.services.dispatch.wait_connected("sbg_climber", 20)
    plan = sapi.wait(sapi.submit("sbg.inspect")["id"], timeout=120)
    assert sapi.post(f"/api/v1/plans/{plan['id']}/approve").status_code == 200
    sapi.post("/api/v1/scene/show", json={"plan_id": plan["id"]})
    r = sapi.post(f"/api/v1/plans/{plan['id']}/dispatch", json={"robot": "sbg_climber"})
    assert r.status_code in (200, 201, 202), r.text
    eid = r.json()["id"]
    wait_execution(sapi, eid, ("completed",), timeout=120)
    scene = sapi.services.scene
    deadline = time.monotonic() + 10
    while (
        time.monotonic() < deadline
        and (scene.current.get("execution") or {}).get("state") != "completed"
    ):
        time.sleep(0.1)
    ex = scene.current["execution"]
    assert ex["id"] == eid and ex["state"] == "completed" and ex["fraction"] == 1.0
    assert "sbg_climber" in scene._live  # reports arrived and were drawn
    assert scene.server.scene.get_handle_by_name("/plan/robot/live") is not None
