"""Planning on a Dask cluster: a real scheduler and two worker
processes on loopback, the app pointed at them with ``dask_scheduler``.

Plans reach the same result as in the local pool; progress and cancel work
through the store; a worker killed mid-plan makes the plan run again once on
the other worker, finished once; a worker stuck without progress is
restarted, and a plan whose runs keep dying fails with a clear error.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from planners.errors import CancelledError, InvalidInputError
from server.app import create_app
from server.auth import create_token
from server.dask_jobs import StoreContext
from server.kinds import registry
from server.store import Store
from server.store.store import worker_name
from tests.conftest import make_settings
from tests.support.dask_cluster import (
    DaskCluster,
    dask_cluster,
    kill_scheduler,
    start_scheduler_again,
)
from tests.support.postgres import pg_url, postgres_server  # noqa: F401

#: The store-level tests run on both backends (a PostgreSQL server is started
#: for the session by tests.support.postgres; skipped, saying why, without one).
BACKENDS = ["sqlite", "postgresql"]


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[DaskCluster]:
    with dask_cluster(tmp_path_factory.mktemp("dask"), workers=2) as c:
        yield c


@pytest.fixture
def dapi(make_api, cluster: DaskCluster, monkeypatch, tmp_path: Path) -> Any:
    """An app whose plans run on the cluster (both workers up), with the test kinds."""
    monkeypatch.setenv("STEELPATH_EXTRA_KINDS", "tests.support.kinds")
    registry.cache_clear()
    cluster.wait_workers(2)

    def factory(**kw: Any) -> Any:
        api = make_api(tmp_path / "dask", dask_scheduler=cluster.address, **kw)
        api.events_seen = []
        api.services.events.add_listener(lambda t, d: api.events_seen.append((t, dict(d))))
        return api

    yield factory
    registry.cache_clear()


def _tick(plan: dict[str, Any]) -> int:
    stage = plan["stage"] or ""
    return int(stage.split()[1]) if stage.startswith("tick ") else 0


def _poll(api: Any, pid: str, ok: Any, timeout: float = 30.0) -> dict[str, Any]:
    deadline = time.monotonic() + timeout
    while True:
        plan = api.get(f"/api/v1/plans/{pid}").json()
        if ok(plan):
            return plan
        assert time.monotonic() < deadline, f"plan never satisfied the condition: {plan}"
        time.sleep(0.05)


def _wait_events(api: Any, pid: str, ok: Any, timeout: float = 5.0) -> list[str]:
    """The states of ``pid``'s plan events once ``ok(states)`` (within ``timeout``)."""
    deadline = time.monotonic() + timeout
    while True:
        states = [d["state"] for t, d in list(api.events_seen) if t == "plan" and d["id"] == pid]
        if ok(states):
            return states
        assert time.monotonic() < deadline, states
        time.sleep(0.05)


def _actions(plan: dict[str, Any]) -> list[str]:
    return [a["action"] for a in plan["audit"]]


def _comparable(plan: dict[str, Any]) -> dict[str, Any]:
    """What must not depend on where a plan ran (timings left out)."""
    metrics = {k: v for k, v in plan["metrics"].items() if "time" not in k}
    return {
        "state": plan["state"],
        "result": plan["result"],
        "checks": plan["checks"],
        "metrics": metrics,
        "arrays": sorted(plan["arrays"]),
        "program_length": plan.get("program_length"),
    }


def test_dask_plans_match_the_local_pool(dapi, make_api, tmp_path: Path) -> None:
    api = dapi()
    local = make_api(tmp_path / "local", job_mode="thread")
    cases: list[tuple[str, dict[str, Any]]] = [("demo.route", {}), ("ara.navigate", {})]
    for kind, params in cases:
        pid = api.submit(kind, params)["id"]
        lid = local.submit(kind, params)["id"]
        plan, ref = api.wait(pid, timeout=120), local.wait(lid, timeout=120)
        assert plan["state"] == "planned", plan
        assert _comparable(plan) == _comparable(ref), kind
        for name in plan["arrays"]:
            a = api.get(f"/api/v1/plans/{pid}/arrays/{name}?format=json").json()
            b = local.get(f"/api/v1/plans/{lid}/arrays/{name}?format=json").json()
            assert np.allclose(np.asarray(a["data"]), np.asarray(b["data"])), name
        # One start on a named worker, one finish; the worker wrote it, the
        # server published it.
        assert _actions(plan).count("finish") == 1 and _actions(plan).count("start") == 1
        rec = api.services.store.get_plan(pid)
        assert rec.attempts == 1 and worker_name(rec.worker) in ("w1", "w2"), rec.worker
        # The server learns the end from the store (its poller, every 0.2 s).
        # A plan that takes a few ms may start and end between two reads: its
        # ``planning`` is in the audit trail, not necessarily on the bus.
        states = _wait_events(api, pid, lambda st: "planned" in st)
        assert states.count("planned") == 1, states
        assert "planning" in states or kind == "demo.route", states
    assert api.services.jobs.running() == []


