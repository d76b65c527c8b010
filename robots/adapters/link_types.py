"""Types of the host side of the robot protocol (:mod:`robots.adapters.link`):
link states, :class:`LinkConfig` (docs/protocol.md §6), the events a link
emits, the pending-frame record and the status snapshot.
"""

from __future__ import annotations

import contextlib
import enum
import select
import socket
from dataclasses import dataclass, field
from typing import Any

from robots.protocol.auth import check_secret
from robots.protocol.capture import SensorCapture
from robots.protocol.messages import (
    Ack,
    FaultFlag,
    HelloAck,
    Message,
    Nak,
    NakReason,
    State,
)


class LinkState(enum.StrEnum):
    DISCONNECTED = "disconnected"
    HANDSHAKING = "handshaking"
    READY = "ready"
    STREAMING = "streaming"
    FAULT = "fault"


CONNECTED_STATES = frozenset({LinkState.READY, LinkState.STREAMING, LinkState.FAULT})


class LinkDownError(RuntimeError):
    """Raised when a frame is sent while no session is up (the link is reconnecting)."""


@dataclass(frozen=True)
class LinkConfig:
    """Timing and limits of a link (defaults per docs/protocol.md §6)."""

    heartbeat_s: float = 0.1  # host → robot heartbeat period when idle
    watchdog_s: float = 0.5  # asked of the robot: stop if no host frame for this long
    link_timeout_s: float = 1.0  # host declares the link lost after this long without a frame
    ack_timeout_s: float = 0.25  # retransmit an unacknowledged frame after this
    max_retries: int = 5  # bounded retransmission: then the link is declared lost
    max_busy_naks: int = 5  # transient NAKs of one frame before it counts as refused
    hello_interval_s: float = 0.3
    handshake_timeout_s: float = 2.0
    backoff_initial_s: float = 0.1
    backoff_max_s: float = 5.0
    poll_s: float = 0.05  # longest the I/O thread sleeps in a read
    max_in_flight: int = 64
    baudrate: int = 115200
    expected_robot: str | None = None  # refuse a robot announcing another name
    # The robot's 32-byte secret (robots.protocol.auth).  None: the link opens
    # the port and sends a latched E-stop, but never gets a session.
    secret: bytes | None = field(default=None, repr=False)
    # Ask the robot to drop whichever host controls it now, on every
    # handshake.  For tools only: two servers with this set would fight over
    # the robot; a server uses RobotLink.takeover() on an operator's request.
    takeover: bool = False
    # A capture whose chunks stop arriving is handed on incomplete after this long.
    capture_timeout_s: float = 1.0

    def __post_init__(self) -> None:
        if self.secret is not None:
            object.__setattr__(self, "secret", check_secret(self.secret))


# --- events ---------------------------------------------------------------------------


@dataclass(frozen=True)
class LinkStateChanged:
    """``session`` is the session the change belongs to (the one lost, for a disconnect)."""

    old: LinkState
    new: LinkState
    reason: str
    session: int


@dataclass(frozen=True)
class EstopLatched:
    """:meth:`RobotLink.estop` was called (emitted in every link state)."""

    session: int


@dataclass(frozen=True)
class Connected:
    """A session is up (after HELLO_ACK and the first state report)."""

    session: int
    hello: HelloAck


@dataclass(frozen=True)
class ReportReceived:
    report: State
    session: int


@dataclass(frozen=True)
class FrameAcked:
    seq: int
    message: Message
    ack: Ack
    session: int


@dataclass(frozen=True)
class FrameRefused:
    """A sequenced frame refused for good (permanent NAK, or too many transient NAKs)."""

    seq: int
    message: Message
    nak: Nak
    session: int

    @property
    def reason(self) -> str:
        try:
            name = NakReason(self.nak.reason).name
        except ValueError:
            name = f"reason {self.nak.reason}"
        return f"{name} (detail {self.nak.detail})"


@dataclass(frozen=True)
class CaptureReceived:
    """A sensor frame the robot sent (``CAPTURE`` + ``CAPTURE_CHUNK``), reassembled.

    ``capture.complete`` is False when chunks were lost: it is handed on with
    the points that arrived when the next capture starts, when no chunk came
    for ``LinkConfig.capture_timeout_s``, when the link is lost or closed, or
    on :meth:`RobotLink.flush_captures`.
    """

    capture: SensorCapture
    session: int


LinkEvent = (
    LinkStateChanged
    | EstopLatched
    | Connected
    | ReportReceived
    | FrameAcked
    | FrameRefused
    | CaptureReceived
)


@dataclass
class _Pending:
    seq: int
    message: Message
    wire: bytes
    deadline: float
    retries: int = 0
    naks: int = 0


@dataclass(frozen=True)
class LinkStatus:
    """Snapshot for a robots panel."""

    url: str
    state: LinkState
    reason: str
    robot: HelloAck | None
    report: State | None
    last_rx_wall: float | None  # time.time() of the last valid frame (the robot's heartbeat)
    estop_latched: bool
    session: int
    stats: dict[str, int] = field(default_factory=dict)


def _disable_nagle(port: Any) -> None:
    """Send small frames at once on ``socket://`` ports.

    pyserial's socket handler leaves Nagle's algorithm on, which holds a small
    write (an E-stop!) while earlier bytes are unacknowledged — tens of ms with
    delayed ACKs.  (``rfc2217://`` already sets TCP_NODELAY.)  The handler keeps
    its socket in a private attribute, hence the guarded lookup.
    """
    sock = getattr(port, "_socket", None)
    if isinstance(sock, socket.socket):
        with contextlib.suppress(OSError):
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)


def _raw_socket(port: Any) -> socket.socket | None:
    """The TCP socket behind a plain ``socket://`` port, else ``None``.

    Only pyserial's ``socket://`` handler qualifies: ``rfc2217://`` parses
    telnet options out of its socket on a thread of its own, so its bytes
    must go through the port.
    """
    if type(port).__module__ != "serial.urlhandler.protocol_socket":
        return None
    sock = getattr(port, "_socket", None)
    return sock if isinstance(sock, socket.socket) else None


def _read_port(port: Any) -> bytes:
    """What has arrived, through the port's own ``read(1)`` + ``read(in_waiting)``
    (its timeout bounds the wait): right for serial devices and ``rfc2217://``."""
    data = bytes(port.read(1))
    if data:
        waiting = port.in_waiting
        if waiting:
            data += bytes(port.read(waiting))
    return data


def _read_some(port: Any, sock: socket.socket | None, timeout_s: float) -> bytes:
    """What has arrived on ``port`` (waiting at most ``timeout_s`` for a first byte).

    On a ``socket://`` port this is one ``select`` and one ``recv`` of all
    that is there.  pyserial's ``in_waiting`` on that handler is a select that
    answers 0 or 1, not a byte count, so ``read(1)`` + ``read(in_waiting)``
    took a frame two bytes per pass of the I/O loop (decoder and timers each
    time): 4.0 ms of host CPU per streamed command against 0.9 ms this way
    (``tests/benchmarks/bench_link_cpu.py``).
    """
    if sock is None:
        return _read_port(port)
    ready, _, _ = select.select([sock], [], [], timeout_s)
    if not ready:
        return b""
    try:
        data = sock.recv(65536)
    except (BlockingIOError, InterruptedError):
        return b""
    if not data:
        raise ConnectionResetError("socket disconnected")
    return data


def _fault_names(faults: int) -> str:
    names = [f.name for f in FaultFlag if f and faults & f and f.name]
    return ", ".join(names) if names else "a fault"
