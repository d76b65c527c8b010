"""Resume never re-drives a motion, proven from the emulator's own log.

For every command type that moves — wheels, joint way-points of a blast sweep, a
climbing step (lift, magnets, plates, joints) and a joint sweep with the nozzle —
the host link is closed at a random point in the middle of a motion, then a *new*
link and streamer resume from the last recorded completion with the same run id,
as a restarted server would.  The robot must end where the program says (odometry
= Σ speed·duration, joints = last target) and its log must show every command
done once and each interrupted one *continued*, not repeated.  The emulator
process itself is restarted from its state file in between in one test.
"""

from __future__ import annotations

import json
import random
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from robots.adapters import ExecState, LinkConfig, RobotLink, Streamer
from robots.emulator import Emulator, ExecutionRecord, SimRobot, check_exactly_once
from robots.emulator.cli import main
from robots.emulator.persist import (
    StateFile,
    StateFileError,
    read_port_file,
    restore_robot_state,
    robot_state,
    write_json_atomic,
)
from robots.emulator.profiles import resolve_profile
from robots.protocol import (
    JointMove,
    LiftArm,
    LimitingPlate,
    Nozzle,
    Program,
    SetMagnet,
    Stop,
    WheelSpeeds,
)
from robots.protocol.auth import load_or_create_secret
from robots.protocol.messages import Clear, FaultFlag, Heartbeat, Hello, State, WheelsCmd

from .helpers import Run

MM = 1e-3
DEG_01 = np.radians(0.1)


# --- programs and what they must end at ------------------------------------------------


@dataclass(frozen=True)
class Scenario:
    robot: str
    program: Program
    cuts: tuple[int, ...]  # commands to interrupt mid-motion, in order
    time_scale: float


def _blast_sweep() -> Program:
    # Way-points as the blast planner streams them; the long middle pass is cut.
    q = np.array(
        [
            [0.0, 0.3, 0.9, 0.0, 0.4, 0.0],
            [0.1, 0.35, 0.85, 0.0, 0.45, 0.1],
            [0.9, 0.45, 0.75, 0.1, 0.5, 0.6],  # 4 s pass across the surface
            [1.0, 0.5, 0.7, 0.1, 0.5, 0.7],
        ]
    )
    times = np.array([0.0, 0.5, 4.5, 5.0])
    return Program.from_joint_trajectory(q, times, nozzle=True, robot="denso_vm6083")


SCENARIOS: dict[str, Scenario] = {
    "wheels": Scenario(
        "ara",
        Program(
            (
                WheelSpeeds((0.2, 0.2), 1.0),
                WheelSpeeds((0.25, 0.25), 8.0),  # the 2.0 m command
                Stop(),
                WheelSpeeds((0.1, -0.1), 2.0),
            ),
            robot="ara",
        ),
        cuts=(1,),
        time_scale=8.0,
    ),
    "blast_sweep": Scenario("denso_vm6083", _blast_sweep(), cuts=(3,), time_scale=4.0),
    "climb_step": Scenario(
        "generic",
        Program(
            (
                SetMagnet(0, False),
                LimitingPlate(0, False),
                LiftArm(1.2, 4.0),
                JointMove((0.6, -0.4, 0.3, 0.0, 0.2, 0.0), 4.0),
                SetMagnet(0, True),
                LimitingPlate(0, True),
                LiftArm(0.2, 1.0),
            ),
            robot="generic",
        ),
        cuts=(2, 3),  # the lift, then (a second outage) the swing
        time_scale=4.0,
    ),
    "joint_sweep_nozzle": Scenario(
        "cmbot",
        Program(
            (
                JointMove(tuple(0.1 * (j % 3) for j in range(12)), 0.5),
                Nozzle(True),
                JointMove(tuple(-0.5 + 0.08 * j for j in range(12)), 4.0),
                JointMove(tuple(-0.45 + 0.08 * j for j in range(12)), 0.5),
                Nozzle(False),
            ),
            robot="cmbot",
        ),
        cuts=(2,),
        time_scale=4.0,
    ),
}


