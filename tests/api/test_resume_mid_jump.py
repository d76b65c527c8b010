"""``kill -9`` of the server while the ARA drives or jumps, restart, resume: the
fault-matrix cells of a robot that jumps (see tests/api/test_fault_matrix.py for the
link and robot faults, tests/emulator/test_jump_resume.py for the emulator alone).

A real ``steelpath serve`` runs as a subprocess on a temporary data directory with
its built-in emulators, which are processes of their own and outlive it (as robots
do).  Each cell dispatches a kind's default plan to the ARA and kills the server
with SIGKILL at a point found from the stored program and the execution's
acknowledged count (``acked``: commands the robot finished) — never from the
wall clock:

- ``drive``: ``ara.navigate`` (wheel commands), mid-way through a long wheels command;
- ``foot_in_air``: ``ara.switch`` (the inch-worm jump), once the first magnet command
  and a few way-points of phase C (foot 1 swings to the target) are done, before
  foot 1 lands;
- ``after_release``: ``ara.switch``, as soon as the release of foot 2's magnet (the
  swap) is acknowledged — the robot streams ahead, so it is then on the trajectory
  that follows the release (foot 2 lifting off), before the next magnet command;
- ``estop_foot_in_air``: as ``foot_in_air``, then, on the restarted server, the
  E-stop while foot 1 is still in the air: both magnets stay as they were (the
  state report's ``magnets``), a resume is refused until the E-stop is cleared, and
  the resume after the clear completes.

Then a new server starts on the same data directory (it finds the emulators again),
the interrupted execution is resumed and must complete, and the evidence is the
emulator's own: its JSON-lines log ``<data>/emulators/ara.log.jsonl`` (every command
executed exactly once, the interrupted one continued rather than repeated, the
magnet commands it completed, no ``fall_risk`` stop — the robot refuses any command
that would leave it without a held foot), the state file it saves at rest
(``ara.state.json``: magnets, joints and ``feet_in_air`` where the kill left it),
and its live state reports through the server (the end pose: odometry within 1 mm
of the plan, joints within 0.1° of the last way-point, magnets as the program left
them).  The reports the server recorded during the run (about 2 Hz) must each show
a held foot.
"""

from __future__ import annotations

import contextlib
import itertools
import math
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from robots.emulator.robot import check_exactly_once
from robots.protocol.messages import FaultFlag
from server.store import Store
from tests.support.feet import (
    held,
    in_air,
    last_joints,
    magnet_commands,
    magnet_commands_done,
    magnets_after,
    ops_match,
    unheld_steps,
    wheel_odometry,
)
from tests.support.serve import ServeProcess, planned, stop_emulators
from tests.support.serve import emulator as emulator_evidence
from tests.support.waiting import wait_for

pytestmark = pytest.mark.slow

ROBOT = "ara"
FOOT1, FOOT2 = 0b01, 0b10  # magnet channel / foot bits (docs/protocol.md §13)


class Server(ServeProcess):
    """``steelpath serve`` on ``data`` (planning in threads: nothing is killed while
    planning) with its embedded emulators at ``time_scale``."""

    _started = itertools.count()

    def __init__(self, data: Path, time_scale: float) -> None:
        super().__init__(data, f"jump-{next(self._started)}", emulator_time_scale=str(time_scale))

    def report(self) -> dict[str, Any]:
        return self.get(f"/robots/{ROBOT}/state")["report"]

    def wait_connected(self, timeout: float = 60) -> dict[str, Any]:
        """Until the link has a session (a robot stopped by the lost link reports a
        latched link fault, which the resume clears: the link is up all the same)."""
        return wait_for(
            lambda: (
                (r := self.get(f"/robots/{ROBOT}/state"))["state"]
                in ("ready", "streaming", "fault")
                and r["report"] is not None
                and r
            ),
            timeout,
            f"{ROBOT} up",
        )

    def execution(self, eid: str) -> dict[str, Any]:
        return self.get(f"/executions/{eid}")


