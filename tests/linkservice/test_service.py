"""The robot-link service runs apart from the web server: a stalled event loop,
a crashed service or a blocked store write cannot delay heartbeats or the E-stop."""

from __future__ import annotations

import os
import signal
import threading
import time

import pytest

from robots.emulator.robot import check_exactly_once
from tests.support.procstat import proc_stat
from tests.support.waiting import wait_for as _wait

ESTOP_MODE = 4  # STATE.mode ESTOP (docs/protocol.md §6)


@pytest.fixture
def lapi(make_api):
    api = make_api(emulators=True, emulator_time_scale=4.0)
    for name in api.services.dispatch.robot_names():
        assert api.services.dispatch.wait_connected(name, 30), name
    return api


def _dispatch_demo(api, robot: str = "ara") -> tuple[str, dict]:
    plan = api.wait(api.submit("demo.route")["id"])
    assert plan["state"] == "planned", plan
    assert api.post(f"/api/v1/plans/{plan['id']}/approve").status_code == 200
    r = api.post(f"/api/v1/plans/{plan['id']}/dispatch", json={"robot": robot})
    assert r.status_code == 201, r.text
    return r.json()["id"], plan


def test_link_service_is_a_process_of_its_own(lapi) -> None:
    eng = lapi.services.dispatch
    stats = eng.stats()
    assert stats["pid"] == eng.pid and stats["pid"] != os.getpid()
    # It runs at least at the default priority; planning workers run below it.
    assert stats["nice"] <= 0
    for name in eng.robot_names():
        emu = lapi.services.emulators[name]
        assert emu.alive() and emu.pid not in (os.getpid(), stats["pid"])
        # Level with the web server (STEELPATH_EMULATOR_NICE=0), not ahead of it.
        st = proc_stat(emu.pid)
        assert st is not None and st.nice == os.nice(0)


def test_stalled_event_loop_cannot_delay_the_link_service(lapi) -> None:
    """Block the web server's event loop; the link service keeps the robot's
    link alive (heartbeats, acks) and obeys an E-stop while the loop is still
    blocked — the E-stop takes no step on that loop."""
    eng, store = lapi.services.dispatch, lapi.services.store
    eid, _ = _dispatch_demo(lapi)
    _wait(lambda: store.get_execution(eid).state == "running", 30, "running")
    started, release = threading.Event(), threading.Event()

    async def stall() -> None:
        started.set()
        release.wait(60)  # blocks the whole event loop, as a CPU-bound handler would

    lapi.client.portal.start_task_soon(stall)
    assert started.wait(10)
    try:
        link_before = eng.robot_status("ara")
        # Longer than the robot's watchdog (0.5 s) and the host's link timeout (1 s).
        time.sleep(2.0)
        during = eng.robot_status("ara")
        assert during["connected"], during
        assert during["stats"].get("links_lost", 0) == link_before["stats"].get("links_lost", 0)
        reached = eng.estop(None, "stalled-loop test")
        assert "ara" in reached
        report = _wait(
            lambda: (r := eng.robot_status("ara")["report"]) and r["mode"] == ESTOP_MODE and r,
            10,
            "the robot reporting ESTOP",
        )
        assert report["executing"] == -1
        assert not release.is_set()  # all of the above happened while the loop was blocked
    finally:
        release.set()
    ex = _wait(
        lambda: (e := store.get_execution(eid)).state == "interrupted" and e,
        10,
        "execution interrupted",
    )
    assert ex.acked < ex.total and "E-stop: stalled-loop test" in (ex.fault or ""), ex
    # The robot itself saw no watchdog or link loss during the stall.
    reasons = [s["reason"] for s in lapi.services.emulators["ara"].stop_events()]
    assert "estop" in reasons and "watchdog" not in reasons and "link_lost" not in reasons


