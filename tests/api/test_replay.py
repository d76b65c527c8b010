"""Replay of a recorded run: the timeline from the stored
rows, and the replay robot in the scene at the interpolated recorded joints."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from server.recording.channels import iso_ns
from server.scene import replay
from tests.api.test_dispatch import approved_demo, wait_execution
from tests.api.test_scene_proposals import free_port


def test_joints_and_plan_time_interpolate() -> None:
    samples = [(0.0, [0.0, 1.0]), (2.0, [2.0, 3.0]), (4.0, [2.0, 3.0, 4.0])]
    q, i = replay.joints_at(samples, 1.5)
    np.testing.assert_allclose(q, [1.5, 2.5])
    assert i == 0
    assert replay.joints_at(samples, -1.0)[0].tolist() == [0.0, 1.0]
    assert replay.joints_at(samples, 3.0)[0].tolist() == [2.0, 3.0]  # lengths differ: held
    assert replay.joints_at(samples, 9.0)[0].tolist() == [2.0, 3.0, 4.0]
    tl = np.array([0.0, 1.0, 3.0])
    assert replay.planned_time_at(tl, [2.0, 4.0], 1.0) == (0.5, 0)
    assert replay.planned_time_at(tl, [2.0, 4.0], 3.0) == (2.0, 1)
    assert replay.planned_time_at(tl, [2.0, 4.0], 5.0) == (3.0, 2)


def test_a_real_run_replays_on_its_timeline_and_in_the_scene(make_api) -> None:
    api = make_api(scene_port=free_port(), emulators=True, emulator_time_scale=10.0)
    assert api.services.dispatch.wait_connected("ara", 20)
    plan = approved_demo(api, end="c2")
    eid = api.post(f"/api/v1/plans/{plan['id']}/dispatch", json={"robot": "ara"}).json()["id"]
    ex = wait_execution(api, eid, ("completed",), timeout=120)
    store = api.services.store

    r = api.get(f"/api/v1/executions/{eid}/replay", "viewer")
    assert r.status_code == 200, r.text
    tl = r.json()
    start = iso_ns(ex["created_at"]) / 1e9
    recorded = store.execution_states(eid)
    assert len(recorded) >= 2
    assert [(s["t_s"], s["state"]) for s in tl["samples"]] == [
        (t - start, st) for t, st in recorded
    ]
    assert tl["thinning"]["stride"] == 1 and tl["thinning"]["stored_samples"] == len(recorded)
    program = plan["program"]
    assert [a["index"] for a in tl["acks"]] == list(range(ex["total"]))
    assert [a["op"] for a in tl["acks"]] == [c["op"] for c in program]
    times = [a["t_s"] for a in tl["acks"]]
    assert times == sorted(times) and times[0] >= 0
    actions = [o["action"] for o in tl["operator"]]
    assert "approve" in actions and "complete" in actions
    assert tl["finished"] and tl["duration_s"] >= max(times[-1], tl["samples"][-1]["t_s"])

    # Thinned above the bound, the last kept, and it says so.
    small = replay.timeline(store, eid, max_samples=3)
    assert len(small["samples"]) <= 3 and small["thinning"]["stride"] > 1
    assert small["samples"][-1] == tl["samples"][-1]
    assert "every" in small["thinning"]["note"]

    # Replay between two reports: the joints are the interpolated recorded ones.
    s0, s1 = tl["samples"][0], tl["samples"][1]
    t = (s0["t_s"] + s1["t_s"]) / 2
    r = api.post("/api/v1/scene/replay", json={"execution_id": eid, "t_s": t})
    assert r.status_code == 200, r.text
    out = r.json()
    want = (np.asarray(s0["state"]["q_rad"]) + np.asarray(s1["state"]["q_rad"])) / 2
    np.testing.assert_allclose(out["q_rad"], want, atol=1e-9)
    scene = api.services.scene
    assert scene.current["plan_id"] == plan["id"]  # shown by the replay
    # demo.route draws no planned robot: the replay robot gets its own node
    # (under a drawn robot it is "<its node>/replay", as the live one).
    node = out["node"]
    assert node == "/plan/replay_ara"
    assert scene.server.scene.get_handle_by_name(node) is not None
    handle = scene._replay["handle"]
    np.testing.assert_allclose(np.asarray(handle._urdf.cfg, dtype=float), want, atol=1e-9)
    assert api.get("/api/v1/scene", "viewer").json()["current"]["replay"]["t_s"] == t
    # After the last ack every command is done; later than the end: the last report.
    end = api.post("/api/v1/scene/replay", json={"execution_id": eid, "t_s": 1e6}).json()
    assert end["acked"] == ex["total"] and end["command"] is None
    assert end["plan_fraction"] == 1.0
    np.testing.assert_allclose(end["q_rad"], tl["samples"][-1]["state"]["q_rad"])
    mid = api.post("/api/v1/scene/replay", json={"execution_id": eid, "t_s": times[0] / 2})
    assert mid.json()["command"] == {"index": 0, "op": program[0]["op"]}

    # DELETE removes the replay robot; the plan stays.
    assert api.delete("/api/v1/scene/replay").status_code == 204
    assert scene.server.scene.get_handle_by_name(node) is None
    assert "replay" not in scene.current and scene.current["plan_id"] == plan["id"]

    # Roles, unknown ids, a run without recorded states.
    assert api.post("/api/v1/scene/replay", "viewer", json={"execution_id": eid, "t_s": 0}
                    ).status_code == 403  # fmt: skip
    assert api.delete("/api/v1/scene/replay", "viewer").status_code == 403
    assert api.get("/api/v1/executions/ex_nope/replay", "viewer").status_code == 404
    assert api.post("/api/v1/scene/replay", json={"execution_id": "ex_nope", "t_s": 0}
                    ).status_code == 404  # fmt: skip
    with store.db.transaction() as conn:
        conn.execute("DELETE FROM execution_states WHERE execution_id = ?", (eid,))
    r = api.post("/api/v1/scene/replay", json={"execution_id": eid, "t_s": 0})
    assert r.status_code == 409 and "no recorded robot states" in r.json()["detail"]
    assert api.get(f"/api/v1/executions/{eid}/replay", "viewer").json()["samples"] == []


@pytest.mark.parametrize("method", ["post", "delete"])
def test_no_scene_is_a_409(api, method: str) -> None:
    kw = {"json": {"execution_id": "ex_x", "t_s": 0}} if method == "post" else {}
    r = getattr(api, method)("/api/v1/scene/replay", **kw)
    assert r.status_code == 409 and "not running" in r.json()["detail"]


def test_an_ara_navigate_replay_moves_the_robot_along_its_path(make_api) -> None:
    """The replayed (and live) ARA rides on the planned robot, which the
    replay places where the plan was at ``t``: it moves along the path."""
    api = make_api(scene_port=free_port(), emulators=True, emulator_time_scale=20.0)
    assert api.services.dispatch.wait_connected("ara", 20)
    plan = api.wait(api.submit("ara.navigate")["id"], timeout=120)
    assert api.post(f"/api/v1/plans/{plan['id']}/approve").status_code == 200
    eid = api.post(f"/api/v1/plans/{plan['id']}/dispatch", json={"robot": "ara"}).json()["id"]
    wait_execution(api, eid, ("completed",), timeout=300)
    duration = api.get(f"/api/v1/executions/{eid}/replay", "viewer").json()["duration_s"]
    scene = api.services.scene
    path = np.asarray(api.services.store.get_plan(plan["id"]).array("path_xyz")).reshape(-1, 3)
    where = []
    for t in (0.0, duration / 3, 2 * duration / 3, 1e6):
        out = api.post("/api/v1/scene/replay", json={"execution_id": eid, "t_s": t}).json()
        assert out["node"] == "/plan/ara/replay", out  # under the planned robot
        base = scene.server.scene.get_handle_by_name("/plan/ara")
        where.append(np.array(base.position, dtype=float))  # a copy: viser updates in place
    steps = [float(np.linalg.norm(b - a)) for a, b in itertools.pairwise(where)]
    assert all(s > 0.05 for s in steps), (steps, where)
    # At the start and the end it stands on the path's ends (lifted off the steel).
    assert np.linalg.norm(where[0] - path[0]) < 0.05
    assert np.linalg.norm(where[-1] - path[-1]) < 0.05
