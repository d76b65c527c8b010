"""Shared helpers: run a program to completion through faults, the way a server would."""

from __future__ import annotations

import socket
import time
from dataclasses import dataclass, field
from typing import Any

from robots.adapters import (
    TERMINAL_STATES,
    ExecState,
    LinkConfig,
    Outcome,
    RobotLink,
    Streamer,
    StreamFault,
)
from robots.emulator import Emulator
from robots.protocol import JointMove, LiftArm, Nozzle, Program, SetMagnet, Stop, WheelSpeeds
from robots.protocol.auth import AuthError, Direction, HostHandshake, SessionMac, session_key
from robots.protocol.framing import Frame, FrameDecoder
from robots.protocol.messages import (
    Challenge,
    HelloStatus,
    Message,
    decode_message,
    encode_message,
)

STOPPED = TERMINAL_STATES | {ExecState.INTERRUPTED, ExecState.FAULTED}


def link_config(emu: Emulator, **kw: Any) -> LinkConfig:
    """The link configuration of the host that owns ``emu`` (its secret)."""
    return LinkConfig(secret=emu.secret, **kw)


def authed_link(emu: Emulator, url: str | None = None, **kw: Any) -> RobotLink:
    """A (not yet started) link to ``emu`` with its secret; ``url`` defaults to its TCP URL."""
    return RobotLink(url or emu.url, link_config(emu, **kw))


class RawHost:
    """A hand-driven host over a raw TCP socket, for tests that speak the protocol
    frame by frame: it records every byte it sends (``sent``) so a test can
    replay them, and keeps the session's MAC state to seal and open frames.
    """

    def __init__(self, address: tuple[str, int], timeout: float = 5.0) -> None:
        self.sock = socket.create_connection(address, timeout=timeout)
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.decoder = FrameDecoder()
        self.sent: list[bytes] = []  # wire bytes, one frame each, in order
        self.received: list[Frame] = []
        self.mac: SessionMac | None = None

    def close(self) -> None:
        self.sock.close()

    def __enter__(self) -> RawHost:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def send_wire(self, wire: bytes) -> None:
        self.sent.append(wire)
        self.sock.sendall(wire)

    def send_until_hung_up(self, wires: list[bytes]) -> int:
        """Send ``wires`` in order until the robot hangs up; how many went out.

        A robot that refuses a frame may close the connection at once, so the
        next write can fail with a broken pipe or a reset: that is its answer,
        not a test error.
        """
        for n, wire in enumerate(wires):
            try:
                self.send_wire(wire)
            except (BrokenPipeError, ConnectionResetError):
                return n
        return len(wires)

    def send(self, msg: Message, seq: int = 0) -> None:
        """``msg`` sealed with the session (a fresh counter)."""
        assert self.mac is not None, "no session"
        self.send_wire(self.mac.seal_message(msg, seq))

    def frames(self, timeout: float) -> list[Frame]:
        """Frames that arrive within ``timeout`` (stops early on EOF)."""
        out: list[Frame] = []
        deadline = time.monotonic() + timeout
        while (left := deadline - time.monotonic()) > 0:
            self.sock.settimeout(left)
            try:
                data = self.sock.recv(4096)
            except TimeoutError:
                break
            except OSError:
                break
            if not data:
                break
            out += self.decoder.feed(data)
        self.received += out
        return out

    def messages(self, timeout: float) -> list[Message]:
        """Authentic messages received within ``timeout`` (plain handshake answers too)."""
        out: list[Message] = []
        for f in self.frames(timeout):
            if self.mac is not None:
                try:
                    out.append(self.mac.open_message(f))
                    continue
                except AuthError:
                    pass
            out.append(decode_message(f))
        return out

    def until(self, predicate: Any, timeout: float = 5.0) -> Message:
        """Receive until a message satisfies ``predicate``; fails the test otherwise."""
        deadline = time.monotonic() + timeout
        while (left := deadline - time.monotonic()) > 0:
            for m in self.messages(min(left, 0.2)):
                if predicate(m):
                    return m
        raise AssertionError("expected message did not arrive")

    def closed_by_peer(self, timeout: float = 5.0) -> bool:
        """True when the robot hangs up within ``timeout``."""
        deadline = time.monotonic() + timeout
        while (left := deadline - time.monotonic()) > 0:
            self.sock.settimeout(left)
            try:
                data = self.sock.recv(4096)
            except TimeoutError:
                return False
            except OSError:
                return True
            if not data:
                return True
            self.received += self.decoder.feed(data)
        return False

    def handshake(
        self,
        secret: bytes | None,
        *,
        watchdog_ms: int = 500,
        takeover: bool = False,
        verify_robot: bool = True,
    ) -> Challenge:
        """HELLO → CHALLENGE → AUTH; with the right secret the session is open after it.

        ``verify_robot=False`` skips checking the robot's proof, as an attacker
        with a wrong key would, and sends its AUTH anyway.  Returns the robot's
        CHALLENGE (status LINE_BUSY when refused).
        """
        hs = HostHandshake(secret, watchdog_ms=watchdog_ms, takeover=takeover)
        self.send_wire(encode_message(hs.hello, 0))
        challenge = self.until(lambda m: isinstance(m, Challenge))
        assert isinstance(challenge, Challenge)
        if challenge.status != HelloStatus.OK or secret is None:
            return challenge
        if verify_robot:
            self.mac = hs.accept(challenge)
        else:
            key = session_key(secret, hs.hello, challenge)
            self.mac = SessionMac(key, Direction.HOST_TO_ROBOT)
        self.send_wire(HostHandshake.auth_frame(self.mac))
        return challenge


