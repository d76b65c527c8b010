"""Restart the app on the same data directory: nothing is lost."""

from __future__ import annotations

import numpy as np


def test_restart_keeps_plans_clouds_executions_audit(make_api, tmp_path) -> None:
    data = tmp_path / "shared-var"
    first = make_api(data=data)
    cloud = first.post("/api/v1/clouds", json={"sample": "demo_plane", "seed": 7}).json()
    planned = first.wait(first.submit("demo.route")["id"])
    rejected = first.wait(first.submit("demo.route", {"max_length_m": 1.0})["id"])
    executing = first.wait(first.submit("demo.route", {"end": "b2"})["id"])
    first.post(f"/api/v1/plans/{executing['id']}/approve")
    ex = first.services.store.create_execution(executing["id"], "ara", 12, "test")
    first.services.store.set_execution_acked(ex.id, 5)
    first.post("/api/v1/estop", json={"reason": "drill"})
    audit_before = first.get("/api/v1/audit?limit=500").json()
    tokens = first.tokens
    first.client.__exit__(None, None, None)

    second = make_api(data=data)
    second.tokens = tokens  # the old tokens still work after a restart
    assert second.get("/api/v1/clouds").json()[0]["id"] == cloud["id"]
    pts = np.load(second.services.store.cloud_path(cloud["id"]))
    assert pts.shape == (5000, 3)
    for old in (planned, rejected):
        new = second.get(f"/api/v1/plans/{old['id']}").json()
        for key in ("state", "params", "metrics", "checks", "result"):
            assert new[key] == old[key], key
    # What was moving when the server went down is interrupted (resumable), not lost.
    assert second.get(f"/api/v1/plans/{executing['id']}").json()["state"] == "interrupted"
    got_ex = second.services.store.get_execution(ex.id)
    assert (got_ex.acked, got_ex.total, got_ex.plan_id) == (5, 12, executing["id"])
    assert got_ex.state == "interrupted"
    audit_after = second.get("/api/v1/audit?limit=500").json()
    assert audit_after[-len(audit_before) :] == audit_before


def test_restart_requeues_interrupted_planning(make_api, tmp_path) -> None:
    data = tmp_path / "v"
    first = make_api(data=data)
    store = first.services.store
    # Simulate a crash while planning: the row says planning, no worker has it.
    kinds = {k["name"]: k for k in first.get("/api/v1/kinds").json()}
    p = store.create_plan("demo.route", kinds["demo.route"]["defaults"], "t")
    store.transition_plan(p.id, "start", "t")
    first.client.__exit__(None, None, None)
    second = make_api(data=data)
    plan = second.wait(p.id)
    assert plan["state"] == "planned"
    assert any(a["action"] == "requeue" for a in plan["audit"])
