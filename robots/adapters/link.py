"""Host side of the robot protocol over any pyserial URL (docs/protocol.md).

:class:`RobotLink` owns one connection (``/dev/ttyUSB0``, ``socket://host:port``,
``loop://``, ``rfc2217://host:port`` — anything ``serial.serial_for_url``
opens) and runs the connection state machine::

    disconnected ─► handshaking ─► ready ⇄ streaming
         ▲               │           │ ▲       │
         └── backoff ◄───┴── link lost ┴─┴► fault (robot reports a latched fault / E-stop)

It handshakes (version, watchdog), sends heartbeats, delivers sequenced
frames with ACK/NAK and bounded go-back-N retransmission, watches the robot's
state reports (the robot → host heartbeat), and reconnects with exponential
backoff when the link is lost.

Authentication (docs/protocol.md §12, :mod:`robots.protocol.auth`): the
handshake is a mutual challenge–response with the robot's secret
(:attr:`LinkConfig.secret`); a robot whose proof is wrong is never streamed
to (state ``disconnected``, reason "robot failed authentication").  Every
frame of the session is MAC'd with a per-session key and a strictly
increasing counter; received frames that do not verify are dropped and
counted (``stats["frames_unauthenticated"]``).  The only plain frames are
the ``HELLO``, the robot's ``CHALLENGE`` (or its refusal) and ``ESTOP``,
which the robot obeys from its controller without a MAC (fail-safe).  A
robot held by another host refuses the handshake ("line busy");
:meth:`RobotLink.takeover` (or ``LinkConfig(takeover=True)``) asks it to
drop that host instead.

Threading, and why not asyncio: pyserial's URL handlers are blocking
(``select``-based reads with a timeout) and there is no asyncio transport for
``socket://``/``rfc2217://``/``loop://`` without an extra dependency.  One
daemon I/O thread per link keeps heartbeats, retransmission and the link
watchdog on time no matter how busy the FastAPI event loop or the planning
workers are.  Public methods are thread-safe and never block on the network
for long; :meth:`RobotLink.estop` writes the E-stop frame from the caller's
thread at once instead of queueing it behind the I/O loop.  Events go to
subscribers (:meth:`RobotLink.subscribe`) from whichever thread produced them,
serialised and in order; a subscriber must only hand them on (a queue, or
``loop.call_soon_threadsafe``), never block.
"""

from __future__ import annotations

import collections
import contextlib
import enum
import logging
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import serial

from robots.protocol.auth import AuthError, HostHandshake, SessionMac, check_secret
from robots.protocol.commands import Command
from robots.protocol.framing import PROTOCOL_MAJOR, Frame, FrameDecoder
from robots.protocol.messages import (
    TRANSIENT_NAKS,
    Abort,
    Ack,
    Challenge,
    Clear,
    CommandMessage,
    Estop,
    FaultFlag,
    Heartbeat,
    Hello,
    HelloAck,
    HelloFlag,
    HelloStatus,
    Message,
    MessageError,
    Mode,
    MsgType,
    Nak,
    NakReason,
    Pause,
    Resume,
    State,
    decode_message,
    encode_message,
    is_command,
)

log = logging.getLogger(__name__)


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


LinkEvent = LinkStateChanged | EstopLatched | Connected | ReportReceived | FrameAcked | FrameRefused


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


