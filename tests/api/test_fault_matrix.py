"""Each injected link/robot fault × each plan kind that compiles to commands:
the run completes after operator resumes, with nothing lost and nothing
executed twice (asserted from the emulator's own execution log).

``host_crash`` kills the robot-link service; ``kill -9`` of the whole server
(web server and link service) mid-run, with the ARA driving, with a foot in the
air and right after a magnet release, then restart and resume, are the cells
of tests/api/test_resume_mid_jump.py (a real ``steelpath serve`` subprocess and
its embedded emulator processes, which outlive it)."""

from __future__ import annotations

import contextlib
import dataclasses
import os
import signal
import time
from collections.abc import Iterator
from typing import Any

import pytest
from fastapi.testclient import TestClient

from robots.emulator.faults import FaultConfig
from robots.emulator.robot import check_exactly_once
from robots.emulator.server import Emulator
from robots.protocol.auth import load_or_create_secret
from server.app import create_app
from server.auth import create_token
from server.kinds import import_errors, registry
from server.linkservice import robot_key_path
from server.linkservice.client import LinkServiceUnavailable
from tests.conftest import Api, make_settings

pytestmark = pytest.mark.slow

#: Link drops are triggered mid-run (after the first acknowledged command);
#: the rest are the emulator's fault-injection settings.
MID_RUN_DROPS = {"drop": None, "silence": 1.5}
FAULTS: dict[str, FaultConfig] = {
    "drop": FaultConfig(),
    "silence": FaultConfig(),
    "corrupt": FaultConfig(corrupt_rate=0.003, seed=7),
    # delay_s is replaced per program by _delay_for (scaled to its commands).
    "delay": FaultConfig(delay_s=0.15),
    "nak": FaultConfig(nak_index=2, nak_times=2),
    "reject": FaultConfig(nak_index=3, nak_permanent=True),
    "robot_fault": FaultConfig(fault_at_index=3),
    # The robot-link service is killed (SIGKILL) mid-run: its links close, the
    # robot stops mid-command, a new service starts and marks the run
    # interrupted; the resume continues the interrupted command.
    "host_crash": FaultConfig(),
}

#: Small seed experiments per kind, so each run streams its whole program quickly.
PARAMS: dict[str, dict] = {
    "demo.route": {"end": "c1"},
    "sbg.inspect": {},
}

#: Every DESIGN kind that compiles to a robot program (fixed here, not read
#: back from the registry: a kind that silently failed to load would otherwise
#: just drop out of the matrix).
KINDS = sorted(
    [
        "ara.navigate",
        "ara.switch",
        "blast",
        "cmbot.climb",
        "cmbot.manipulate",
        "demo.route",
        "sbg.inspect",
    ]
)

#: Wall seconds each program is scaled to (``time_scale``), so faults land mid-run.
RUN_WALL_S = 3.0


def _delay_for(n_commands: int) -> float:
    """Frame delay for a program of ``n_commands``, scaled to it.

    Each command then lasts ``RUN_WALL_S / n`` wall seconds; holding every frame
    for half of that (clamped to 5–150 ms) keeps the delay comparable to a
    command's own duration — acknowledgements arrive after the motion they
    acknowledge has begun — without a long program paying 150 ms per frame
    (cmbot.climb's 2 475 commands took 21 s at a 20 ms floor).
    """
    return min(0.15, max(0.005, 0.5 * RUN_WALL_S / max(n_commands, 1)))


#: Programs up to this many commands are corrupted at the base rate; longer
#: ones at a rate scaled down to the same expected count of corrupted frames.
CORRUPT_FULL_RATE_COMMANDS = 500


