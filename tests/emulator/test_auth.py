"""Only the secret's holder commands the robot (docs/protocol.md §12).

Every attack here — no secret, a wrong secret, replayed wire bytes of a real
authorised session (into a new connection and into the same session),
altered frames with a fixed-up CRC, a second connection while the line is
held, a takeover without the secret — must leave the emulator where it was
(joints and odometry unchanged, nothing in its execution log), and the
authorised link must stay up and still complete a program afterwards.
"""

from __future__ import annotations

import os
import struct
import time
from collections.abc import Iterator
from typing import Any

import pytest
import serial

from robots.adapters import (
    ExecState,
    LinkConfig,
    LinkState,
    LinkStateChanged,
    RobotLink,
    Streamer,
)
from robots.emulator import Emulator
from robots.protocol import FaultFlag, JointMove, Mode, Program, WheelSpeeds, generate_secret
from robots.protocol.auth import TRAILER_SIZE
from robots.protocol.framing import (
    CRC_SIZE,
    DELIMITER,
    cobs_decode,
    cobs_encode,
    crc16,
)
from robots.protocol.messages import (
    Challenge,
    Estop,
    Heartbeat,
    HelloStatus,
    JointsCmd,
    MsgType,
    State,
    WheelsCmd,
    encode_message,
)

from .helpers import RawHost, link_config

SHORT = Program(
    (
        WheelSpeeds((0.1, 0.1), 0.3),
        JointMove((0.1, -0.1, 0.1, 0.0, 0.1, 0.0), 0.3),
        WheelSpeeds((-0.05, 0.05), 0.2),
    )
)
MOVE_JOINTS = JointsCmd(run_id=99, index=0, duration_ms=200, q_urad=(300_000,) * 6)
MOVE_WHEELS = WheelsCmd(run_id=99, index=0, duration_ms=5_000, speeds_um_s=(300_000, 300_000))


class Recorder:
    """A pyserial factory that records every write of a real RobotLink (wire bytes)."""

    def __init__(self) -> None:
        self.writes: list[bytes] = []

    def __call__(self, url: str, **kw: Any) -> Any:
        port = serial.serial_for_url(url, **kw)
        write = port.write

        def recording_write(data: bytes) -> int | None:
            self.writes.append(bytes(data))
            return write(data)

        port.write = recording_write
        return port

    def frames_of(self, msg_type: int) -> list[bytes]:
        """Recorded frames of one message type (wire bytes, delimiter included)."""
        return [w for w in self.writes if cobs_decode(w[:-1])[1] == msg_type]


def pose(emu: Emulator) -> tuple[tuple[int, ...], tuple[int, ...], int]:
    """Joints, odometry and the number of executed commands: what an attack must not change."""
    rep = emu.snapshot()
    return rep.q_urad, rep.odometry_um, len(emu.execution_log())


def assert_still_works(emu: Emulator, link: RobotLink, run_id: int) -> None:
    """The authorised link is up, never lost its link, and completes a short program."""
    assert link.connected, link.status()
    with Streamer(SHORT, link, run_id=run_id) as s:
        assert s.wait(timeout=20) == ExecState.COMPLETED
    assert link.status().stats.get("links_lost", 0) == 0
    assert link.session == 1


def refix(raw: bytes) -> bytes:
    """Wire bytes for ``raw`` (header ‖ payload) with a freshly computed CRC."""
    return cobs_encode(raw + crc16(raw).to_bytes(2, "little")) + DELIMITER


@pytest.fixture
def held() -> Iterator[tuple[Emulator, RobotLink, Recorder, list[Any]]]:
    """An emulator with an authorised link holding the line (recorded, events collected)."""
    rec = Recorder()
    events: list[Any] = []
    with Emulator("generic", time_scale=4) as emu:
        link = RobotLink(emu.url, link_config(emu), serial_factory=rec)
        link.subscribe(events.append)
        with link:
            assert link.wait_connected(5)
            yield emu, link, rec, events
    lost = [e for e in events if isinstance(e, LinkStateChanged) and "lost" in e.reason]
    assert lost == [], lost


