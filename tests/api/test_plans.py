"""The plans resource end to end through the demo kind (thread-mode jobs)."""

from __future__ import annotations

import json

import numpy as np


def test_submit_plan_and_read_it_back(api) -> None:
    created = api.submit("demo.route")
    assert created["state"] == "queued" and created["progress"] == 0.0
    plan = api.wait(created["id"])
    assert plan["state"] == "planned"
    assert plan["progress"] == 1.0 and plan["stage"] == "done"
    # Dijkstra on the default 3×3 grid (1 m spacing) from a0 to c2: 4 m.
    assert plan["metrics"]["route_length_m"] == 4.0
    assert [c["name"] for c in plan["checks"]] == ["route_found", "route_length", "command_program"]
    assert all(set(c) == {"name", "passed", "value", "limit", "message"} for c in plan["checks"])
    assert plan["result"]["path"][0] == "a0" and plan["result"]["path"][-1] == "c2"
    assert [a["action"] for a in reversed(plan["audit"])] == ["submit", "start", "finish"]
    assert "approve" in plan["allowed_actions"]
    arr = api.get(f"/api/v1/plans/{plan['id']}/arrays/path_xyz?format=json").json()
    assert arr["shape"] == [5, 3]
    assert np.allclose(np.array(arr["data"])[[0, -1]], [[0, 0, 0], [2, 2, 0]])


def test_list_filters_and_pagination(api) -> None:
    ids = [api.submit("demo.route", {"end": e})["id"] for e in ("b1", "c2", "a2")]
    for i in ids:
        api.wait(i)
    listed = api.get("/api/v1/plans", "viewer").json()
    assert [p["id"] for p in listed] == ids[::-1]
    assert "result" not in listed[0]
    assert len(api.get("/api/v1/plans?limit=2").json()) == 2
    assert [p["id"] for p in api.get("/api/v1/plans?limit=2&offset=2").json()] == [ids[0]]
    assert api.get("/api/v1/plans?kind=nope").json() == []
    assert len(api.get("/api/v1/plans?state=planned").json()) == 3
    r = api.get("/api/v1/plans?state=bogus")
    assert r.status_code == 422 and "'planned'" in r.text  # the error lists the states


def test_approve_and_illegal_transitions(api) -> None:
    pid = api.wait(api.submit("demo.route")["id"])["id"]
    r = api.post(f"/api/v1/plans/{pid}/approve", json={"comment": "looks safe"})
    assert r.status_code == 200 and r.json()["state"] == "approved"
    assert r.json()["approved_by"].startswith("test-operator")
    again = api.post(f"/api/v1/plans/{pid}/approve")
    assert again.status_code == 409
    body = again.json()
    assert body["state"] == "approved" and "dispatch" in body["allowed_actions"]
    assert "it is approved" in body["detail"]
    cancel = api.post(f"/api/v1/plans/{pid}/cancel")
    assert cancel.status_code == 409 and cancel.json()["state"] == "approved"
    audit = api.get(f"/api/v1/plans/{pid}").json()["audit"]
    assert audit[0]["action"] == "approve" and audit[0]["reason"] == "looks safe"


def test_failed_check_rejects_and_blocks_approval(api) -> None:
    pid = api.submit("demo.route", {"max_length_m": 1.5})["id"]
    plan = api.wait(pid)
    assert plan["state"] == "rejected"
    bad = [c for c in plan["checks"] if not c["passed"]]
    assert [c["name"] for c in bad] == ["route_length"] and bad[0]["value"] == 4.0
    r = api.post(f"/api/v1/plans/{pid}/approve")
    assert r.status_code == 409
    assert "route_length" in r.json()["detail"]["message"]
    assert r.json()["detail"]["failed_checks"] == ["route_length"]


def test_revision_creates_linked_plan_and_keeps_parent(api) -> None:
    parent = api.wait(api.submit("demo.route")["id"])
    api.post(f"/api/v1/plans/{parent['id']}/approve")
    r = api.post(f"/api/v1/plans/{parent['id']}/revise", json={"params": {"end": "a2"}})
    assert r.status_code == 202
    child = api.wait(r.json()["id"])
    assert child["parent_id"] == parent["id"]
    assert child["params"]["end"] == "a2" and child["params"]["start"] == "a0"
    assert child["metrics"]["route_length_m"] == 2.0
    again = api.get(f"/api/v1/plans/{parent['id']}").json()
    assert again["state"] == "approved" and again["params"]["end"] == "c2"
    assert again["revisions"] == [child["id"]]
    assert [p["id"] for p in api.get(f"/api/v1/plans?parent_id={parent['id']}").json()] == [
        child["id"]
    ]