@dataclass(frozen=True)
class Cell:
    kind: str
    time_scale: float  # the embedded emulators' (the whole program in a few wall seconds)
    #: ``(program, plan) → (acked count to wait for, what it is)``: the kill point.
    kill_at: Callable[[list[dict[str, Any]], dict[str, Any]], tuple[int, str]]
    #: Fraction of the command executing at the kill point to let run before the kill.
    into_command: float = 0.0
    estop: bool = False


def _long_drive(program: list[dict[str, Any]], _plan: dict[str, Any]) -> tuple[int, str]:
    """The first wheels command after the first of at least 5 simulated seconds:
    ``acked`` = its index means every command before it is done and it is executing."""
    k = next(
        i
        for i, c in enumerate(program)
        if i >= 1 and c["op"] == "wheels" and c["duration_s"] >= 5.0
    )
    return k, f"wheels command {k} executing"


def _phase_c(program: list[dict[str, Any]], plan: dict[str, Any]) -> tuple[int, int]:
    """(index of the first way-point of phase C, index of foot 1's magnet command
    after it: the landing)."""
    (c,) = [p for p in plan["result"]["jump"]["phases"] if p["name"] == "C"]
    t = 0.0
    first = None
    for i, cmd in enumerate(program):
        d = cmd.get("duration_s", 0.0)
        if cmd["op"] == "joints" and t <= c["t_start_s"] + 1e-3 < t + d:
            first = i
            break
        t += d
    assert first is not None, c
    land = next(
        i
        for i, cmd in enumerate(program)
        if i > first and cmd["op"] == "magnet" and cmd["magnet"] == 0 and cmd["touched"]
    )
    return first, land


def _foot_in_air(program: list[dict[str, Any]], plan: dict[str, Any]) -> tuple[int, str]:
    first, land = _phase_c(program, plan)
    assert land - first > 40, (first, land)  # room to kill mid-swing
    assert magnet_commands(program, first)[0][:2] == (1, 1)  # foot 2 anchors first
    return first + 5, f"5 way-points of phase C done (C: {first}…{land - 1}, landing {land})"


def _first_release(program: list[dict[str, Any]], _plan: dict[str, Any]) -> tuple[int, str]:
    k = next(i for i, c in enumerate(program) if c["op"] == "magnet" and not c["touched"])
    assert program[k + 1]["op"] == "joints", program[k + 1]
    return k + 1, f"magnet release {k} done"


CELLS = {
    "drive": Cell("ara.navigate", 25.0, _long_drive, into_command=0.4),
    "foot_in_air": Cell("ara.switch", 4.0, _foot_in_air),
    "after_release": Cell("ara.switch", 4.0, _first_release),
    "estop_foot_in_air": Cell("ara.switch", 4.0, _foot_in_air, estop=True),
}


@pytest.fixture
def servers(tmp_path: Path) -> Iterator[list[Server]]:
    started: list[Server] = []
    yield started
    for s in started:
        with contextlib.suppress(Exception):
            s.stop()
    stop_emulators(tmp_path / "var")


