"""Watchdog and E-stop: the robot stops when heartbeats stop, and on E-stop from any
link state.  Latency *figures* are measured in tests/benchmarks/bench_estop.py; the
bounds here are functional (seconds), far above the 100 ms target, so they cannot flake."""

from __future__ import annotations

import socket
import time

from robots.adapters import ExecState, LinkConfig, LinkState, Outcome, RobotLink, Streamer
from robots.emulator import Emulator, FaultConfig, check_exactly_once
from robots.protocol import FaultFlag, JointMove, Mode, Program
from robots.protocol.auth import generate_secret
from robots.protocol.framing import FrameDecoder, encode_frame
from robots.protocol.messages import (
    Heartbeat,
    Hello,
    HelloAck,
    HelloStatus,
    JointsCmd,
    MsgType,
    State,
    decode_message,
    encode_message,
)

from .helpers import STOPPED, RawHost, link_config

FUNCTIONAL_BOUND_S = 2.0


def long_program(
    n: int = 40, step_s: float = 0.5, long_index: int = 0, long_s: float = 5.0
) -> Program:
    """Way-points of ``step_s``, except command ``long_index`` which takes ``long_s``.

    Tests act while the long one executes, so "the robot is moving" holds for
    seconds whatever the machine's load, instead of depending on a race.
    """
    return Program(
        tuple(
            JointMove((0.02 * (k + 1),) * 6, long_s if k == long_index else step_s)
            for k in range(n)
        )
    )


def executing(index: int):
    return lambda e: e.robot.current is not None and e.robot.current.msg.index == index


def test_watchdog_stops_motion_when_heartbeats_stop() -> None:
    """A raw (authenticated) client that goes silent mid-motion: the robot stops by itself."""
    with Emulator("generic") as emu, RawHost(emu.address) as host:
        host.handshake(emu.secret, watchdog_ms=300)
        host.until(lambda m: isinstance(m, State))
        cmd = JointsCmd(run_id=1, index=0, duration_ms=20_000, q_urad=(500_000,) * 6)
        # Taken before the send: the emulator may read the frame (and start its
        # watchdog) before this thread runs again, never before the send.
        last_frame = time.monotonic()
        host.send(cmd, 1)
        assert emu.wait_for(lambda e: e.robot.stops, 5)
        stop = emu.stop_events()[0]
        assert (stop.reason, stop.moving, stop.index) == ("watchdog", True, 0)
        assert 0.3 <= stop.t - last_frame < 0.3 + FUNCTIONAL_BOUND_S
        rep = emu.snapshot()
        assert rep.mode == Mode.FAULT and rep.faults == FaultFlag.WATCHDOG
        assert emu.execution_log()[-1].outcome == "interrupted"


def test_heartbeats_keep_a_long_motion_going() -> None:
    with Emulator("generic") as emu, RobotLink(emu.url, link_config(emu)) as link:
        assert link.wait_connected(5)
        link.send_command(JointMove((0.5,) * 6, 20.0), run_id=1, index=0)
        assert emu.wait_for(lambda e: e.robot.current is not None, 5)
        # Three watchdog periods with nothing to send but heartbeats: no stop.
        assert not emu.wait_for(lambda e: e.robot.stops, 1.5)
        assert emu.snapshot().mode == Mode.MOVING


def test_watchdog_on_a_silent_serial_line() -> None:
    """pty: the host cannot see the cable go; the robot's watchdog stops it, and the
    run resumes from the last acknowledged command after the line comes back."""
    prog = long_program(12, 0.3, long_index=2, long_s=4.5)  # 1.5 s of wall time
    persisted: list[int] = []
    with (
        Emulator("generic", listen=None, pty=True, time_scale=3) as emu,
        RobotLink(emu.pty_path, link_config(emu)) as link,
    ):
        with Streamer(prog, link, run_id=8, on_ack=persisted.append) as s:
            assert emu.wait_for(executing(2), 10)
            emu.drop_link(silence_s=1.5)
            assert s.wait(STOPPED, 10) == ExecState.INTERRUPTED
            assert [e.reason for e in emu.stop_events()] == ["watchdog"]
            s.resume()
            assert s.wait(timeout=20) == ExecState.COMPLETED
        assert persisted == list(range(len(prog)))
        assert check_exactly_once(emu.execution_log(), 8, len(prog)) == []


