"""``kill -9`` of the server mid-command, restart, Resume: the robot ends where
the plan says, not further, for every command type that moves.

A real ``steelpath serve`` runs as a subprocess on a temporary data directory
with its built-in emulators, which are processes of their own (as robots are,
they outlive the server).  Each test dispatches a kind's default plan, kills
the server with SIGKILL while a command of the named type executes, starts a
new server on the same data directory (it finds the running emulators again),
resumes the interrupted execution and compares the robot's final state with
the end of the plan's program; the emulator's own log must show every command
completed exactly once, the interrupted one continued rather than repeated.
"""

from __future__ import annotations

import contextlib
import itertools
import math
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from robots.emulator.robot import check_exactly_once
from tests.support.procstat import proc_stat
from tests.support.serve import ServeProcess, stop_emulators
from tests.support.serve import emulator as emulator_evidence
from tests.support.waiting import wait_for as _wait

pytestmark = pytest.mark.slow


class Server(ServeProcess):
    """One ``steelpath serve`` process on ``data``, planning in worker
    processes (the default) with its emulators at ``time_scale``."""

    _started = itertools.count()

    def __init__(self, data: Path, time_scale: float) -> None:
        super().__init__(
            data,
            f"crash-{next(self._started)}",
            emulator_time_scale=str(time_scale),
            job_mode="process",
        )

    def robot(self, name: str) -> dict[str, Any]:
        return self.get(f"/robots/{name}/state")

    def wait_connected(self, name: str, timeout: float = 60) -> dict[str, Any]:
        """Until the link has a session (a robot stopped by a lost link reports a
        latched link fault, which a resume clears: the link is up all the same)."""
        return _wait(
            lambda: (r := self.robot(name))["state"] in ("ready", "streaming", "fault") and r,
            timeout,
            f"{name} up",
        )


@pytest.fixture
def servers(tmp_path) -> Iterator[list[Server]]:
    started: list[Server] = []
    yield started
    for s in started:
        s.stop()
    stop_emulators(tmp_path / "var")


def planned_end(program: list[dict[str, Any]], odometry0: list[float]) -> dict[str, Any]:
    """Where the program leaves the robot: last joint target, wheel distances, last lift
    angle, magnet and plate states (quantised as on the wire: µm/s, ms, µrad)."""
    q: list[float] | None = None
    lift: float | None = None
    odo = list(odometry0)
    magnets: dict[int, bool] = {}
    plates: dict[int, bool] = {}
    for c in program:
        if c["op"] == "joints":
            q = [round(v * 1e6) * 1e-6 for v in c["q_rad"]]
        elif c["op"] == "wheels":
            ms = round(c["duration_s"] * 1e3)
            for i, v in enumerate(c["speeds_m_s"]):
                odo[i] += round(v * 1e6) * ms * 1e-9
        elif c["op"] == "lift":
            lift = round(c["angle_rad"] * 1e6) * 1e-6
        elif c["op"] == "magnet":
            magnets[c["magnet"]] = bool(c["touched"])
        elif c["op"] == "plate":
            plates[c["plate"]] = bool(c["engaged"])
    return {"q": q, "odometry": odo, "lift": lift, "magnets": magnets, "plates": plates}