def _corrupt_for(rate: float, n_commands: int) -> float:
    """Per-byte corruption rate for a program of ``n_commands``.

    At 0.003 a byte, about one frame in three arrives corrupted: cmbot.climb's
    2 475 commands then took 1 718 corrupted frames, 6 lost links and 53 s to
    finish, where every other kind takes 10 s.  Past
    :data:`CORRUPT_FULL_RATE_COMMANDS` the rate falls with the length, so a
    long program still sees hundreds of corrupted frames and lost links.
    """
    return rate * min(1.0, CORRUPT_FULL_RATE_COMMANDS / max(n_commands, 1))


def test_every_design_kind_is_registered_and_none_failed_to_import() -> None:
    assert import_errors() == {}
    assert set(KINDS) <= set(registry())
    for kind in KINDS:
        assert registry()[kind].compile is not None and registry()[kind].robot is not None, kind


@pytest.fixture(scope="module")
def mapi(tmp_path_factory) -> Iterator[Api]:
    settings = make_settings(tmp_path_factory.mktemp("faults") / "var", emulators=False)
    app = create_app(settings)
    with TestClient(app) as client:
        store = app.state.services.store
        tokens = {r: create_token(store, r, r, "test")[1] for r in ("viewer", "operator", "admin")}
        yield Api(client, tokens, app)


class _BasePlans(dict):
    """One planned plan per kind, made on first use; each matrix cell revises
    it (an approved plan runs once)."""

    def __init__(self, api: Api) -> None:
        super().__init__()
        self.api = api

    def __missing__(self, kind: str) -> dict:
        plan = self.api.wait(self.api.submit(kind, PARAMS.get(kind, {}))["id"], timeout=300)
        failed = [c for c in plan["checks"] if not c["passed"]]
        assert plan["state"] == "planned", (kind, plan["error"], failed)
        self[kind] = plan
        return plan


@pytest.fixture(scope="module")
def base_plans(mapi) -> dict[str, dict]:
    return _BasePlans(mapi)


def _fresh_approved(mapi: Api, base: dict) -> dict:
    """An approved copy of the kind's planned base plan (an approved plan runs once).

    The planners are deterministic, so a revision would plan the same program
    again; the matrix is about dispatch under faults, so the copy stores the
    base plan's result, checks and program directly instead of re-planning
    (which made each cell cost a full planning run).
    """
    store = mapi.services.store
    copy = store.create_plan(base["kind"], base["params"], "fault-matrix", parent_id=base["id"])
    store.transition_plan(copy.id, "start", "fault-matrix")
    store.store_plan_result(
        copy.id,
        result=base["result"],
        arrays={},
        checks=base["checks"],
        metrics=base["metrics"],
        program=base["program"],
    )
    assert mapi.post(f"/api/v1/plans/{copy.id}/approve").status_code == 200
    plan = mapi.get(f"/api/v1/plans/{copy.id}").json()
    assert plan["state"] == "approved" and plan["program"] == base["program"]
    return plan