def test_planner_error_fails_plan_and_server_keeps_serving(api) -> None:
    # Valid at submission, infeasible in the planner: two components.
    params = {"edges": [["a0", "a1"], ["c1", "c2"]], "start": "a0", "end": "c2"}
    plan = api.wait(api.submit("demo.route", params)["id"])
    assert plan["state"] == "failed"
    assert "InfeasibleError" in plan["error"] and "different components" in plan["error"]
    assert api.get("/api/v1/health").status_code == 200
    assert api.wait(api.submit("demo.route")["id"])["state"] == "planned"


def test_bad_requests(api) -> None:
    r = api.post("/api/v1/plans", json={"kind": "nope.kind", "params": {}})
    assert r.status_code == 422 and "known kinds" in r.json()["detail"]
    r = api.post("/api/v1/plans", json={"kind": "demo.route", "params": {"start": "zz"}})
    assert r.status_code == 422 and "'zz' is not in the graph" in r.json()["detail"]
    r = api.post("/api/v1/plans", json={"kind": "demo.route", "params": {"max_length_m": -1}})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["max_length_m"]
    r = api.post("/api/v1/plans", json={"params": {}})
    assert r.status_code == 422
    r = api.client.post(
        "/api/v1/plans",
        content=b"{not json",
        headers={**api.headers(), "Content-Type": "application/json"},
    )
    assert r.status_code == 422
    r = api.post(
        "/api/v1/plans", json={"kind": "demo.route", "params": {}, "parent_id": "pl_missing"}
    )
    assert r.status_code == 404 and "pl_missing" in r.json()["detail"]
    for method, path in (
        ("get", "/api/v1/plans/pl_missing"),
        ("post", "/api/v1/plans/pl_missing/approve"),
        ("post", "/api/v1/plans/pl_missing/cancel"),
        ("post", "/api/v1/plans/pl_missing/revise"),
        ("delete", "/api/v1/plans/pl_missing"),
        ("get", "/api/v1/plans/pl_missing/arrays/x"),
    ):
        r = getattr(api, method)(path)
        assert r.status_code == 404, (method, path, r.text)
        assert "no plan with id 'pl_missing'" in r.json()["detail"]
    pid = api.wait(api.submit("demo.route")["id"])["id"]
    r = api.get(f"/api/v1/plans/{pid}/arrays/nothing")
    assert r.status_code == 404 and "path_xyz" in r.json()["detail"]


def test_delete_rules(api) -> None:
    pid = api.wait(api.submit("demo.route")["id"])["id"]
    assert api.delete(f"/api/v1/plans/{pid}", "viewer").status_code == 403
    assert api.delete(f"/api/v1/plans/{pid}").status_code == 204
    assert api.get(f"/api/v1/plans/{pid}").status_code == 404
    # Not while executing: move one to executing through the store.
    pid2 = api.wait(api.submit("demo.route")["id"])["id"]
    api.post(f"/api/v1/plans/{pid2}/approve")
    api.services.store.create_execution(pid2, "ara", 1, "test")
    r = api.delete(f"/api/v1/plans/{pid2}")
    assert r.status_code == 409 and r.json()["state"] == "executing"
    assert "abort" in r.json()["allowed_actions"]


def test_cancel_queued_and_running(api) -> None:
    slow = api.submit("demo.route", {"step_delay_s": 0.5})
    api.wait(slow["id"], until=("planning",))
    queued = [api.submit("demo.route", {"step_delay_s": 0.5}) for _ in range(2)]
    # Two workers: the third plan is still queued; cancel it first.
    r = api.post(f"/api/v1/plans/{queued[-1]['id']}/cancel")
    assert r.status_code == 200
    assert api.wait(queued[-1]["id"])["state"] == "cancelled"
    r = api.post(f"/api/v1/plans/{slow['id']}/cancel")
    assert r.json()["outcome"] in ("cancelling", "cancelled")
    plan = api.wait(slow["id"])
    assert plan["state"] == "cancelled" and plan["progress"] < 1.0
    assert api.wait(queued[0]["id"], timeout=30)["state"] in ("planned", "cancelled")


def test_events_stream_replays_plan_changes(api) -> None:
    pid = api.wait(api.submit("demo.route", {"step_delay_s": 0.05})["id"])["id"]
    r = api.get("/api/v1/events?once=true")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/event-stream")
    events = []
    for block in r.text.split("\n\n"):
        lines = dict(line.split(": ", 1) for line in block.splitlines() if not line.startswith(":"))
        if lines.get("event") == "plan":
            events.append(json.loads(lines["data"]))
    states = [e["state"] for e in events if e["id"] == pid]
    assert states[0] == "queued" and states[-1] == "planned" and "planning" in states
    assert any(e.get("stage", "").startswith("step") for e in events if e["id"] == pid)