def generic_program(n_moves: int = 24, step_s: float = 0.1) -> Program:
    """Every command kind the generic robot has, mostly timed way-points."""
    cmds: list = []
    for k in range(n_moves):
        a = 0.02 * (k + 1)
        cmds.append(JointMove((a, -a, a, 0.0, a, 0.0), step_s))
        if k == 2:
            cmds += [Nozzle(True), SetMagnet(0, True), WheelSpeeds((0.1, 0.1), step_s)]
        if k == n_moves // 2:
            cmds += [LiftArm(0.5, step_s), Stop(), Nozzle(False), SetMagnet(0, False)]
    return Program(tuple(cmds), robot="generic")


@dataclass
class Run:
    """What a dispatch engine would have persisted."""

    acked: list[int] = field(default_factory=list)
    faults: list[StreamFault] = field(default_factory=list)
    outcomes: list[Outcome] = field(default_factory=list)
    streamers: int = 0
    resumes_in_place: int = 0

    def on_ack(self, index: int) -> None:
        # A persisted ack must be exactly the next index: no gap, no repeat.
        expected = self.acked[-1] + 1 if self.acked else index
        assert index == expected, f"on_ack({index}) after {self.acked[-3:]}"
        self.acked.append(index)


def run_to_completion(
    link: RobotLink,
    program: Program,
    run_id: int,
    *,
    timeout: float = 40.0,
    max_resumes: int = 25,
    window: int = 8,
) -> Run:
    """Stream ``program``, resuming after every interruption or fault until it completes.

    Alternates the two resume paths a server has: ``Streamer.resume()`` in place,
    and a new streamer from the persisted index (as after a server restart).
    """
    run = Run()
    deadline = time.monotonic() + timeout
    start = 0
    while True:
        streamer = Streamer(
            program,
            link,
            run_id=run_id,
            start=start,
            on_ack=run.on_ack,
            on_fault=run.faults.append,
            on_done=run.outcomes.append,
            window=window,
            # Operator decision after a robot fault: clear it when starting again.
            clear_robot_faults=bool(run.faults),
        )
        run.streamers += 1
        with streamer:
            while True:
                state = streamer.wait(STOPPED, timeout=max(0.0, deadline - time.monotonic()))
                assert state is not None, f"timed out; faults so far: {run.faults}"
                if state in TERMINAL_STATES:
                    assert state == ExecState.COMPLETED, (state, run.faults)
                    assert run.outcomes == [Outcome.COMPLETED]
                    return run
                assert len(run.faults) <= max_resumes, f"too many faults: {run.faults}"
                if len(run.faults) % 2 == 1:
                    run.resumes_in_place += 1
                    streamer.resume(clear_robot_faults=True)
                    streamer.wait({ExecState.PENDING, ExecState.RUNNING, *TERMINAL_STATES}, 5)
                    continue
                break
        start = run.acked[-1] + 1 if run.acked else 0