def test_estop_mid_motion_then_clear_and_resume() -> None:
    prog = long_program(20, 0.3, long_index=2, long_s=4.5)  # 1.5 s of wall time
    persisted: list[int] = []
    done: list[Outcome] = []
    with Emulator("generic", time_scale=3) as emu, RobotLink(emu.url, link_config(emu)) as link:
        with Streamer(prog, link, run_id=21, on_ack=persisted.append, on_done=done.append) as s:
            assert emu.wait_for(executing(2), 10)
            t0 = time.monotonic()
            s.estop()
            assert emu.wait_for(lambda e: e.robot.stops, FUNCTIONAL_BOUND_S)
            stop = emu.stop_events()[0]
            assert stop.reason == "estop" and stop.moving
            assert stop.t - t0 < FUNCTIONAL_BOUND_S
            assert s.wait(timeout=5) == ExecState.ESTOPPED and done == [Outcome.ESTOPPED]
        assert link.wait_for(lambda lk: lk.last_report.mode == Mode.ESTOP, 5)
        assert link.state == LinkState.FAULT
        # Latched: a new execution is refused until the operator clears the E-stop.
        with Streamer(prog, link, run_id=21, start=persisted[-1] + 1) as s2:
            assert s2.wait(STOPPED, 5) == ExecState.FAULTED
            assert "E-stop" in s2.fault.message
        link.clear_estop()
        assert link.wait_for(lambda lk: lk.last_report.faults == 0, 5)
        with Streamer(
            prog, link, run_id=21, start=persisted[-1] + 1, on_ack=persisted.append
        ) as s3:
            assert s3.wait(timeout=30) == ExecState.COMPLETED
        assert persisted == list(range(len(prog)))
        assert check_exactly_once(emu.execution_log(), 21, len(prog)) == []


def test_estop_while_the_link_is_reconnecting() -> None:
    prog = long_program(20, 0.3, long_index=0, long_s=20.0)
    with Emulator("generic") as emu, RobotLink(emu.url, link_config(emu)) as link:
        with Streamer(prog, link, run_id=5) as s:
            assert emu.wait_for(executing(0), 10)
            emu.drop_link(silence_s=2.5)  # the cable is pulled, TCP stays open
            assert link.wait_for(lambda lk: not lk.connected, 5)
            assert link.state in (LinkState.DISCONNECTED, LinkState.HANDSHAKING)
            link.estop()
            assert s.wait(timeout=5) == ExecState.ESTOPPED
        # Meanwhile the robot's watchdog stopped it; once the line is back the
        # latched E-stop is the first thing it hears.
        assert emu.wait_for(lambda e: e.robot.faults & FaultFlag.ESTOP, 10)
        assert emu.stop_events()[0].reason == "watchdog", emu.stop_events()
        assert link.wait_for(lambda lk: lk.connected and lk.last_report.mode == Mode.ESTOP, 5)


def test_estop_with_no_robot_is_delivered_when_it_appears() -> None:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    secret = generate_secret()
    cfg = LinkConfig(backoff_initial_s=0.05, backoff_max_s=0.2, secret=secret)
    with RobotLink(f"socket://127.0.0.1:{port}", cfg) as link:
        link.estop()
        assert link.estop_latched and link.state == LinkState.DISCONNECTED
        with Emulator("generic", listen=f"tcp://127.0.0.1:{port}", secret=secret) as emu:
            assert emu.wait_for(lambda e: e.robot.faults & FaultFlag.ESTOP, 5)


def test_robot_answers_an_unknown_major_version() -> None:
    with Emulator("generic") as emu, socket.create_connection(emu.address, timeout=5) as sock:
        sock.sendall(encode_frame(MsgType.HELLO, 0, Hello(major=3).payload(), ver=3))
        dec = FrameDecoder()
        replies: list = []
        deadline = time.monotonic() + 5
        while not any(isinstance(r, HelloAck) for r in replies) and time.monotonic() < deadline:
            replies += [decode_message(f) for f in dec.feed(sock.recv(4096))]
        ack = next(r for r in replies if isinstance(r, HelloAck))
        assert ack.status == HelloStatus.VERSION_UNSUPPORTED and ack.major == 2
        sock.sendall(encode_message(Heartbeat(), 0))


def test_emulator_refusal_of_out_of_limit_targets_from_robot_description() -> None:
    # denso_vm6083: J2 is limited to −90…135° (DESIGN §7) whichever source the limits come from.
    with (
        Emulator("denso_vm6083", faults=FaultConfig()) as emu,
        RobotLink(emu.url, link_config(emu)) as link,
    ):
        assert link.wait_connected(5)
        prog = Program((JointMove((0.0, -2.0, 0.0, 0.0, 0.0, 0.0), 0.0),))
        with Streamer(prog, link, run_id=1) as s:
            assert s.wait(STOPPED, 5) == ExecState.FAULTED
            assert "LIMIT (detail 1)" in s.fault.message
        assert emu.execution_log() == []