@pytest.mark.parametrize("fault", sorted(FAULTS))
@pytest.mark.parametrize("kind", KINDS)
def test_fault_matrix(mapi, base_plans, kind: str, fault: str) -> None:
    robot = registry()[kind].robot
    # Run each program in about RUN_WALL_S of wall time, whatever its length,
    # so the faults land mid-run.
    program = base_plans[kind]["program"]
    duration = sum(c.get("duration_s", 0.0) for c in program)
    scale = max(duration / RUN_WALL_S, 1.0)
    faults = FAULTS[fault]
    if fault == "delay":
        faults = dataclasses.replace(faults, delay_s=_delay_for(len(program)))
    if fault == "corrupt":
        faults = dataclasses.replace(
            faults, corrupt_rate=_corrupt_for(faults.corrupt_rate, len(program))
        )
    plan = _fresh_approved(mapi, base_plans[kind])
    # The robot holds the secret this server's link service uses for it.
    secret = load_or_create_secret(robot_key_path(mapi.services.settings.data, robot))
    emulator = Emulator(robot, faults=faults, time_scale=scale, secret=secret)
    # Count the frames the emulator really holds back (its stats have no
    # counter for delays): wrap, not replace, its scheduler.
    held = [0]
    schedule = emulator._later

    def counting_later(when: float, action, _schedule=schedule) -> None:
        held[0] += 1
        _schedule(when, action)

    emulator._later = counting_later  # type: ignore[method-assign]
    emulator.start()
    eid = None
    try:
        r = mapi.put(f"/api/v1/robots/{robot}/connection", "admin", json={"url": emulator.url})
        assert r.status_code == 200, r.text
        deadline = time.monotonic() + 30
        while True:  # a corrupting or slow link may need a few handshakes
            assert mapi.services.dispatch.wait_connected(robot, 20)
            r = mapi.post(f"/api/v1/plans/{plan['id']}/dispatch", json={"robot": robot})
            if r.status_code == 201 or time.monotonic() > deadline:
                break
        assert r.status_code == 201, r.text
        eid = r.json()["id"]
        resumes, dropped, deadline = 0, False, time.monotonic() + 240
        while True:
            ex = mapi.get(f"/api/v1/executions/{eid}").json()
            if fault in MID_RUN_DROPS and not dropped and ex["acked"] >= 1:
                emulator.drop_link(MID_RUN_DROPS[fault])
                dropped = True
            if fault == "host_crash" and not dropped and ex["acked"] >= 1:
                killed_pid = mapi.services.dispatch.pid
                os.kill(killed_pid, signal.SIGKILL)
                dropped = True
            if ex["state"] == "completed":
                break
            assert ex["state"] != "aborted", ex
            stopped = ex["state"] in ("interrupted", "faulted")
            if stopped and _connected(mapi, robot, 0.2):
                # The operator's decision: resume (clearing a robot fault once "fixed").
                body = {"clear_faults": True} if "robot_fault" in (ex["fault"] or "") else {}
                r = mapi.post(f"/api/v1/executions/{eid}/resume", json=body)
                resumes += r.status_code == 200
            assert time.monotonic() < deadline, f"stuck: {ex}"
            time.sleep(0.05)
        problems = check_exactly_once(emulator.execution_log(), ex["run_id"], ex["total"])
        assert problems == [], problems
        assert mapi.services.store.list_acks(eid) == list(range(ex["total"]))
        stats = emulator.stats
        # The fault really happened (no vacuous pass).
        if fault in MID_RUN_DROPS:
            assert dropped and resumes >= 1
        elif fault == "host_crash":
            assert dropped and resumes >= 1 and mapi.services.dispatch.pid != killed_pid
        elif fault == "corrupt":
            # corrupted frames reached both ends and were caught there
            link_stats = mapi.services.dispatch.robot_status(robot)["stats"]
            assert stats["frames_corrupt"] > 0 and link_stats.get("frames_corrupt", 0) > 0, (
                stats,
                link_stats,
            )
        elif fault in ("reject", "robot_fault"):
            assert resumes >= 1
        elif fault == "delay":
            # every command and its acknowledgement crossed a delayed link
            assert held[0] >= 2 * ex["total"], (held[0], ex["total"])
        elif fault == "nak":
            link_stats = mapi.services.dispatch.robot_status(robot)["stats"]
            assert link_stats.get("naks", 0) >= 1, link_stats
    finally:
        if eid is not None:  # a failed cell must not leave the robot busy for the next ones
            with contextlib.suppress(Exception):
                state = mapi.get(f"/api/v1/executions/{eid}").json()["state"]
                if state not in ("completed", "aborted"):
                    mapi.post(f"/api/v1/executions/{eid}/abort")
        emulator.close()


def _connected(mapi: Any, robot: str, timeout: float) -> bool:
    """Whether the link is up; ``False`` while a killed link service is being respawned."""
    try:
        return bool(mapi.services.dispatch.wait_connected(robot, timeout))
    except LinkServiceUnavailable:
        time.sleep(timeout)
        return False