@pytest.mark.parametrize("case", sorted(CELLS))
def test_kill9_mid_jump_restart_resume(servers, tmp_path: Path, case: str) -> None:
    cell = CELLS[case]
    data = tmp_path / "var"
    first = Server(data, cell.time_scale)
    servers.append(first)
    plan = planned(first, cell.kind)
    program = plan["program"]
    total = len(program)
    before = first.wait_connected()["report"]
    # A fresh robot in the mobile configuration, held by its wheels.
    assert before["magnets"] == 0 and before["faults"] == 0, before
    assert held(0, before["q_rad"]) == FOOT1 | FOOT2
    # The plan itself never leaves the robot without a held foot.
    assert unheld_steps(program, before["q_rad"]) == []
    kill_acked, what = cell.kill_at(program, plan)
    assert 1 <= kill_acked < total - 1, (kill_acked, total)

    ex = first.post(f"/plans/{plan['id']}/dispatch", {"robot": ROBOT}, status=201)
    eid, run_id = ex["id"], ex["run_id"]

    def at_kill_point() -> dict[str, Any] | None:
        e = first.execution(eid)
        assert e["state"] in ("pending", "running"), (e, what)
        return e if e["acked"] >= kill_acked else None

    seen = wait_for(at_kill_point, 120, what, poll_s=0.01)
    if cell.into_command:
        time.sleep(program[kill_acked]["duration_s"] / cell.time_scale * cell.into_command)
    first.kill9()
    emu = emulator_evidence(data, ROBOT)

    # The robot stopped when its controller vanished, mid-command.
    interrupted = wait_for(
        lambda: [
            r for r in emu.execution_log() if r.run_id == run_id and r.outcome == "interrupted"
        ],
        20,
        "the robot to stop when its controller vanished",
    )
    cut = interrupted[-1]
    assert cut.index >= seen["acked"], (cut, seen)
    # (Its link closed: the link service dies with the server and closes its links.)
    assert cut.reason in ("link_lost", "watchdog"), cut
    stops = emu.stop_events()
    assert stops and stops[-1]["index"] == cut.index and stops[-1]["moving"], stops
    # Where the kill left it: the state the robot saved at the halt.
    kept = wait_for(
        lambda: (
            (s := emu.state()) is not None
            and s["run_id"] == run_id
            and s["faults"] & FaultFlag.LINK_RESET
            and s
        ),
        20,
        "the robot's state saved at the halt",
    )
    done_at_kill = kept["last_done"]
    assert done_at_kill == cut.index - 1, (kept["last_done"], cut)
    # No magnet released (or touched) that the program had not at that point …
    assert kept["magnets"] == magnets_after(program, done_at_kill), (kept, done_at_kill)
    log_at_kill = emu.execution_log()
    assert magnet_commands_done(log_at_kill, run_id, program) == magnet_commands(
        program, done_at_kill
    )
    # … and a foot held.
    assert held(kept["magnets"], kept["q_rad"]) != 0, kept
    assert kept["feet_in_air"] == in_air(kept["magnets"], kept["q_rad"]), kept
    if cell.kind == "ara.navigate":
        assert cut.op == "wheels", cut
        assert kept["magnets"] == 0 and kept["feet_in_air"] == 0, kept
    elif cell.kill_at is _foot_in_air:
        c_first, land = _phase_c(program, plan)
        # Mid-swing: foot 2 anchors, foot 1 is in the air and has not landed.
        assert cut.op == "joints" and c_first + 5 <= cut.index < land, (cut, c_first, land)
        assert kept["magnets"] == FOOT2 and kept["feet_in_air"] == FOOT1, kept
    else:
        release = kill_acked - 1
        nxt = next(i for i, _m, _on in magnet_commands(program) if i > release)
        # Foot 2 released, foot 1 holds, before the next magnet command.
        assert release < cut.index < nxt and cut.op == "joints", (cut, release, nxt)
        assert kept["magnets"] == FOOT1 and kept["feet_in_air"] == FOOT2, kept

    second = Server(data, cell.time_scale)
    servers.append(second)
    assert all(r["emulated"] for r in second.get("/robots") if r["name"] == ROBOT)
    got = second.execution(eid)
    assert got["state"] == "interrupted", got
    report = second.wait_connected()["report"]
    # The robot stands where it stopped (it outlived the server): same magnets, same pose.
    assert report["magnets"] == kept["magnets"] and report["last_done"] == done_at_kill, report
    assert max(abs(a - b) for a, b in zip(report["q_rad"], kept["q_rad"], strict=True)) < 2e-6

    if cell.estop:
        r = second.post("/estop", {"robot": ROBOT, "reason": "person under the jumping robot"})
        # Reached by this server, which drives the robot.  (The killed server's
        # heartbeat is still fresh, so the E-stop is also forwarded to it, and that
        # fails — an error in the answer, as it should be.)
        assert r["local"] == [ROBOT] and r["robots"][ROBOT] == r["server"], r
        assert r["unreached"] == [] and r["held"] == [], r
        stopped_report = wait_for(
            lambda: (
                (s := second.get(f"/robots/{ROBOT}/state"))["estop_latched"]
                and s["report"]["faults"] & FaultFlag.ESTOP
                and s["report"]
            ),
            20,
            "the robot to report the E-stop",
        )
        # Both magnets as they were, the joints where the kill stopped them.
        assert stopped_report["magnets"] == report["magnets"] == FOOT2, stopped_report
        assert (
            max(abs(a - b) for a, b in zip(stopped_report["q_rad"], report["q_rad"], strict=True))
            < 2e-6
        )
        assert held(stopped_report["magnets"], stopped_report["q_rad"]) == FOOT2
        # The run is not lost: still interrupted, but no resume while E-stopped.
        assert second.execution(eid)["state"] == "interrupted"
        refused = second.http.post(f"/executions/{eid}/resume", json={})
        assert refused.status_code == 409 and "E-stop" in refused.text, refused.text
        second.post(f"/robots/{ROBOT}/clear-estop")
        report = wait_for(
            lambda: (r := second.wait_connected()["report"])["faults"] & FaultFlag.ESTOP == 0 and r,
            20,
            "the robot to report the E-stop cleared",
        )
        assert report["magnets"] == FOOT2, report

    second.post(f"/executions/{eid}/resume")
    finished = wait_for(
        lambda: (
            (e := second.execution(eid))["state"]
            in ("completed", "aborted", "faulted", "interrupted")
            and e
        ),
        120,
        "the resumed run to finish",
    )
    assert finished["state"] == "completed", finished
    assert finished["run_id"] == run_id and finished["acked"] == total

    # Nothing done twice, nothing lost: the emulator's own log.
    log = emu.execution_log()
    assert check_exactly_once(log, run_id, total) == []
    assert ops_match(log, run_id, program) == []
    again = [r for r in log if r.run_id == run_id and r.index == cut.index]
    assert [r.outcome for r in again] == ["interrupted", "done"], again
    assert again[1].continued_from is not None
    # Each magnet command once, in the program's order; the robot never refused a
    # command for want of a held foot.
    assert magnet_commands_done(log, run_id, program) == magnet_commands(program)
    reasons = [s["reason"] for s in emu.stop_events()]
    assert "fall_risk" not in reasons, reasons

    # The robot ends where the plan says.
    end = wait_for(
        lambda: (r := second.report())["executing"] == -1 and r["last_done"] == total - 1 and r,
        30,
        "the robot at rest",
    )
    assert end["faults"] == 0, end
    assert end["magnets"] == magnets_after(program, total - 1), end
    want = wheel_odometry(program, before["odometry_m"])
    for got_m, want_m in zip(end["odometry_m"], want, strict=True):
        assert abs(got_m - want_m) <= 1e-3, (end["odometry_m"], want)
    q_end = last_joints(program)
    if q_end is not None:
        worst = max(abs(a - b) for a, b in zip(end["q_rad"], q_end, strict=True))
        assert worst <= math.radians(0.1), (worst, end["q_rad"], q_end)
    assert held(end["magnets"], end["q_rad"]) != 0

    # Every state report the servers recorded while the run was active had a held foot.
    store = Store(data)
    try:
        states = [s for _t, s in store.execution_states(eid)]
    finally:
        store.close()
    assert states, "no recorded state reports"
    unheld = [s for s in states if not held(s["magnets"], s["q_rad"])]
    assert unheld == [], unheld[:3]
    assert not any(s["faults"] & FaultFlag.FALL_RISK for s in states)
