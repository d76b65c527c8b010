"""Dispatch through the REST API to the embedded emulators."""

from __future__ import annotations

import pytest

from robots.emulator.robot import check_exactly_once
from tests.support.waiting import wait_for as _wait


@pytest.fixture
def dapi(make_api):
    api = make_api(emulators=True, emulator_time_scale=40.0)
    eng = api.services.dispatch
    for name in eng.robot_names():
        assert eng.wait_connected(name, 20), name
    return api


def approved_demo(api, **params) -> dict:
    plan = api.wait(api.submit("demo.route", params)["id"])
    assert plan["state"] == "planned", plan
    assert api.post(f"/api/v1/plans/{plan['id']}/approve").status_code == 200
    return api.get(f"/api/v1/plans/{plan['id']}").json()


def wait_execution(api, eid: str, states: tuple[str, ...], timeout: float = 60.0) -> dict:
    return _wait(
        lambda: (ex := api.get(f"/api/v1/executions/{eid}").json())["state"] in states and ex,
        timeout,
        f"execution {eid} in {states}",
    )


def exactly_once(api, robot: str, ex: dict) -> list[str]:
    emulator = api.services.emulators[robot]
    return check_exactly_once(emulator.execution_log(), ex["run_id"], ex["total"])


def test_robots_panel(dapi) -> None:
    robots = {r["name"]: r for r in dapi.get("/api/v1/robots", "viewer").json()}
    assert set(robots) == {"ara", "cmbot", "denso_vm6083", "sbg_climber"}
    for r in robots.values():
        assert r["connected"] and r["emulated"] and r["url"].startswith("socket://127.0.0.1:")
        assert r["robot_info"] is not None and r["last_heartbeat"] is not None
    state = dapi.get("/api/v1/robots/ara/state", "viewer").json()
    assert state["report"] is not None and "q_rad" in state["report"]
    assert dapi.get("/api/v1/robots/nope/state").status_code == 404


def test_compiled_program_is_stored_and_checked(dapi) -> None:
    plan = approved_demo(dapi)
    prog = plan["program"]
    assert prog[-1] == {"op": "stop"} and all(c["op"] in ("wheels", "stop") for c in prog)
    check = next(c for c in plan["checks"] if c["name"] == "command_program")
    assert check["passed"] and check["value"] == len(prog) == plan["program_length"]


def test_dispatch_runs_to_completion_exactly_once(dapi) -> None:
    plan = approved_demo(dapi, end="b1")
    r = dapi.post(f"/api/v1/plans/{plan['id']}/dispatch", json={"robot": "ara"})
    assert r.status_code == 201, r.text
    ex = wait_execution(dapi, r.json()["id"], ("completed",))
    assert ex["acked"] == ex["total"] == len(plan["program"])
    assert dapi.services.store.list_acks(ex["id"]) == list(range(ex["total"]))
    assert exactly_once(dapi, "ara", ex) == []
    assert dapi.get(f"/api/v1/plans/{plan['id']}").json()["state"] == "completed"
    actions = [
        a["action"] for a in reversed(dapi.get(f"/api/v1/executions/{ex['id']}").json()["audit"])
    ]
    assert actions == ["create", "start", "complete"]


def test_dispatch_refusals(dapi) -> None:
    planned = dapi.wait(dapi.submit("demo.route")["id"])
    r = dapi.post(f"/api/v1/plans/{planned['id']}/dispatch", json={"robot": "ara"})
    assert r.status_code == 409 and "planned" in r.json()["detail"]  # not approved
    plan = approved_demo(dapi)
    r = dapi.post(f"/api/v1/plans/{plan['id']}/dispatch", "viewer", json={"robot": "ara"})
    assert r.status_code == 403
    r = dapi.post(f"/api/v1/plans/{plan['id']}/dispatch", json={"robot": "hal9000"})
    assert r.status_code == 404 and "hal9000" in r.json()["detail"]
    r = dapi.post(f"/api/v1/plans/{plan['id']}/dispatch", json={"robot": "cmbot"})
    assert r.status_code == 409 and "drives robot 'ara'" in r.json()["detail"]
    r = dapi.post("/api/v1/plans/pl_missing/dispatch", json={"robot": "ara"})
    assert r.status_code == 404
    # A disconnected robot: point ara at a port nobody listens on.
    r = dapi.put("/api/v1/robots/ara/connection", "operator", json={"url": "socket://127.0.0.1:9"})
    assert r.status_code == 403  # connections are admin business
    r = dapi.put("/api/v1/robots/ara/connection", "admin", json={"url": "socket://127.0.0.1:9"})
    assert r.status_code == 200
    r = dapi.post(f"/api/v1/plans/{plan['id']}/dispatch", json={"robot": "ara"})
    assert r.status_code == 409 and "not connected" in r.json()["detail"]
    assert dapi.get(f"/api/v1/plans/{plan['id']}").json()["state"] == "approved"
    r = dapi.put("/api/v1/robots/ara/connection", "admin", json={"url": "ftp://x"})
    assert r.status_code == 422
    assert dapi.services.store.robot_urls()["ara"] == "socket://127.0.0.1:9"