def expected_end(program: Program, state0: State) -> dict[str, np.ndarray]:
    """Where the robot must end: independent of the emulator's kinematics code."""
    odometry = np.asarray(state0.odometry_um, dtype=float) * 1e-6
    q = np.asarray(state0.q_urad, dtype=float) * 1e-6
    lift = state0.lift_urad * 1e-6
    for c in program:
        if isinstance(c, WheelSpeeds):
            odometry = odometry + np.asarray(c.speeds_m_s) * c.duration_s
        elif isinstance(c, JointMove):
            q = np.asarray(c.q_rad, dtype=float)
        elif isinstance(c, LiftArm):
            lift = c.angle_rad
    return {"odometry": odometry, "q": q, "lift": np.array([lift])}


def assert_at_end(state: State, want: dict[str, np.ndarray]) -> None:
    odometry = np.asarray(state.odometry_um, dtype=float) * 1e-6
    q = np.asarray(state.q_urad, dtype=float) * 1e-6
    assert np.all(np.abs(odometry - want["odometry"]) <= MM), (odometry, want["odometry"])
    assert np.all(np.abs(q - want["q"]) <= DEG_01), (q, want["q"])
    assert abs(state.lift_urad * 1e-6 - want["lift"][0]) <= DEG_01


def assert_continued_not_repeated(
    log: list[ExecutionRecord], run_id: int, program: Program, cuts: tuple[int, ...]
) -> None:
    problems = check_exactly_once(log, run_id, len(program))
    assert problems == [], problems
    for index in cuts:
        recs = [r for r in log if r.run_id == run_id and r.index == index]
        assert [(r.outcome, r.continued_from is None) for r in recs] == [
            ("interrupted", True),
            ("done", False),
        ], recs
        cut, rest = recs
        # Interrupted in the middle of the motion, and continued from exactly there.
        assert cut.progress is not None and 0.05 < cut.progress < 0.95, cut
        assert rest.continued_from == pytest.approx(cut.progress, abs=1e-6)


# --- host side: links and streamers as a (restarted) server makes them -----------------


def link_config(secret: bytes) -> LinkConfig:
    return LinkConfig(secret=secret)


def _executing_at(robot: SimRobot, run_id: int, index: int, fraction: float) -> bool:
    seg = robot.current
    if seg is None or (seg.msg.run_id, seg.msg.index) != (run_id, index):
        return False
    point = robot.resume_point()
    return point is not None and point.progress >= fraction


def stream_until_cut(
    emu: Emulator, scenario: Scenario, run_id: int, run: Run, cut: int, fraction: float
) -> None:
    """A server streams until ``cut`` is ``fraction`` done, then its link closes."""
    config = link_config(emu.secret)
    with RobotLink(emu.url, config) as link:
        streamer = Streamer(
            scenario.program,
            link,
            run_id=run_id,
            start=len(run.acked),
            on_ack=run.on_ack,
            on_fault=run.faults.append,
        )
        with streamer:
            ok = emu.wait_for(lambda e: _executing_at(e.robot, run_id, cut, fraction), 20)
            assert ok, f"command {cut} never reached {fraction:.0%}; faults {run.faults}"
    # The TCP connection is gone: the robot stops (link_lost) without waiting for anything.
    assert emu.wait_for(lambda e: not e.robot.busy, 5)


def stream_to_completion(
    url: str, secret: bytes, scenario: Scenario, run_id: int, run: Run
) -> None:
    with RobotLink(url, link_config(secret)) as link:
        streamer = Streamer(
            scenario.program,
            link,
            run_id=run_id,
            start=len(run.acked),
            on_ack=run.on_ack,
            on_fault=run.faults.append,
        )
        with streamer:
            state = streamer.wait(timeout=40)
            assert state == ExecState.COMPLETED, (state, run.faults)
    assert run.acked == list(range(len(scenario.program)))


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_interrupted_motion_is_continued_not_repeated(name: str) -> None:
    scenario = SCENARIOS[name]
    rng = random.Random(f"resume-{name}")
    run_id = 4200 + list(SCENARIOS).index(name)
    with Emulator(scenario.robot, time_scale=scenario.time_scale) as emu:
        want = expected_end(scenario.program, emu.snapshot())
        run = Run()
        for cut in scenario.cuts:
            stream_until_cut(emu, scenario, run_id, run, cut, rng.uniform(0.2, 0.5))
            assert emu.robot.interrupted is not None
        # The "restarted server": a new link and streamer from the last recorded ack.
        stream_to_completion(emu.url, emu.secret, scenario, run_id, run)
        assert emu.wait_for(lambda e: not e.robot.busy, 5)
        assert_at_end(emu.snapshot(), want)
        log = emu.execution_log()
        assert [s.reason for s in emu.stop_events() if s.moving] == ["link_lost"] * len(
            scenario.cuts
        )
    assert_continued_not_repeated(log, run_id, scenario.program, scenario.cuts)


