"""The robot's reported joints drive its live URDF in the scene, for every robot.

A robot reports the joints it has (``RobotModel.joint_names``); CMBOT's arm
reports 7 of its URDF's 12, which are placed by name (they once were dropped
for not matching the URDF's count, so the live CMBOT never moved).
"""

from __future__ import annotations

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