def test_pause_resume_abort(dapi) -> None:
    plan = approved_demo(dapi)
    eid = dapi.post(f"/api/v1/plans/{plan['id']}/dispatch", json={"robot": "ara"}).json()["id"]
    wait_execution(dapi, eid, ("running",))
    assert dapi.post(f"/api/v1/executions/{eid}/pause").json()["state"] == "paused"
    assert dapi.get(f"/api/v1/plans/{plan['id']}").json()["state"] == "paused"
    r = dapi.post(f"/api/v1/executions/{eid}/pause")
    assert r.status_code == 409 and r.json()["state"] == "paused"
    assert dapi.post(f"/api/v1/executions/{eid}/resume").json()["state"] == "running"
    ex = dapi.post(f"/api/v1/executions/{eid}/abort").json()
    assert ex["state"] == "aborted"
    assert dapi.get(f"/api/v1/plans/{plan['id']}").json()["state"] == "aborted"
    assert dapi.post(f"/api/v1/executions/{eid}/resume").status_code == 409


def test_estop_stops_the_run_and_it_resumes_once_cleared(dapi) -> None:
    """An E-stop stops the robot and leaves its run ``interrupted`` with the reason
    and who pressed it; nothing moves until the E-stop is cleared; then *resume*
    finishes the run from where it stopped, every command exactly once."""
    plan = approved_demo(dapi)
    eid = dapi.post(f"/api/v1/plans/{plan['id']}/dispatch", json={"robot": "ara"}).json()["id"]
    wait_execution(dapi, eid, ("running",))
    emulator = dapi.services.emulators["ara"]
    r = dapi.post("/api/v1/estop", json={"reason": "person on the girder"})
    assert r.status_code == 200 and r.json()["errors"] == []
    _wait(lambda: emulator.stop_events(), 5, "emulator stop event")
    ex = wait_execution(dapi, eid, ("interrupted",))
    assert ex["acked"] < ex["total"]
    assert "E-stop: person on the girder" in ex["fault"] and "operator" in ex["fault"], ex
    assert dapi.get(f"/api/v1/plans/{plan['id']}").json()["state"] == "interrupted"
    stop = [e for e in ex["audit"] if e["action"] == "interrupt"]
    assert len(stop) == 1 and stop[0]["actor"] == "estop" and stop[0]["ts"], ex["audit"]
    assert "clear the E-stop, then resume" in stop[0]["reason"]
    assert dapi.get("/api/v1/robots/ara/state").json()["estop_latched"]
    # Nothing moves while it is latched: no resume, no other run on the robot.
    r = dapi.post(f"/api/v1/executions/{eid}/resume")
    assert r.status_code == 409 and "clear the E-stop" in r.json()["detail"]
    plan2 = approved_demo(dapi)
    r = dapi.post(f"/api/v1/plans/{plan2['id']}/dispatch", json={"robot": "ara"})
    assert r.status_code == 409, r.text
    dapi.post("/api/v1/robots/ara/clear-estop")
    _wait(lambda: dapi.services.dispatch.wait_connected("ara", 0.1), 10, "reconnect")
    # The interrupted run still holds the robot: resumed, it completes once.
    r = dapi.post(f"/api/v1/plans/{plan2['id']}/dispatch", json={"robot": "ara"})
    assert r.status_code == 409 and eid in r.json()["detail"], r.text
    r = _wait(
        lambda: (x := dapi.post(f"/api/v1/executions/{eid}/resume")).status_code == 200 and x,
        10,
        "resume accepted once the robot reports the E-stop cleared",
    )
    done = wait_execution(dapi, eid, ("completed",), timeout=120)
    assert check_exactly_once(emulator.execution_log(), done["run_id"], done["total"]) == []
    assert dapi.services.store.list_acks(eid) == list(range(done["total"]))
    # Then the robot is free for the next plan.
    r = dapi.post(f"/api/v1/plans/{plan2['id']}/dispatch", json={"robot": "ara"})
    assert r.status_code == 201, r.text
    wait_execution(dapi, r.json()["id"], ("completed",))
    assert dapi.post("/api/v1/robots/nope/estop").status_code == 404


