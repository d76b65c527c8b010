"""Planning jobs in worker processes: progress, cancel, planner errors, crashes."""

from __future__ import annotations

import time

import pytest

from server.kinds import registry


@pytest.fixture
def papi(make_api, monkeypatch):
    monkeypatch.setenv("STEELPATH_EXTRA_KINDS", "tests.support.kinds")
    registry.cache_clear()
    yield make_api(job_mode="process", job_workers=2)
    registry.cache_clear()


def test_process_jobs_progress_and_cancel(papi) -> None:
    pid = papi.submit("test.job", {"seconds": 60})["id"]
    plan = papi.wait(pid, until=("planning",), timeout=60)
    # Progress advances while the job runs in another process.
    deadline = time.monotonic() + 30
    while plan["stage"] in ("", "start") and time.monotonic() < deadline:
        plan = papi.get(f"/api/v1/plans/{pid}").json()
    assert plan["stage"].startswith("tick") and 0 <= plan["progress"] < 1
    # The HTTP server stays responsive while a job burns a worker.
    t0 = time.monotonic()
    assert papi.get("/api/v1/health").status_code == 200
    assert time.monotonic() - t0 < 5
    r = papi.post(f"/api/v1/plans/{pid}/cancel")
    assert r.status_code == 200
    done = papi.wait(pid, timeout=30)
    assert done["state"] == "cancelled"
    assert any(a["action"] == "cancel" for a in done["audit"])


def test_process_planner_exception_fails_plan(papi) -> None:
    plan = papi.wait(papi.submit("test.job", {"mode": "raise"})["id"], timeout=60)
    assert plan["state"] == "failed"
    assert plan["error"] == "RuntimeError: planner blew up on purpose"
    assert papi.wait(papi.submit("demo.route")["id"], timeout=60)["state"] == "planned"


def test_worker_crash_fails_plan_and_pool_recovers(papi) -> None:
    plan = papi.wait(papi.submit("test.job", {"mode": "crash"})["id"], timeout=60)
    assert plan["state"] == "failed" and "crashed" in plan["error"]
    assert papi.wait(papi.submit("demo.route")["id"], timeout=60)["state"] == "planned"


def test_unstorable_result_fails_cleanly(papi) -> None:
    plan = papi.wait(papi.submit("test.job", {"mode": "nan"})["id"], timeout=60)
    assert plan["state"] == "failed" and "could not be stored" in plan["error"]