CASES = {
    # name: (kind, robot, params, emulator time scale, command type to kill in,
    #        shortest such command (simulated s) worth aiming at)
    "wheels": ("demo.route", "ara", {}, 8.0, "wheels", 5.0),
    "joint_waypoints": ("cmbot.manipulate", "cmbot", {}, 4.0, "joints", 0.05),
    # Two gait cycles, not the seed's 1.5 m: its 0.1 s way-points at the 12×
    # needed to replay 240 s in time were 8 ms each, so a loaded streamer let
    # the robot's buffer run dry and the kill found it between commands.
    "climbing_steps": ("cmbot.climb", "cmbot", {"goal_rear_x_m": 5.0}, 2.0, "joints", 0.05),
    "blast_sweep": ("blast", "denso_vm6083", {}, 8.0, "joints", 0.05),
    "lift_and_wheels": ("sbg.inspect", "sbg_climber", {}, 60.0, "wheels", 5.0),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_kill9_mid_command_restart_resume_ends_on_the_plan(servers, tmp_path, case) -> None:
    kind, robot, params, scale, op, floor = CASES[case]
    data = tmp_path / "var"
    first = Server(data, scale)
    servers.append(first)
    plan = first.post("/plans", {"kind": kind, "params": params}, status=202)
    plan = _wait(
        lambda: (
            (p := first.get(f"/plans/{plan['id']}"))["state"] not in ("queued", "planning") and p
        ),
        300,
        "planned",
    )
    assert plan["state"] == "planned", plan.get("error")
    program = plan["program"]
    first.post(f"/plans/{plan['id']}/approve")
    before = first.wait_connected(robot)["report"]
    end = planned_end(program, before["odometry_m"])
    ex = first.post(f"/plans/{plan['id']}/dispatch", {"robot": robot}, status=201)
    # Wait for a long-enough command of the named type, past its first third
    # but not its end, then kill the server with SIGKILL.
    floor = min(floor, max(c.get("duration_s", 0.0) for c in program if c["op"] == op))

    def executing_target() -> int | None:
        report = first.robot(robot)["report"]
        k = report["executing"]
        # More commands queued behind it: the robot is mid-program, not
        # waiting for the streamer, when the server dies.
        if (
            k >= 1
            and report["buffer_level"] >= 2
            and program[k]["op"] == op
            and program[k].get("duration_s", 0) >= floor
        ):
            return k
        return None

    k = _wait(executing_target, 120, f"a {op} command executing")
    time.sleep(program[k]["duration_s"] / scale * 0.4)
    first.kill9()
    emu = emulator_evidence(data, robot)
    interrupted = _wait(
        lambda: [
            r
            for r in emu.execution_log()
            if r.run_id == ex["run_id"] and r.outcome == "interrupted"
        ],
        20,
        "the robot to stop when its controller vanished",
    )
    assert interrupted[-1].index >= 1

    second = Server(data, scale)
    servers.append(second)
    emulator = second.get("/robots")
    assert all(r["emulated"] for r in emulator if r["name"] == robot)
    got = second.get(f"/executions/{ex['id']}")
    assert got["state"] == "interrupted", got
    second.wait_connected(robot)
    second.post(f"/executions/{ex['id']}/resume")
    done = _wait(
        lambda: (
            (e := second.get(f"/executions/{ex['id']}"))["state"]
            in ("completed", "aborted", "faulted", "interrupted")
            and e
        ),
        300,
        "the resumed run to finish",
    )
    assert done["state"] == "completed", done
    log = emu.execution_log()
    assert check_exactly_once(log, done["run_id"], done["total"]) == []
    # The interrupted command was continued, not run again from its start.
    cont = [r for r in log if r.run_id == done["run_id"] and r.index == interrupted[-1].index]
    assert [r.outcome for r in cont] == ["interrupted", "done"], cont
    report = _wait(
        lambda: (r := second.robot(robot)["report"]) and r["executing"] == -1 and r,
        30,
        "the robot at rest",
    )
    if end["q"] is not None:
        worst = max(abs(a - b) for a, b in zip(report["q_rad"], end["q"], strict=True))
        assert worst <= math.radians(0.1), (worst, report["q_rad"], end["q"])
    for got_m, want_m in zip(report["odometry_m"], end["odometry"], strict=True):
        assert abs(got_m - want_m) <= 1e-3, (report["odometry_m"], end["odometry"])
    if end["lift"] is not None:
        assert abs(report["lift_rad"] - end["lift"]) <= math.radians(0.1)
    for i, on in end["magnets"].items():
        assert bool(report["magnets"] >> i & 1) == on, ("magnet", i, report["magnets"])
    for i, on in end["plates"].items():
        assert bool(report["plates"] >> i & 1) == on, ("plate", i, report["plates"])


def _children(pid: int) -> dict[int, str]:
    out = {}
    for task in Path(f"/proc/{pid}/task").iterdir():
        with contextlib.suppress(OSError):
            for child in (task / "children").read_text().split():
                with contextlib.suppress(OSError):
                    cmd = Path(f"/proc/{child}/cmdline").read_bytes().replace(b"\0", b" ")
                    out[int(child)] = cmd.decode(errors="replace")
    return out


def test_the_link_service_dies_with_a_killed_server_and_the_robots_do_not(
    servers, tmp_path
) -> None:
    data = tmp_path / "var"
    server = Server(data, 1.0)
    servers.append(server)
    kids = _children(server.proc.pid)
    (link_pid,) = [p for p, cmd in kids.items() if "server.linkservice" in cmd]
    robots = [p for p, cmd in kids.items() if "robots.emulator" in cmd]
    assert len(robots) == 4
    server.kill9()
    _wait(
        lambda: not Path(f"/proc/{link_pid}").exists() or _zombie(link_pid), 15, "link service gone"
    )
    # The robots (emulator processes) live on, as robots do.
    assert all(Path(f"/proc/{p}").exists() and not _zombie(p) for p in robots)


def _zombie(pid: int) -> bool:
    st = proc_stat(pid)
    return st is None or st.state == "Z"