def test_progress_is_visible_while_planning(api) -> None:
    pid = api.submit("demo.route", {"step_delay_s": 0.3})["id"]
    seen = set()
    plan = api.get(f"/api/v1/plans/{pid}").json()
    while plan["state"] in ("queued", "planning"):
        if plan["state"] == "planning":
            seen.add((round(plan["progress"], 3), plan["stage"]))
        plan = api.get(f"/api/v1/plans/{pid}").json()
    assert plan["state"] == "planned"
    stages = {s for _, s in seen}
    assert any(s.startswith("step") for s in stages), seen
    assert len({p for p, _ in seen}) >= 2


def test_kinds_endpoint(api) -> None:
    kinds = {k["name"]: k for k in api.get("/api/v1/kinds", "viewer").json()}
    demo = kinds["demo.route"]
    assert demo["defaults"]["start"] == "a0"
    assert "max_length_m" in demo["params_schema"]["properties"]
    assert "demo_plane" in demo["samples"]


# ------------------------------------------------------- unknown params keys
def test_misspelt_params_key_is_refused_naming_it(api) -> None:
    r = api.post("/api/v1/plans", json={"kind": "demo.route", "params": {"strat": "b1"}})
    assert r.status_code == 422, r.text
    detail = r.json()["detail"]
    assert isinstance(detail, list)
    assert [e["loc"] for e in detail] == [["strat"]] and "strat" in r.text
    assert api.get("/api/v1/plans", "viewer").json() == []  # nothing was queued


def test_every_kind_forbids_unknown_params_keys(api) -> None:
    from server.kinds import registry

    kinds = sorted(registry())
    assert len(kinds) >= 7
    for kind in kinds:
        r = api.post("/api/v1/plans", json={"kind": kind, "params": {"no_such_key": 1}})
        assert r.status_code == 422, (kind, r.text)
        locs = [e["loc"] for e in r.json()["detail"]]
        assert ["no_such_key"] in locs, (kind, locs)
        assert {e["type"] for e in r.json()["detail"]} == {"extra_forbidden"}, kind


def test_nested_params_models_forbid_unknown_keys() -> None:
    """Nested parts (girder, robot overrides, surfaces, guardrail…) are strict too."""
    import typing

    from pydantic import BaseModel

    from server.kinds import registry

    seen: set[type] = set()

    def walk(model: type[BaseModel]) -> None:
        if model in seen:
            return
        seen.add(model)
        assert model.model_config.get("extra") == "forbid", model.__name__
        for field in model.model_fields.values():
            stack = [field.annotation]
            while stack:
                t = stack.pop()
                stack.extend(typing.get_args(t))
                if isinstance(t, type) and issubclass(t, BaseModel):
                    walk(t)

    for kind in registry().values():
        walk(kind.params_model)
    assert len(seen) > len(registry())  # nested models were found and checked


def test_legacy_rows_with_unknown_keys_still_load_run_and_revise(api) -> None:
    """A plan stored before params were strict (extra key in its row) is not broken."""
    store = api.services.store
    legacy = store.create_plan("demo.route", {"start": "a0", "old_knob": 3}, "test")
    api.services.jobs.submit(legacy.id)
    done = api.wait(legacy.id)
    assert done["state"] == "planned", done
    assert done["params"]["old_knob"] == 3  # the stored row is shown as it is
    r = api.post(f"/api/v1/plans/{legacy.id}/revise", json={"params": {"end": "c1"}})
    assert r.status_code == 202, r.text
    assert "old_knob" not in r.json()["params"] and r.json()["params"]["end"] == "c1"
    r = api.post(f"/api/v1/plans/{legacy.id}/revise", json={"params": {"ned": "c1"}})
    assert r.status_code == 422 and [e["loc"] for e in r.json()["detail"]] == [["ned"]]


def test_listing_is_a_summary_with_the_program_length(api) -> None:
    plan = api.wait(api.submit("demo.route")["id"])
    full = api.get(f"/api/v1/plans/{plan['id']}").json()
    (listed,) = [p for p in api.get("/api/v1/plans").json() if p["id"] == plan["id"]]
    assert "result" not in listed and "program" not in listed
    assert listed["program_length"] == len(full["program"]) > 0
    assert listed["checks"] == full["checks"] and listed["metrics"] == full["metrics"]