# --- state that survives the emulator process ----------------------------------------------


def test_state_file_round_trip_continues_exactly() -> None:
    profile = resolve_profile("ara")
    robot = SimRobot(profile, clock=lambda: 0.0)
    robot.receive(Hello(watchdog_ms=2000), 0, now=0.0)
    cmd = WheelsCmd(run_id=7, index=0, duration_ms=2000, speeds_um_s=(250_000, 250_000))
    robot.receive(cmd, 1, now=0.0)
    robot.advance(0.0)
    robot.link_lost(now=1.03)
    data = json.loads(json.dumps(robot_state(robot)))  # what goes through the file
    again = SimRobot(profile, clock=lambda: 10.0)
    restore_robot_state(again, data)
    assert again.interrupted == robot.interrupted and again.last_done == -1
    assert again.odometry == pytest.approx([0.2575, 0.2575])
    assert again.faults == FaultFlag.LINK_RESET and again.run_id == 7
    again.receive(Hello(watchdog_ms=2000), 0, now=10.0)
    again.receive(Clear(faults=FaultFlag.LINK_RESET), 1, now=10.0)
    again.receive(cmd, 2, now=10.0)
    for k in range(1, 20):
        again.receive(Heartbeat(), 0, now=10.0 + 0.1 * k)
    assert again.last_done == 0
    assert again.odometry == pytest.approx([0.5, 0.5], abs=1e-9)