def test_client_without_the_secret_cannot_move_a_free_robot() -> None:
    with Emulator("generic") as emu:
        before = pose(emu)
        with RawHost(emu.address) as host:
            challenge = host.handshake(None)  # it gets a challenge, but cannot answer it
            assert challenge.status == HelloStatus.OK
            for seq, msg in enumerate((MOVE_JOINTS, MOVE_WHEELS, Heartbeat()), start=1):
                host.send_wire(encode_message(msg, seq))  # plain, as a v1 host would
            # No answer, not even a NAK, and no state report leaks to it.
            assert host.messages(0.5) == []
        assert emu.wait_for(lambda e: e.stats["frames_unauthenticated"] >= 3, 5)
        assert pose(emu) == before and emu.execution_log() == []
        assert emu.stats["sessions"] == 0 and not emu.has_controller


def test_wrong_secret_is_refused_on_both_sides() -> None:
    with Emulator("generic") as emu:
        before = pose(emu)
        # An attacker ignoring the robot's proof and answering with its own key.
        with RawHost(emu.address) as host:
            host.handshake(generate_secret(), verify_robot=False)
            host.send(MOVE_WHEELS, 1)
            assert host.closed_by_peer(5)  # a failed AUTH hangs up at once
        assert emu.stats["auth_failures"] == 1 and emu.stats["sessions"] == 0
        # A RobotLink with another secret notices the robot's proof is wrong first.
        cfg = LinkConfig(secret=generate_secret(), backoff_max_s=0.2)
        with RobotLink(emu.url, cfg) as link:
            assert link.wait_for(lambda lk: "failed authentication" in lk.status().reason, 5)
            assert not link.connected and link.status().stats["auth_failures"] >= 1
        assert pose(emu) == before and emu.execution_log() == []


def test_host_refuses_an_impostor_robot() -> None:
    """A robot that does not know the host's secret is never streamed to."""
    secret = generate_secret()
    with Emulator("generic") as impostor:  # its own random secret
        cfg = LinkConfig(secret=secret, backoff_max_s=0.2)
        with RobotLink(impostor.url, cfg) as link:
            assert link.wait_for(lambda lk: "robot failed authentication" in lk.status().reason, 5)
            assert link.state in (LinkState.DISCONNECTED, LinkState.HANDSHAKING)
            assert link.session == 0 and link.robot_info is None
        assert impostor.stats["sessions"] == 0


def test_replayed_session_into_a_new_connection_moves_nothing() -> None:
    rec = Recorder()
    with Emulator("generic", time_scale=4) as emu:
        with RobotLink(emu.url, link_config(emu), serial_factory=rec) as link:
            assert link.wait_connected(5)
            with Streamer(SHORT, link, run_id=7) as s:
                assert s.wait(timeout=20) == ExecState.COMPLETED
        assert emu.wait_for(lambda e: not e.has_controller, 5)
        before = pose(emu)
        assert rec.frames_of(MsgType.AUTH) and rec.frames_of(MsgType.CMD_WHEELS)
        # Every byte the authorised host sent, HELLO and AUTH included, into a new connection.
        with RawHost(emu.address) as attacker:
            replay = [w for w in rec.writes if cobs_decode(w[:-1])[1] != MsgType.ESTOP]
            sent = attacker.send_until_hung_up(replay)
            assert sent >= 2  # at least HELLO and the old AUTH reached it
            assert attacker.closed_by_peer(5)  # the old AUTH fails against a fresh nonce
            got = [m for m in attacker.messages(0.2) if not isinstance(m, Challenge)]
            assert got == []
        assert emu.stats["auth_failures"] >= 1 and emu.stats["sessions"] == 1
        assert pose(emu) == before