def test_an_estopped_run_can_be_aborted(dapi) -> None:
    plan = approved_demo(dapi)
    eid = dapi.post(f"/api/v1/plans/{plan['id']}/dispatch", json={"robot": "ara"}).json()["id"]
    wait_execution(dapi, eid, ("running",))
    assert dapi.post("/api/v1/robots/ara/estop").status_code == 200
    wait_execution(dapi, eid, ("interrupted",))
    ex = dapi.post(f"/api/v1/executions/{eid}/abort").json()
    assert ex["state"] == "aborted" and ex["acked"] < ex["total"]
    assert dapi.post(f"/api/v1/executions/{eid}/resume").status_code == 409


def test_server_restart_mid_run_resumes_without_loss(make_api, tmp_path) -> None:
    data = tmp_path / "v"
    first = make_api(data=data, emulators=True, emulator_time_scale=10.0)
    assert first.services.dispatch.wait_connected("ara", 20)
    plan = approved_demo(first)
    eid = first.post(f"/api/v1/plans/{plan['id']}/dispatch", json={"robot": "ara"}).json()["id"]
    _wait(lambda: first.get(f"/api/v1/executions/{eid}").json()["acked"] >= 2, 60, "two acks")
    # The emulators are processes of their own: like robots, they outlive the
    # server (detach them so the clean exit below does not stop them either).
    emulators = first.services.emulators
    first.services.emulators = None
    emulator = emulators["ara"]
    first.client.__exit__(None, None, None)
    assert emulator.alive()
    second = make_api(data=data, emulators=True, emulator_time_scale=10.0)
    assert second.services.emulators["ara"].pid == emulator.pid  # found and reused
    ex = second.get(f"/api/v1/executions/{eid}").json()
    assert ex["state"] == "interrupted"
    assert second.get(f"/api/v1/plans/{plan['id']}").json()["state"] == "interrupted"
    # Interrupted once, by the server that drives the robot now, saying why.  The
    # first server closing its own links as it stopped is no link loss of the
    # robot's: recorded as one ("robot", "link_lost: closed") it hid the reason.
    interrupts = [(e["actor"], e["reason"]) for e in ex["audit"] if e["action"] == "interrupt"]
    assert len(interrupts) == 1, ex["audit"]
    assert interrupts[0][0] == "system" and "took the robot over" in interrupts[0][1], interrupts
    assert second.services.dispatch.wait_connected("ara", 20)
    r = second.post(f"/api/v1/executions/{eid}/resume")
    assert r.status_code == 200, r.text
    done = wait_execution(second, eid, ("completed",), timeout=120)
    assert check_exactly_once(emulator.execution_log(), done["run_id"], done["total"]) == []
    assert second.services.store.list_acks(eid) == list(range(done["total"]))


def test_estop_while_reconnecting_reaches_the_robot_when_it_returns(dapi) -> None:
    eng = dapi.services.dispatch
    emulator = dapi.services.emulators["ara"]
    dapi.put("/api/v1/robots/ara/connection", "admin", json={"url": "socket://127.0.0.1:9"})
    assert not eng.wait_connected("ara", 0.5)
    r = dapi.post("/api/v1/robots/ara/estop")
    assert r.status_code == 200 and r.json()["errors"] == []
    assert dapi.get("/api/v1/robots/ara/state").json()["estop_latched"]
    n = len(emulator.stop_events())
    # The robot comes back: the latched E-stop is delivered first.
    dapi.put("/api/v1/robots/ara/connection", "admin", json={"url": emulator.url})
    _wait(lambda: len(emulator.stop_events()) > n, 10, "E-stop delivered on reconnect")
    assert emulator.stop_events()[-1]["reason"] == "estop"
    # Other robots were not stopped by a per-robot E-stop.
    assert not dapi.get("/api/v1/robots/cmbot/state").json()["estop_latched"]