def test_state_file_refuses_another_robot_and_corrupt_files(tmp_path: Path) -> None:
    path = tmp_path / "state.json"
    StateFile(path).save(SimRobot(resolve_profile("ara")))
    with pytest.raises(StateFileError, match="robot 'ara', not 'cmbot'"):
        Emulator("cmbot", state_file=path)
    path.write_text("{not json")
    with pytest.raises(StateFileError, match="not JSON"):
        Emulator("ara", state_file=path)
    write_json_atomic(path, {"format": "something else"})
    with pytest.raises(StateFileError, match="not an emulator state file"):
        Emulator("ara", state_file=path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["state.json"]  # no temp files left


def test_cli_refuses_bad_state_file_and_orphan_delay(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "state.json"
    StateFile(path).save(SimRobot(resolve_profile("ara")))
    assert main(["--robot", "cmbot", "--state-file", str(path)]) == 2
    assert "robot 'ara', not 'cmbot'" in capsys.readouterr().err
    assert main(["--robot", "ara", "--exit-when-orphaned", "0"]) == 2
    assert "must be > 0" in capsys.readouterr().err
    assert not list(tmp_path.glob(".*.tmp"))


def test_state_file_written_at_rest_and_loaded_by_the_next_emulator(tmp_path: Path) -> None:
    scenario, run_id, cut = SCENARIOS["wheels"], 31, 1
    path = tmp_path / "state.json"
    with Emulator("ara", time_scale=8, state_file=path) as emu:
        assert not emu.state_loaded
        want = expected_end(scenario.program, emu.snapshot())
        run = Run()
        stream_until_cut(emu, scenario, run_id, run, cut, 0.3)
        (rec,) = [r for r in emu.execution_log() if r.outcome == "interrupted"]
        # Written when the robot stopped, while the emulator keeps running.
        deadline = time.monotonic() + 10
        while True:
            saved = json.loads(path.read_text()) if path.exists() else {}
            if saved.get("interrupted") is not None:
                break
            assert time.monotonic() < deadline, "state not written at rest"
            time.sleep(0.02)
        assert saved["interrupted"]["progress"] == pytest.approx(rec.progress)
        assert saved["last_done"] == 0 and saved["faults"] == FaultFlag.LINK_RESET
        kept = emu.snapshot()
        memory = emu.robot.interrupted
    with Emulator("ara", time_scale=8, state_file=path) as emu:
        assert emu.state_loaded and emu.robot.interrupted == memory
        now = emu.snapshot()
        assert (now.odometry_um, now.run_id, now.last_done) == (
            kept.odometry_um,
            kept.run_id,
            kept.last_done,
        )
        stream_to_completion(emu.url, emu.secret, scenario, run_id, run)
        assert_at_end(emu.snapshot(), want)
        log = emu.execution_log()
    # The second emulator's log holds only the continuation; its first part is upstream.
    assert [(r.index, r.continued_from is not None) for r in log] == [
        (1, True),
        (2, False),
        (3, False),
    ]


def test_state_writer_keeps_the_last_capture(tmp_path: Path) -> None:
    robot = SimRobot(resolve_profile("ara"))
    state = StateFile(tmp_path / "s.json")
    state.start()
    try:
        for k in range(20):
            robot.odometry[:] = k
            state.capture(robot)
    finally:
        state.close()
    assert json.loads((tmp_path / "s.json").read_text())["odometry_m"] == [19.0, 19.0]
    assert state.flush() is False  # nothing left waiting


def _emulator_cmd(tmp_path: Path, *extra: str) -> list[str]:
    return [
        sys.executable,
        "-m",
        "robots.emulator",
        "--robot",
        "ara",
        "--listen",
        "tcp://127.0.0.1:0",
        "--log-jsonl",
        str(tmp_path / "exec.jsonl"),
        "--state-file",
        str(tmp_path / "state.json"),
        "--port-file",
        str(tmp_path / "port.json"),
        *extra,
    ]


def _secret_args(tmp_path: Path) -> tuple[list[str], bytes]:
    path = tmp_path / "robot.secret"
    return ["--secret-file", str(path)], load_or_create_secret(path)


@contextmanager
def emulator_process(cmd: list[str], port_file: Path) -> Iterator[tuple[subprocess.Popen, str]]:
    """Run the emulator CLI; yields (process, url from its port file); always reaped."""
    port_file.unlink(missing_ok=True)
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 20
        info = None
        while info is None or info.pid != proc.pid:
            assert proc.poll() is None, f"emulator exited with {proc.returncode}"
            assert time.monotonic() < deadline, "no port file from the emulator"
            time.sleep(0.05)
            info = read_port_file(port_file)
        assert info.robot == "ara" and info.url is not None
        yield proc, info.url
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait(10)


def _log_lines(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines()]


def _log_records(path: Path) -> list[ExecutionRecord]:
    """The command records of a ``--log-jsonl`` file (it also holds stop records)."""
    return [
        ExecutionRecord(**{k: v for k, v in d.items() if k != "record"})
        for d in _log_lines(path)
        if d["record"] == "command"
    ]


def test_emulator_process_restarted_from_its_state_file(tmp_path: Path) -> None:
    scenario = SCENARIOS["wheels"]
    run_id, cut = 77, 1
    secret_args, secret = _secret_args(tmp_path)
    cmd = _emulator_cmd(tmp_path, "--time-scale", "8", *secret_args)
    port_file, state_file = tmp_path / "port.json", tmp_path / "state.json"
    run = Run()
    fraction = random.Random("process").uniform(0.25, 0.5)
    # Start of command 1 and its planned end, from the program alone (robot starts at 0).
    start_m = 0.2 * 1.0
    with emulator_process(cmd, port_file) as (proc, url):
        with RobotLink(url, link_config(secret)) as link:
            assert link.wait_for(lambda lk: lk.last_report is not None, 10)
            state0 = link.last_report
            assert state0 is not None
            streamer = Streamer(scenario.program, link, run_id=run_id, on_ack=run.on_ack)
            with streamer:
                ok = link.wait_for(
                    lambda lk: (
                        lk.last_report is not None
                        and lk.last_report.executing == cut
                        and lk.last_report.odometry_um[0] * 1e-6 >= start_m + fraction * 2.0
                    ),
                    20,
                )
                assert ok, "wheels command never got under way"
        # Link closed mid-motion; the robot stopped and wrote its state at rest.
        deadline = time.monotonic() + 10
        while not (tmp_path / "exec.jsonl").exists() or not any(
            r.outcome == "interrupted" for r in _log_records(tmp_path / "exec.jsonl")
        ):
            assert time.monotonic() < deadline, "the robot did not stop when its link closed"
            time.sleep(0.02)
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(10) == 0
    assert not port_file.exists()  # a clean exit withdraws its announcement
    saved = json.loads(state_file.read_text())
    assert saved["interrupted"] is not None and saved["last_done"] == 0
    (cut_rec,) = [r for r in _log_records(tmp_path / "exec.jsonl") if r.outcome == "interrupted"]
    assert cut_rec.reason == "link_lost"
    stops = [d for d in _log_lines(tmp_path / "exec.jsonl") if d["record"] == "stop"]
    assert [(d["reason"], d["moving"], d["index"]) for d in stops] == [("link_lost", True, cut)]
    assert stops[0]["t"] == pytest.approx(cut_rec.wall_end)
    assert saved["interrupted"]["progress"] == pytest.approx(cut_rec.progress)
    assert run.acked == [0]

    # A new emulator process: it must stand where the old one stopped, then finish.
    with emulator_process(cmd, port_file) as (proc, url):
        with RobotLink(url, link_config(secret)) as link:
            assert link.wait_for(lambda lk: lk.last_report is not None, 10)
            report = link.last_report
            assert report is not None and report.run_id == run_id and report.last_done == 0
            odometry = np.asarray(report.odometry_um) * 1e-6
            assert odometry == pytest.approx(np.asarray(saved["odometry_m"]), abs=1e-6)
            assert odometry[0] > start_m + 0.1  # not back home: the state was kept
        stream_to_completion(url, secret, scenario, run_id, run)
        with RobotLink(url, link_config(secret)) as link:
            assert link.wait_for(lambda lk: lk.last_report is not None, 10)
            final = link.last_report
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(10) == 0
    assert final is not None
    assert_at_end(final, expected_end(scenario.program, state0))
    log = _log_records(tmp_path / "exec.jsonl")  # both processes appended to it
    assert_continued_not_repeated(log, run_id, scenario.program, (cut,))


def test_exit_when_orphaned(tmp_path: Path) -> None:
    secret_args, secret = _secret_args(tmp_path)
    cmd = _emulator_cmd(tmp_path, "--exit-when-orphaned", "1", "--time-scale", "4", *secret_args)
    port_file = tmp_path / "port.json"
    program = Program((WheelSpeeds((0.1, 0.1), 1.0),), robot="ara")
    with emulator_process(cmd, port_file) as (proc, url):
        with RobotLink(url, link_config(secret)) as link:
            run = Run()
            with Streamer(program, link, run_id=5, on_ack=run.on_ack) as streamer:
                assert streamer.wait(timeout=20) == ExecState.COMPLETED
            # Connected but idle for longer than the orphan delay: it stays.
            time.sleep(1.6)
            assert proc.poll() is None
        # Nobody connected any more: it saves its state and exits on its own.
        assert proc.wait(15) == 0
    assert not port_file.exists()
    saved = json.loads((tmp_path / "state.json").read_text())
    assert (saved["run_id"], saved["last_done"], saved["interrupted"]) == (5, 0, None)
    assert saved["odometry_m"] == pytest.approx([0.1, 0.1], abs=1e-9)


def test_exit_when_orphaned_in_process_and_bad_values() -> None:
    import threading

    gone = threading.Event()
    with Emulator("ara", exit_when_orphaned_s=0.3, on_orphaned=gone.set) as emu:
        assert gone.wait(10) and emu.orphaned
    with pytest.raises(ValueError, match="must be > 0"):
        Emulator("ara", exit_when_orphaned_s=0)