def test_replayed_and_altered_frames_into_the_live_session_are_dropped() -> None:
    """A serial line anyone can write to (the pty): frames of the running session itself."""
    rec = Recorder()
    events: list[Any] = []
    with Emulator("generic", listen=None, pty=True, time_scale=4) as emu:
        link = RobotLink(emu.pty_path, link_config(emu), serial_factory=rec)
        link.subscribe(events.append)
        with link:
            assert link.wait_connected(5)
            with Streamer(SHORT, link, run_id=8) as s:
                assert s.wait(timeout=20) == ExecState.COMPLETED
            assert emu.wait_for(lambda e: not e.robot.busy, 5)
            before = pose(emu)
            duplicates = emu.robot.counters["duplicates"]
            wheels = rec.frames_of(MsgType.CMD_WHEELS)
            assert wheels
            # Altered: a command's speed byte flipped, and also one with a fresh
            # (never used) counter; the CRC is fixed, so only the MAC catches them.
            raw = bytearray(cobs_decode(wheels[0][:-1])[:-CRC_SIZE])
            speed_at = 5 + 13  # header, then run_id, index, duration, count
            flipped = bytearray(raw)
            flipped[speed_at] ^= 0x40
            fresh = bytearray(raw)
            struct.pack_into("<I", fresh, len(raw) - TRAILER_SIZE, 0x7FFF_FFFF)
            # The whole session so far, except its HELLOs (a HELLO is only a request).
            replay = [w for w in rec.writes if cobs_decode(w[:-1])[1] != MsgType.HELLO]
            n_auth = len(rec.frames_of(MsgType.AUTH))
            with emu._lock:
                unauth0, replayed0 = (
                    emu.stats["frames_unauthenticated"],
                    emu.stats["frames_replayed"],
                )
            fd = os.open(emu.pty_path, os.O_WRONLY | os.O_NOCTTY)  # write only: steal nothing
            try:
                for wire in replay:
                    os.write(fd, wire)
                os.write(fd, refix(bytes(flipped)))
                os.write(fd, refix(bytes(fresh)))
            finally:
                os.close(fd)
            n_estop = len(rec.frames_of(MsgType.ESTOP))
            dropped = len(replay) - n_estop + 2
            assert emu.wait_for(lambda e: e.stats["frames_unauthenticated"] >= unauth0 + dropped, 5)
            with emu._lock:
                # Every replayed data frame was caught by its counter (AUTHs too, counted
                # as failed handshakes), both altered ones by their MAC.
                assert emu.stats["frames_replayed"] - replayed0 >= len(replay) - n_estop - n_auth
                # Dropped before the robot: it never even saw them as duplicates.
                assert emu.robot.counters["duplicates"] == duplicates
            assert pose(emu) == before
            assert_still_works(emu, link, run_id=9)
    assert not [e for e in events if isinstance(e, LinkStateChanged) and "lost" in e.reason]


def test_second_connection_is_refused_while_the_line_is_held(held: Any) -> None:
    emu, link, _rec, _events = held
    before = pose(emu)
    # A plain HELLO: refused at once, then hung up.
    with RawHost(emu.address) as other:
        assert other.handshake(None).status == HelloStatus.LINE_BUSY
        assert other.closed_by_peer(2)
    # Even the right secret does not take the line without asking.
    cfg = link_config(emu, backoff_max_s=0.2)
    with RobotLink(emu.url, cfg) as second:
        assert second.wait_for(lambda lk: "line busy" in lk.status().reason, 5)
        assert not second.connected
    # A squatter that says nothing is closed after the authentication timeout.
    with RawHost(emu.address) as squatter:
        t0 = time.monotonic()
        assert squatter.closed_by_peer(5)
        assert time.monotonic() - t0 >= 1.0
    # Its ESTOP (a candidate's) does not disturb the controller either.
    with RawHost(emu.address) as other:
        other.send_wire(encode_message(Estop(), 1))
        assert other.closed_by_peer(5)
    assert emu.snapshot().faults == 0 and pose(emu) == before
    assert emu.stats["connections_refused"] >= 3 and emu.stats["sessions"] == 1
    assert_still_works(emu, link, run_id=11)


def test_takeover_needs_the_request_and_the_secret() -> None:
    with Emulator("generic", time_scale=4) as emu, RobotLink(emu.url, link_config(emu)) as link:
        assert link.wait_connected(5)
        _takeover(emu, link)