def test_dask_progress_and_cancel(dapi) -> None:
    api = dapi()
    finished: list[str] = []
    api.services.jobs.on_finished.append(finished.append)
    pid = api.submit("test.job", {"seconds": 60})["id"]
    first = _poll(api, pid, lambda p: _tick(p) >= 1)
    later = _poll(api, pid, lambda p: _tick(p) > _tick(first))
    assert first["state"] == later["state"] == "planning"
    assert 0 <= first["progress"] <= later["progress"] < 1
    # Progress events reach the bus from the store (the server's poller reads
    # it every 0.2 s; the worker's own throttle is tested below).
    time.sleep(1.0)
    progress = [
        d
        for t, d in api.events_seen
        if d.get("id") == pid and str(d.get("stage")).startswith("tick")
    ]
    assert len(progress) >= 2, progress
    assert all(d["state"] == "planning" and 0 <= d["progress"] < 1 for d in progress)
    r = api.post(f"/api/v1/plans/{pid}/cancel")
    assert r.status_code == 200, r.text
    done = api.wait(pid, timeout=15)
    assert done["state"] == "cancelled", done
    assert "cancel" in _actions(done) and "cancel-request" in _actions(done)
    assert _poll(api, pid, lambda p: pid in finished, timeout=5)

    # A plan no worker has started yet is cancelled at once and never runs.
    busy = [api.submit("test.job", {"seconds": 60})["id"] for _ in range(2)]
    for b in busy:
        api.wait(b, until=("planning",), timeout=30)
    queued = api.submit("demo.route")["id"]
    r = api.post(f"/api/v1/plans/{queued}/cancel")
    assert r.status_code == 200, r.text
    plan = api.get(f"/api/v1/plans/{queued}").json()
    assert plan["state"] == "cancelled" and "start" not in _actions(plan), plan
    for b in busy:
        api.post(f"/api/v1/plans/{b}/cancel")
    for b in busy:
        assert api.wait(b, timeout=15)["state"] == "cancelled"
    # Once the workers are free, a task that still reached one finds the plan
    # cancelled in the store and starts nothing.
    time.sleep(0.5)
    assert "start" not in _actions(api.get(f"/api/v1/plans/{queued}").json())
    assert api.services.jobs.running() == []


def test_killed_worker_reruns_the_plan_once_elsewhere(dapi, cluster: DaskCluster) -> None:
    api = dapi()
    store = api.services.store
    pid = api.submit("test.job", {"seconds": 4})["id"]
    _poll(api, pid, lambda p: _tick(p) >= 5)
    first = store.get_plan(pid).worker
    killed = worker_name(first)
    cluster.kill_worker(cluster.workers()[killed])
    plan = api.wait(pid, timeout=60)
    assert plan["state"] == "planned", plan
    acts = _actions(plan)
    assert acts.count("finish") == 1 and acts.count("rerun") == 1, acts
    rerun = next(a for a in plan["audit"] if a["action"] == "rerun")
    assert f"re-run after worker {killed} died" in rerun["reason"], rerun
    assert plan["metrics"]["reruns"] == 1.0
    rec = store.get_plan(pid)
    assert rec.attempts == 2 and worker_name(rec.worker) not in (killed, "?"), rec.worker
    cluster.wait_workers(2)  # the killed worker's nanny started a new one


def test_dask_plans_through_a_postgresql_store(dapi, request: pytest.FixtureRequest) -> None:
    """Workers open the PostgreSQL store the server gives them (database_url)."""
    api = dapi(database_url=request.getfixturevalue("pg_url"))
    pid = api.submit("demo.route")["id"]
    plan = api.wait(pid, timeout=60)
    assert plan["state"] == "planned", plan
    assert _actions(plan).count("finish") == 1
    assert worker_name(api.services.store.get_plan(pid).worker) in ("w1", "w2")