class RobotLink:
    """One robot connection over a pyserial URL; see the module docstring."""

    def __init__(
        self,
        url: str,
        config: LinkConfig | None = None,
        *,
        name: str = "",
        serial_factory: Callable[..., Any] | None = None,
    ) -> None:
        self.url = url
        self.config = config or LinkConfig()
        self.name = name or url
        self._serial_factory = serial_factory or serial.serial_for_url
        self._lock = threading.RLock()
        self._cond = threading.Condition(self._lock)
        self._write_lock = threading.Lock()
        self._dispatch_lock = threading.RLock()
        self._events: collections.deque[LinkEvent] = collections.deque()
        self._subscribers: list[Callable[[LinkEvent], None]] = []
        self._wake = threading.Event()
        self._stop = False
        self._thread: threading.Thread | None = None
        self._port: Any = None
        self._decoder = FrameDecoder(accept_any_version=True)
        self._state = LinkState.DISCONNECTED
        self._reason = "not started"
        self._session = 0
        self._hello: HelloAck | None = None
        self._report: State | None = None
        self._last_rx = 0.0
        self._last_rx_wall: float | None = None
        self._last_tx = 0.0
        self._hs_started = 0.0
        self._hs_last_hello = 0.0
        self._next_attempt = 0.0
        self._backoff = self.config.backoff_initial_s
        self._tx_seq = 0
        self._unacked: collections.OrderedDict[int, _Pending] = collections.OrderedDict()
        self._gap_resend: tuple[int, float] = (-1, 0.0)
        # A command was acknowledged but no report since shows it queued: stay
        # "streaming" meanwhile instead of flapping to "ready" for a moment.
        self._awaiting_report = False
        self._lost_reason: str | None = None
        self._estop_latched = False
        self._estop_acked = False
        self._estop_seq = 0
        self._estop_last_tx = 0.0
        self._stats = collections.Counter[str]()
        self._handshake: HostHandshake | None = None  # this port's handshake attempt
        self._mac: SessionMac | None = None  # set by a valid CHALLENGE; seals every frame
        self._takeover_requested = False

    # --- lifecycle -----------------------------------------------------------------

    def start(self) -> RobotLink:
        """Start the I/O thread; it connects and keeps reconnecting until :meth:`close`."""
        with self._lock:
            if self._thread is not None:
                return self
            self._thread = threading.Thread(
                target=self._run, name=f"robot-link {self.name}", daemon=True
            )
            self._thread.start()
        return self

    def close(self, timeout: float = 5.0) -> None:
        """Stop the I/O thread and close the port (no frame is sent)."""
        with self._lock:
            self._stop = True
            thread = self._thread
        self._wake.set()
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout)
        with self._lock:
            self._close_port()
            self._set_state(LinkState.DISCONNECTED, "closed")
        self._dispatch()

    def __enter__(self) -> RobotLink:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def reconnect_now(self) -> None:
        """Skip the remaining backoff delay (e.g. after the operator fixed a cable)."""
        with self._lock:
            self._next_attempt = 0.0
            self._backoff = self.config.backoff_initial_s
        self._wake.set()

    def takeover(self) -> None:
        """Take the robot over from whichever host controls it (an operator's explicit action).

        The next handshakes carry the takeover flag until one opens a session;
        the robot then drops its current controller (stopping any motion and
        latching ``LINK_RESET``, as every new session does).  Still needs the
        secret: a takeover without it is refused like any other stranger.  A
        link that already has a session keeps it (it holds the line already).
        """
        with self._lock:
            if self._state in CONNECTED_STATES:
                return
            self._takeover_requested = True
            self._stats["takeovers_requested"] += 1
            # A handshake under way without the flag is restarted by the I/O
            # thread (_timers_locked); a waiting reconnect starts now.
            self._next_attempt = 0.0
            self._backoff = self.config.backoff_initial_s
        self._wake.set()

    # --- observation ---------------------------------------------------------------

    def subscribe(self, callback: Callable[[LinkEvent], None]) -> Callable[[], None]:
        """Call ``callback(event)`` for every event; returns a function that unsubscribes."""
        with self._lock:
            self._subscribers.append(callback)

        def unsubscribe() -> None:
            with self._lock:
                if callback in self._subscribers:
                    self._subscribers.remove(callback)

        return unsubscribe

    @property
    def state(self) -> LinkState:
        return self._state

    @property
    def connected(self) -> bool:
        return self._state in CONNECTED_STATES

    @property
    def session(self) -> int:
        """Count of sessions opened so far; changes on every reconnect."""
        return self._session

    @property
    def robot_info(self) -> HelloAck | None:
        return self._hello

    @property
    def last_report(self) -> State | None:
        return self._report

    @property
    def estop_latched(self) -> bool:
        return self._estop_latched

    def status(self) -> LinkStatus:
        with self._lock:
            return LinkStatus(
                url=self.url,
                state=self._state,
                reason=self._reason,
                robot=self._hello,
                report=self._report,
                last_rx_wall=self._last_rx_wall,
                estop_latched=self._estop_latched,
                session=self._session,
                stats=dict(self._stats),
            )

    def wait_for(self, predicate: Callable[[RobotLink], bool], timeout: float) -> bool:
        """Block until ``predicate(self)`` holds (re-checked on every change) or timeout."""
        with self._cond:
            return self._cond.wait_for(lambda: predicate(self), timeout)

    def wait_connected(self, timeout: float) -> bool:
        return self.wait_for(lambda link: link.connected, timeout)

    # --- sending ---------------------------------------------------------------------

    def send_command(self, command: Command | CommandMessage, run_id: int, index: int) -> int:
        """Queue command ``index`` of run ``run_id`` on the reliable channel; returns its seq.

        The ACK/NAK arrives as a :class:`FrameAcked`/:class:`FrameRefused`
        event; completion shows in state reports (``last_done``).
        Raises :class:`LinkDownError` when no session is up.
        """
        if isinstance(command, Command):
            msg: Message = command.to_message(run_id, index)
        else:
            msg = command
        return self._send_sequenced(msg)

    def pause(self) -> int:
        return self._send_sequenced(Pause())

    def resume(self) -> int:
        return self._send_sequenced(Resume())

    def abort(self) -> int:
        """Robot stops and drops its queued commands (the run's progress is kept)."""
        return self._send_sequenced(Abort())

    def clear_faults(self, faults: int) -> int:
        """Clear latched robot faults (:class:`FaultFlag` bits); E-stop: use :meth:`clear_estop`."""
        return self._send_sequenced(Clear(faults=int(faults) & ~int(FaultFlag.ESTOP)))

    def ping(self) -> int:
        """A no-op sequenced frame (CLEAR of no faults): its ACK times the round trip."""
        return self._send_sequenced(Clear(faults=0))

    def estop(self) -> None:
        """Emergency stop, from any state; never raises for a down link.

        Latches on the host: written now if a session is up (from this thread,
        without waiting for the I/O loop), repeated until the robot ACKs it,
        and sent first thing after every reconnect until :meth:`clear_estop`.
        While the link is down the robot's watchdog has already stopped it.
        """
        with self._lock:
            first = not self._estop_latched
            self._estop_latched = True
            self._estop_acked = False
            # Any open port will do: the robot obeys ESTOP even before a session.
            self._send_estop_locked()
            if first:
                self._stats["estops"] += 1
            self._emit_locked(EstopLatched(self._session))
            self._update_state_locked()
        self._dispatch()

    def clear_estop(self) -> None:
        """Release the host latch and, when connected, the robot's E-stop."""
        with self._lock:
            self._estop_latched = False
            self._estop_acked = False
            connected = self._state in CONNECTED_STATES
            if connected:
                self._send_sequenced_locked(Clear(faults=int(FaultFlag.ESTOP)))
            self._update_state_locked()
        self._dispatch()

    # --- internals: sending --------------------------------------------------------------

    def _send_sequenced(self, msg: Message) -> int:
        with self._lock:
            seq = self._send_sequenced_locked(msg)
        self._dispatch()
        return seq

    def _send_sequenced_locked(self, msg: Message) -> int:
        if self._state not in CONNECTED_STATES:
            raise LinkDownError(f"{self.name}: link is {self._state.value} ({self._reason})")
        if len(self._unacked) >= self.config.max_in_flight:
            raise LinkDownError(f"{self.name}: {len(self._unacked)} frames unacknowledged")
        self._tx_seq = (self._tx_seq + 1) & 0xFFFF
        seq = self._tx_seq
        wire = self._seal_locked(msg, seq)
        now = time.monotonic()
        self._unacked[seq] = _Pending(seq, msg, wire, now + self.config.ack_timeout_s)
        self._write_locked(wire)
        self._update_state_locked()
        return seq

    def _send_estop_locked(self) -> None:
        # Plain on purpose (docs/protocol.md §12.5): the robot obeys an ESTOP
        # from its controller with or without a session, so this frame needs
        # no key, no handshake and no counter — nothing can hold it up.
        self._estop_seq = (self._estop_seq + 1) & 0xFFFF
        self._estop_last_tx = time.monotonic()
        self._write_locked(encode_message(Estop(), self._estop_seq))

    def _seal_locked(self, msg: Message, seq: int) -> bytes:
        """Wire bytes of ``msg`` with this session's counter and MAC (a fresh counter per call)."""
        mac = self._mac
        if mac is None:
            raise LinkDownError(f"{self.name}: no session key")
        try:
            return mac.seal_message(msg, seq)
        except AuthError as exc:  # counter exhausted after 2**32 frames: a new session
            self._lost_reason = self._lost_reason or str(exc)
            self._wake.set()
            return b""

    def _write_locked(self, wire: bytes) -> None:
        with self._write_lock:
            port = self._port
            if port is None:
                return
            try:
                port.write(wire)
                self._last_tx = time.monotonic()
                self._stats["frames_tx"] += 1
            except Exception as exc:  # any handler's error means the link is gone
                # Closing belongs to the I/O thread (it may be inside read()).
                self._lost_reason = self._lost_reason or f"write failed: {exc}"
                self._wake.set()

    # --- internals: state and events -----------------------------------------------------

    def _emit_locked(self, event: LinkEvent) -> None:
        self._events.append(event)

    def _dispatch(self) -> None:
        """Deliver queued events in order, one at a time, outside ``_lock``."""
        with self._dispatch_lock:
            while True:
                with self._lock:
                    if not self._events:
                        return
                    event = self._events.popleft()
                    subscribers = list(self._subscribers)
                for callback in subscribers:
                    try:
                        callback(event)
                    except Exception:  # a broken subscriber must not kill the link
                        log.exception("%s: link subscriber failed", self.name)

    def _set_state(self, new: LinkState, reason: str) -> None:
        old = self._state
        if new == old and reason == self._reason:
            return
        self._state, self._reason = new, reason
        if new != old:
            log.info("%s: %s → %s (%s)", self.name, old.value, new.value, reason)
            self._emit_locked(LinkStateChanged(old, new, reason, self._session))
        self._cond.notify_all()

    def _update_state_locked(self) -> None:
        """Recompute ready / streaming / fault from the latest report and host latches."""
        if self._state not in CONNECTED_STATES:
            return
        rep = self._report
        if self._estop_latched:
            self._set_state(LinkState.FAULT, "E-stop latched on the host")
        elif rep is not None and (rep.faults or rep.mode in (Mode.FAULT, Mode.ESTOP)):
            self._set_state(LinkState.FAULT, f"robot reports {_fault_names(rep.faults)}")
        elif (
            self._unacked
            or self._awaiting_report
            or (
                rep is not None and (rep.mode in (Mode.MOVING, Mode.PAUSED) or rep.buffer_level > 0)
            )
        ):
            self._set_state(LinkState.STREAMING, "commands in flight or executing")
        else:
            self._set_state(LinkState.READY, "idle")

    # --- internals: I/O thread ---------------------------------------------------------

    def _run(self) -> None:
        try:
            while True:
                with self._lock:
                    if self._stop:
                        return
                    port = self._port
                if port is None:
                    self._try_connect()
                else:
                    self._service(port)
                self._dispatch()
        except Exception:  # pragma: no cover - a bug; keep the reason visible
            log.exception("%s: link thread crashed", self.name)
            with self._lock:
                self._close_port()
                self._set_state(LinkState.DISCONNECTED, "link thread crashed (see log)")
            self._dispatch()

    def _try_connect(self) -> None:
        now = time.monotonic()
        if now < self._next_attempt:
            self._wake.wait(self._next_attempt - now)
            self._wake.clear()
            return
        try:
            port = self._serial_factory(
                self.url,
                baudrate=self.config.baudrate,
                timeout=self.config.poll_s,
                write_timeout=1.0,
            )
            with contextlib.suppress(Exception):
                port.reset_input_buffer()  # stale bytes from before this session
            _disable_nagle(port)
        except Exception as exc:
            with self._lock:
                self._schedule_retry_locked(f"cannot open {self.url}: {exc}")
            return
        with self._lock:
            if self._stop:
                port.close()
                return
            self._port = port
            self._decoder.reset()
            self._mac = None
            self._handshake = HostHandshake(
                self.config.secret,
                heartbeat_ms=round(self.config.heartbeat_s * 1000),
                watchdog_ms=round(self.config.watchdog_s * 1000),
                takeover=self.config.takeover or self._takeover_requested,
            )
            self._unacked.clear()
            self._awaiting_report = False
            self._lost_reason = None
            self._hello = None
            self._report = None
            now = time.monotonic()
            self._hs_started = now
            self._hs_last_hello = now
            self._last_rx = now
            self._stats["connects"] += 1
            self._set_state(LinkState.HANDSHAKING, f"opened {self.url}")
            self._send_hello_locked()
            if self._estop_latched:
                # The robot may have rebooted since it last acknowledged it.
                self._estop_acked = False
                self._send_estop_locked()

    def _send_hello_locked(self) -> None:
        """Send (or repeat) the current handshake step: HELLO, or AUTH once challenged."""
        self._tx_seq = 0
        self._hs_last_hello = time.monotonic()
        if self._mac is not None:
            # Challenged already: repeat the AUTH (a fresh counter each time).
            self._write_locked(HostHandshake.auth_frame(self._mac))
            return
        hs = self._handshake
        hello = hs.hello if hs is not None else Hello()
        # Repeated verbatim (same nonce): the robot answers it with the same CHALLENGE.
        self._write_locked(encode_message(hello, 0))

    def _refuse_robot_locked(self, reason: str, *, slow: bool) -> None:
        """The robot's handshake answer rules it out for now: close, and retry later."""
        self._stats["handshakes_refused"] += 1
        if slow:
            self._backoff = self.config.backoff_max_s
        self._close_port()
        self._schedule_retry_locked(reason)

    def _schedule_retry_locked(self, reason: str) -> None:
        self._next_attempt = time.monotonic() + self._backoff
        self._set_state(LinkState.DISCONNECTED, f"{reason}; retrying in {self._backoff:.1f} s")
        self._backoff = min(self._backoff * 2, self.config.backoff_max_s)

    def _close_port(self) -> None:
        with self._write_lock:
            port, self._port = self._port, None
        if port is not None:
            with contextlib.suppress(Exception):
                port.close()
        self._unacked.clear()
        self._mac = None
        self._handshake = None

    def _lose_locked(self, reason: str) -> None:
        self._stats["links_lost"] += 1
        self._close_port()
        self._schedule_retry_locked(f"link lost: {reason}")

    def _service(self, port: Any) -> None:
        try:
            data = port.read(1)
            if data:
                waiting = port.in_waiting
                if waiting:
                    data += port.read(waiting)
        except Exception as exc:
            with self._lock:
                if self._port is port:
                    self._lose_locked(f"read failed: {exc}")
            return
        with self._lock:
            if self._port is not port:
                return
            now = time.monotonic()
            if data:
                errors_before = self._decoder.errors
                for frame in self._decoder.feed(data):
                    if frame.ver != PROTOCOL_MAJOR:
                        self._stats["frames_bad_version"] += 1
                        continue
                    msg = self._open_locked(frame)
                    if msg is None:
                        continue
                    self._on_message_locked(msg, now)
                    if self._port is not port:
                        return
                self._stats["frames_corrupt"] += self._decoder.errors - errors_before
            self._timers_locked(now)

    def _timers_locked(self, now: float) -> None:
        cfg = self.config
        if self._lost_reason:
            self._lose_locked(self._lost_reason)
            return
        if (
            self._estop_latched
            and not self._estop_acked
            and now - self._estop_last_tx >= cfg.ack_timeout_s
        ):
            self._send_estop_locked()
        if self._state == LinkState.HANDSHAKING:
            hs = self._handshake
            if (
                self._takeover_requested
                and hs is not None
                and not hs.hello.flags & HelloFlag.TAKEOVER
            ):
                # takeover() asked during a plain handshake: start again with the flag.
                self._close_port()
                self._next_attempt = 0.0
                self._set_state(LinkState.DISCONNECTED, "taking over the robot")
                return
            if now - self._hs_started > cfg.handshake_timeout_s:
                self._lose_locked(f"no handshake answer within {cfg.handshake_timeout_s:.1f} s")
            elif now - self._hs_last_hello >= cfg.hello_interval_s:
                self._send_hello_locked()
            return
        if now - self._last_rx > cfg.link_timeout_s:
            self._lose_locked(f"no frame from the robot for {now - self._last_rx:.2f} s")
            return
        if self._unacked:
            oldest = next(iter(self._unacked.values()))
            if now >= oldest.deadline:
                oldest.retries += 1
                if oldest.retries > cfg.max_retries:
                    self._lose_locked(
                        f"{type(oldest.message).__name__} seq {oldest.seq} not acknowledged "
                        f"after {cfg.max_retries} retransmissions"
                    )
                    return
                self._resend_from_locked(oldest.seq, now)
        if now - self._last_tx >= cfg.heartbeat_s:
            self._write_locked(self._seal_locked(Heartbeat(), 0))

    def _open_locked(self, frame: Frame) -> Message | None:
        """The message in ``frame`` if it is authentic (or an allowed plain one), else None."""
        mac = self._mac
        if mac is not None:
            try:
                return mac.open_message(frame)
            except MessageError:
                self._stats["frames_invalid"] += 1
                return None
            except AuthError:
                pass  # maybe one of the plain handshake answers
        try:
            msg = decode_message(frame)
        except MessageError:
            msg = None
        # Plain: only the robot's handshake answers, and only while handshaking.
        if self._state == LinkState.HANDSHAKING and (
            isinstance(msg, Challenge)
            or (isinstance(msg, HelloAck) and msg.status != HelloStatus.OK)
        ):
            return msg
        self._stats["frames_unauthenticated"] += 1
        return None

    def _resend_from_locked(self, seq: int, now: float) -> None:
        """Go-back-N: resend ``seq`` and every later unacknowledged frame, in order."""
        found = False
        for pending in self._unacked.values():
            found = found or pending.seq == seq
            if found:
                pending.deadline = now + self.config.ack_timeout_s
                self._stats["retransmits"] += 1
                # Sealed again: the robot drops a repeated counter as a replay.
                self._write_locked(self._seal_locked(pending.message, pending.seq))

    def _on_message_locked(self, msg: Message, now: float) -> None:
        self._last_rx = now
        self._last_rx_wall = time.time()
        self._stats["frames_rx"] += 1
        if isinstance(msg, Challenge):
            self._on_challenge_locked(msg)
        elif isinstance(msg, HelloAck):
            self._on_hello_ack_locked(msg)
        elif self._state == LinkState.HANDSHAKING and not isinstance(msg, State):
            return  # leftovers of an earlier session
        elif isinstance(msg, State):
            self._on_state_locked(msg)
        elif isinstance(msg, Ack):
            self._on_ack_locked(msg)
        elif isinstance(msg, Nak):
            self._on_nak_locked(msg, now)
        # Host-bound types only; anything else (an echo on loop://) is ignored.

    def _on_challenge_locked(self, msg: Challenge) -> None:
        if self._state != LinkState.HANDSHAKING or self._mac is not None:
            return  # a duplicate answer to a repeated HELLO
        if msg.status == HelloStatus.LINE_BUSY:
            self._refuse_robot_locked(
                "robot is controlled by another host (line busy); a takeover is needed",
                slow=False,
            )
            return
        hs = self._handshake
        if hs is None:
            return
        try:
            self._mac = hs.accept(msg)
        except AuthError as exc:
            # An impostor, or a robot with another secret: never stream to it.
            self._stats["auth_failures"] += 1
            self._refuse_robot_locked(str(exc), slow=True)
            return
        self._send_hello_locked()  # now the AUTH

    def _on_hello_ack_locked(self, msg: HelloAck) -> None:
        if self._state != LinkState.HANDSHAKING:
            return  # a late duplicate answer to a repeated HELLO
        if msg.status != HelloStatus.OK or msg.major != PROTOCOL_MAJOR:
            self._backoff = self.config.backoff_max_s
            self._lose_locked(
                f"robot speaks protocol {msg.major}.{msg.minor}, host speaks {PROTOCOL_MAJOR}.x"
            )
            return
        expected = self.config.expected_robot
        if expected and msg.name != expected:
            self._backoff = self.config.backoff_max_s
            self._lose_locked(f"robot announces itself as {msg.name!r}, expected {expected!r}")
            return
        self._hello = msg
        # Ready only with the first state report (faults, progress) in hand.

    def _on_state_locked(self, msg: State) -> None:
        self._report = msg
        self._awaiting_report = False
        if self._state == LinkState.HANDSHAKING:
            if self._hello is None:
                return
            self._session += 1
            self._backoff = self.config.backoff_initial_s
            self._takeover_requested = False
            if self._estop_latched and not msg.faults & FaultFlag.ESTOP:
                # The E-stop sent on opening the port was not (yet) obeyed: repeat it.
                self._estop_acked = False
            self._set_state(LinkState.READY, "session open")
            self._emit_locked(Connected(self._session, self._hello))
        self._emit_locked(ReportReceived(msg, self._session))
        self._update_state_locked()
        self._cond.notify_all()

    def _on_ack_locked(self, msg: Ack) -> None:
        if msg.ref_type == MsgType.ESTOP:
            self._estop_acked = True
            return
        pending = self._unacked.get(msg.ref_seq)
        if pending is None or msg.ref_type != pending.message.TYPE:
            return  # duplicate answer to a retransmission
        del self._unacked[msg.ref_seq]
        if is_command(msg.ref_type):
            self._awaiting_report = True
        self._emit_locked(FrameAcked(msg.ref_seq, pending.message, msg, self._session))
        self._update_state_locked()

    def _on_nak_locked(self, msg: Nak, now: float) -> None:
        if msg.reason == NakReason.NOT_READY:
            self._lose_locked("robot has no session (it restarted?)")
            return
        pending = self._unacked.get(msg.ref_seq)
        if pending is None or msg.ref_type != pending.message.TYPE:
            if msg.reason == NakReason.SEQ_GAP:
                self._gap_locked(msg.expected_seq, now)
            return
        self._stats["naks"] += 1
        if msg.reason == NakReason.SEQ_GAP:
            self._gap_locked(msg.expected_seq, now)
        elif msg.reason == NakReason.BUSY and pending.naks < self.config.max_busy_naks:
            pending.naks += 1
            # Back off one ack timeout, and keep the gap NAKs of the frames
            # behind it from triggering an immediate resend.
            pending.deadline = now + self.config.ack_timeout_s
            self._gap_resend = (pending.seq, now)
        else:
            del self._unacked[msg.ref_seq]
            self._emit_locked(FrameRefused(msg.ref_seq, pending.message, msg, self._session))
            if msg.reason in TRANSIENT_NAKS:
                # The robot still expects this seq, so nothing behind it can
                # get through: start a fresh session rather than stall.
                self._lose_locked(
                    f"robot refused {type(pending.message).__name__} seq {pending.seq} "
                    f"{pending.naks + 1} times ({NakReason(msg.reason).name})"
                )
                return
            self._update_state_locked()

    def _gap_locked(self, expected: int, now: float) -> None:
        last_seq, last_t = self._gap_resend
        if expected == last_seq and now - last_t < self.config.ack_timeout_s:
            return  # every frame after a lost one is NAKed; resend once
        if expected in self._unacked:
            self._gap_resend = (expected, now)
            self._resend_from_locked(expected, now)


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


def _fault_names(faults: int) -> str:
    names = [f.name for f in FaultFlag if f and faults & f and f.name]
    return ", ".join(names) if names else "a fault"