def _takeover(emu: Emulator, link: RobotLink) -> None:
    # The takeover flag without the secret: a challenge it cannot answer.
    with RawHost(emu.address) as other:
        assert other.handshake(generate_secret(), takeover=True, verify_robot=False).status == 0
        assert other.closed_by_peer(5)
    cfg = LinkConfig(secret=generate_secret(), takeover=True, backoff_max_s=0.2)
    with RobotLink(emu.url, cfg) as stranger:
        assert stranger.wait_for(lambda lk: "failed authentication" in lk.status().reason, 5)
    assert emu.stats["takeovers"] == 0 and emu.stats["sessions"] == 1
    assert link.connected and link.session == 1
    # The secret without the request: refused (line busy).
    with RobotLink(emu.url, link_config(emu, backoff_max_s=0.2)) as other:
        assert other.wait_for(lambda lk: "line busy" in lk.status().reason, 5)
        # The explicit request: the robot drops the old controller mid-motion.
        with Streamer(Program((WheelSpeeds((0.1, 0.1), 20.0),)), link, run_id=12) as s:
            assert emu.wait_for(lambda e: e.robot.current is not None, 5)
            other.takeover()
            assert other.wait_connected(5)
            assert s.wait({ExecState.INTERRUPTED}, 5) == ExecState.INTERRUPTED
        assert emu.stats["takeovers"] == 1
        stops = emu.stop_events()
        assert stops and stops[-1].reason == "link_lost" and stops[-1].moving
        # The new controller starts from a latched LINK_RESET, as after any lost link.
        assert other.wait_for(lambda lk: lk.last_report.faults & FaultFlag.LINK_RESET, 5)
        # The old one is now the outsider: refused, not fighting back.
        assert link.wait_for(lambda lk: "line busy" in lk.status().reason, 5)
        assert not link.connected
        other.clear_faults(FaultFlag.LINK_RESET)
        assert other.wait_for(lambda lk: lk.state == LinkState.READY, 5)


def test_estop_is_fail_safe_from_the_controller_and_a_free_line() -> None:
    """ESTOP needs no MAC: from the controller (even mid-handshake) and while nobody holds
    the line; a stranger's ESTOP cannot disturb a held line (see the refusal test)."""
    with Emulator("generic") as emu, RawHost(emu.address) as anyone:
        anyone.send_wire(encode_message(Estop(), 1))
        assert emu.wait_for(lambda e: e.robot.faults & FaultFlag.ESTOP, 5)
    with Emulator("generic") as emu, RobotLink(emu.url, link_config(emu)) as link:
        assert link.wait_connected(5)
        link.estop()  # written plain from this thread
        assert emu.wait_for(lambda e: e.robot.faults & FaultFlag.ESTOP, 5)
        assert link.wait_for(lambda lk: lk.last_report.mode == Mode.ESTOP, 5)


def test_a_silent_connection_does_not_squat_on_a_free_line() -> None:
    with Emulator("generic") as emu, RawHost(emu.address) as squatter:
        assert emu.wait_for(lambda e: e.stats["connections"] == 1, 5)
        with RobotLink(emu.url, link_config(emu)) as link:
            assert link.wait_connected(5)
            with emu._lock:
                # Connected while the squatter is still there, waiting to be timed out.
                assert len(emu._candidates) == 1 and not emu._candidates[0].closed
        assert squatter.closed_by_peer(5)


def test_host_drops_unauthenticated_frames_from_the_robot_side(held: Any) -> None:
    emu, link, _rec, _events = held
    report = link.last_report
    assert report is not None
    forged = State(mode=Mode.ESTOP, faults=int(FaultFlag.ESTOP), run_id=4242)
    emu._do(lambda now: emu._write(emu._tcp, encode_message(forged, 1), now))
    assert link.wait_for(lambda lk: lk.status().stats.get("frames_unauthenticated", 0) >= 1, 5)
    time.sleep(0.3)
    assert link.last_report.run_id != 4242 and link.state == LinkState.READY
    assert_still_works(emu, link, run_id=13)


def test_link_without_a_secret_gets_no_session_but_its_estop_still_stops() -> None:
    """A server missing the robot's key file cannot command it, yet can always stop it."""
    with Emulator("generic") as emu, RobotLink(emu.url, LinkConfig(backoff_max_s=0.2)) as link:
        assert link.wait_for(lambda lk: "no secret configured" in lk.status().reason, 5)
        assert not link.connected and emu.stats["sessions"] == 0
        link.estop()
        assert emu.wait_for(lambda e: e.robot.faults & FaultFlag.ESTOP, 5)