def test_a_crashed_link_service_restarts_and_the_run_resumes_exactly_once(lapi) -> None:
    eng, store = lapi.services.dispatch, lapi.services.store
    eid, _ = _dispatch_demo(lapi)
    _wait(lambda: store.get_execution(eid).acked >= 1, 60, "one completed command")
    old_pid = eng.pid
    os.kill(old_pid, signal.SIGKILL)
    _wait(lambda: eng.pid != old_pid and eng.restarts >= 1, 30, "a new link service")
    new_pid = eng.pid
    assert eng.stats()["pid"] == new_pid
    time.sleep(1.5)  # the new service stays up (it is not tied to a short-lived thread)
    assert (eng.pid, eng.restarts) == (new_pid, 1)
    ex = _wait(
        lambda: (e := store.get_execution(eid)).state == "interrupted" and e, 30, "interrupted"
    )
    assert eng.wait_connected("ara", 30)
    r = lapi.post(f"/api/v1/executions/{eid}/resume")
    assert r.status_code == 200, r.text
    done = _wait(
        lambda: (e := store.get_execution(eid)).state == "completed" and e, 120, "completed"
    )
    log = lapi.services.emulators["ara"].execution_log()
    assert check_exactly_once(log, done.run_id, done.total) == []
    assert store.list_acks(eid) == list(range(done.total))
    assert ex.acked <= done.total


def test_a_clear_right_after_an_estop_sticks_and_the_next_dispatch_runs(lapi) -> None:
    """The E-stop's bookkeeping (after the reply) must not latch the link again
    over an operator's clear, and a dispatch right after the clear must not
    meet a robot still reporting its E-stop."""
    eng, store = lapi.services.dispatch, lapi.services.store
    eid, _ = _dispatch_demo(lapi)
    _wait(lambda: store.get_execution(eid).state == "running", 30, "running")
    assert lapi.post("/api/v1/estop").status_code == 200
    cleared = lapi.post("/api/v1/robots/ara/clear-estop")
    assert cleared.status_code == 200 and not cleared.json()["estop_latched"]
    _wait(lambda: store.get_execution(eid).state == "interrupted", 10, "execution interrupted")
    time.sleep(0.5)  # the bookkeeping has run by now
    status = eng.robot_status("ara")
    assert not status["estop_latched"], status
    assert not status["report"]["faults"] & 0x0004, status["report"]  # the robot agrees
    # The E-stopped run holds the robot until the operator resumes or ends it.
    assert lapi.post(f"/api/v1/executions/{eid}/abort").json()["state"] == "aborted"
    eid2, _ = _dispatch_demo(lapi)
    done = _wait(
        lambda: (e := store.get_execution(eid2)).state in ("completed", "faulted", "aborted") and e,
        60,
        "second run finished",
    )
    assert done.state == "completed", done


def _sigterm_open_threads(pid: int) -> list[str]:
    """The service's threads, but the main one, that leave SIGTERM unblocked.

    The main thread blocks SIGTERM too, but the kernel opens it while that
    thread sits in ``sigtimedwait`` (which is how the service takes it)."""
    bit = 1 << (signal.SIGTERM - 1)
    open_ = []
    for tid in os.listdir(f"/proc/{pid}/task"):
        if int(tid) == pid:
            continue
        try:
            with open(f"/proc/{pid}/task/{tid}/status") as f:
                fields = dict(line.split(":", 1) for line in f if ":" in line)
        except FileNotFoundError:  # the thread ended meanwhile
            continue
        if not int(fields["SigBlk"].strip(), 16) & bit:
            open_.append(f"{tid} ({fields['Name'].strip()})")
    return open_


def test_no_thread_of_the_link_service_but_the_main_one_takes_sigterm(lapi) -> None:
    """A SIGTERM taken by any other thread ends the process at once, without
    the orderly shutdown (links stopped, leases kept or released, the store
    closed): threads started while importing (a BLAS pool) must not exist or
    must block it."""
    pid = lapi.services.dispatch.pid
    assert pid is not None and pid != os.getpid()
    open_ = _sigterm_open_threads(pid)
    assert open_ == [], f"threads of the link service that take SIGTERM: {open_}"