def test_server_restart_requeues_and_the_old_run_writes_nothing(
    cluster: DaskCluster, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """A server stopped mid-plan: the next one re-submits the plan as a fresh
    start; the run still going on a worker stops and finishes nothing."""
    monkeypatch.setenv("STEELPATH_EXTRA_KINDS", "tests.support.kinds")
    registry.cache_clear()
    cluster.wait_workers(2)
    settings = make_settings(tmp_path / "var", dask_scheduler=cluster.address)
    try:
        with TestClient(create_app(settings)) as client:
            store = client.app.state.services.store  # type: ignore[attr-defined]
            h = {"Authorization": f"Bearer {create_token(store, 'op', 'operator', 't')[1]}"}
            r = client.post(
                "/api/v1/plans", headers=h, json={"kind": "test.job", "params": {"seconds": 8}}
            )
            pid = r.json()["id"]
            deadline = time.monotonic() + 30
            while not (store.get_plan(pid).stage or "").startswith("tick"):
                assert time.monotonic() < deadline, store.get_plan(pid)
                time.sleep(0.05)
            old_run = store.get_plan(pid).worker
        with TestClient(create_app(settings)) as client:
            store = client.app.state.services.store  # type: ignore[attr-defined]
            deadline = time.monotonic() + 60
            while (plan := store.get_plan(pid)).state in ("queued", "planning"):
                assert time.monotonic() < deadline, plan
                time.sleep(0.05)
            assert plan.state == "planned", plan
            assert plan.attempts == 1 and plan.worker != old_run
            acts = [e.action for e in reversed(store.list_audit("plan", pid))]
            assert acts.count("requeue") == 1 and acts.count("finish") == 1, acts
            assert "rerun" not in acts and "fail" not in acts, acts
    finally:
        registry.cache_clear()


@pytest.mark.parametrize("client_gives_up", [False, True], ids=["reconnects", "new-client"])
def test_a_lost_scheduler_loses_no_plan_and_finishes_each_once(
    make_api, monkeypatch: pytest.MonkeyPatch, tmp_path: Path, client_gives_up: bool
) -> None:
    """The scheduler is killed while one plan is planning; a second plan is
    submitted while it is down.  Once a supervisor has started the scheduler
    and workers again, both are planned: the first re-queued once (its run
    died with its worker), each finished once, none failed.  The client either
    reconnects by itself, or (``new-client``) has given up and closed, and the
    runner makes a new one."""
    monkeypatch.setenv("STEELPATH_EXTRA_KINDS", "tests.support.kinds")
    registry.cache_clear()
    try:
        with dask_cluster(tmp_path / "dask-lost", workers=1) as c:
            api = make_api(tmp_path / "var", dask_scheduler=c.address)
            jobs = api.services.jobs
            old_client = jobs._client
            if client_gives_up:
                # Dask's reconnect deadline (the connect timeout, 30 s in the app).
                old_client._timeout = 0.5
            first = api.submit("test.job", {"seconds": 3})["id"]
            _poll(api, first, lambda p: (p["stage"] or "").startswith("tick"))
            kill_scheduler(c)
            gone = ("closed",) if client_gives_up else ("connecting", "closed")
            deadline = time.monotonic() + 10
            while old_client.status not in gone:
                assert time.monotonic() < deadline, old_client.status
                time.sleep(0.05)
            second = api.submit("test.job", {"seconds": 1})["id"]
            assert api.get(f"/api/v1/plans/{second}").json()["state"] == "queued"
            start_scheduler_again(c)
            for pid in (first, second):
                plan = api.wait(pid, timeout=120)
                assert plan["state"] == "planned", plan
                acts = _actions(plan)
                assert acts.count("finish") == 1 and "fail" not in acts, acts
            requeues = [a for a in api.wait(first)["audit"] if a["action"] == "requeue"]
            assert len(requeues) == 1 and "scheduler was lost" in requeues[0]["reason"]
            assert "requeue" not in _actions(api.wait(second))
            assert (jobs._client is not old_client) == client_gives_up
    finally:
        registry.cache_clear()


def test_stuck_worker_is_restarted_and_runs_stop_after_one_rerun(dapi, cluster) -> None:
    api = dapi(dask_stuck_s=1.5)
    pid = api.submit("test.job", {"mode": "hang", "seconds": 300})["id"]
    plan = api.wait(pid, timeout=90)
    assert plan["state"] == "failed", plan
    assert "started 3 times" in plan["error"], plan["error"]
    acts = _actions(plan)
    assert acts.count("worker-restart") == 2 and acts.count("rerun") == 1, acts
    assert "finish" not in acts
    cluster.wait_workers(2)


def _store(request: pytest.FixtureRequest, backend: str, data: Path) -> Store:
    url = request.getfixturevalue("pg_url") if backend == "postgresql" else None
    return Store(data, database_url=url)


@pytest.mark.parametrize("backend", BACKENDS)
def test_run_writes_are_conditional(
    tmp_path: Path, request: pytest.FixtureRequest, backend: str
) -> None:
    """The store's side, without a cluster: a run that lost its plan writes nothing."""
    store = _store(request, backend, tmp_path / "var")
    try:
        pid = store.create_plan("demo.route", {}, "test").id
        assert store.start_plan_run(pid, "w1@tcp://a#r1")[0] == "run"
        assert store.set_run_progress(pid, "w1@tcp://a#r1", 0.5, "half")
        # w1 died; Dask started the task on w2: a re-run.
        assert store.start_plan_run(pid, "w2@tcp://b#r2")[0] == "run"
        assert store.get_plan(pid).stage == "re-run after worker w1 died"
        assert not store.set_run_progress(pid, "w1@tcp://a#r1", 0.9, "zombie")
        out: dict[str, Any] = {"result": {"x": 1}, "checks": [], "metrics": {}}
        arrays = {"p": np.zeros(3)}
        assert not store.finish_plan_run(pid, "w1@tcp://a#r1", arrays=arrays, **out)
        assert store.finish_plan_run(pid, "w2@tcp://b#r2", arrays=arrays, **out)
        assert not store.finish_plan_run(pid, "w2@tcp://b#r2", arrays=arrays, **out)
        plan = store.get_plan(pid)
        assert plan.state == "planned" and plan.arrays == {"p": "plans/" + pid + "/p.r2.npy"}
        assert list((tmp_path / "var/arrays/plans" / pid).iterdir()) == [
            tmp_path / "var/arrays/plans" / pid / "p.r2.npy"
        ]
        finishes = [e for e in store.list_audit("plan", pid) if e.action == "finish"]
        assert len(finishes) == 1

        # A cancel is not overwritten by the run finishing after it.
        pid = store.create_plan("demo.route", {}, "test").id
        assert store.start_plan_run(pid, "w1@tcp://a#r3")[0] == "run"
        store.request_plan_cancel(pid)
        assert store.plan_run_status(pid, "w1@tcp://a#r3") == (True, True)
        assert store.end_plan_run(pid, "w1@tcp://a#r3", "cancel", "operator", "asked")
        assert not store.finish_plan_run(pid, "w1@tcp://a#r3", arrays={}, **out)
        assert store.get_plan(pid).state == "cancelled"

        # The third start fails the plan; a fresh start of a cancelled-early plan cancels it.
        pid = store.create_plan("demo.route", {}, "test").id
        for run in ("w1@a#1", "w2@b#2"):
            assert store.start_plan_run(pid, run)[0] == "run"
        assert store.start_plan_run(pid, "w1@a#3")[0] == "failed"
        plan = store.get_plan(pid)
        assert plan.state == "failed" and "started 3 times" in (plan.error or "")
        assert store.start_plan_run(pid, "w1@a#4")[0] == "gone"
        pid = store.create_plan("demo.route", {}, "test").id
        store.request_plan_cancel(pid)
        assert store.start_plan_run(pid, "w1@a#5")[0] == "cancelled"
        assert store.get_plan(pid).state == "cancelled"
    finally:
        store.close()


def test_worker_context_throttles_progress_and_honours_cancel(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A run's progress: ≤ 5 store writes a second however often the planner
    reports; a cancel (or losing the plan) raises at the next progress call."""
    store = Store(tmp_path / "var")
    try:
        pid = store.create_plan("test.job", {}, "test").id
        run = "w1@tcp://a#r1"
        assert store.start_plan_run(pid, run)[0] == "run"
        writes: list[tuple[float, str]] = []
        real = store.set_run_progress

        def counting(plan_id: str, r: str, frac: float, stage: str) -> bool:
            writes.append((frac, stage))
            return real(plan_id, r, frac, stage)

        monkeypatch.setattr(store, "set_run_progress", counting)
        ctx = StoreContext(store, pid, run)
        t0 = time.monotonic()
        calls = 0
        while time.monotonic() - t0 < 1.05:
            calls += 1
            ctx.progress(0.5, f"tick {calls}")
            time.sleep(0.002)
        assert calls > 100 and 4 <= len(writes) <= 6, (calls, writes)
        assert store.get_plan(pid).stage == writes[-1][1]
        ctx.progress(1.0, "last")  # the final 1.0 is never held back
        assert writes[-1] == (1.0, "last")
        with pytest.raises(InvalidInputError):
            ctx.load_cloud("cl_nope")
        store.request_plan_cancel(pid)
        assert ctx.cancelled()
        with pytest.raises(CancelledError, match="cancelled"):
            ctx.progress(0.6, "next")
        # A run whose plan was taken over by another run stops the same way.
        pid = store.create_plan("test.job", {}, "test").id
        assert store.start_plan_run(pid, run)[0] == "run"
        ctx = StoreContext(store, pid, run)
        assert store.start_plan_run(pid, "w2@tcp://b#r2")[0] == "run"
        with pytest.raises(CancelledError, match="no longer"):
            ctx.progress(0.1, "zombie")
    finally:
        store.close()
