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

Captures (docs/protocol.md §14): the robot's ``CAPTURE`` header and
``CAPTURE_CHUNK`` messages are reassembled on the I/O thread into
:class:`~robots.protocol.capture.SensorCapture` and emitted as
:class:`CaptureReceived` events (complete or, with chunks lost, not);
:meth:`RobotLink.subscribe_captures` subscribes to those alone.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

from robots.adapters.link_io import _IoLoop
from robots.adapters.link_types import (
    CONNECTED_STATES,
    CaptureReceived,
    Connected,
    EstopLatched,
    FrameAcked,
    FrameRefused,
    LinkConfig,
    LinkDownError,
    LinkEvent,
    LinkState,
    LinkStateChanged,
    LinkStatus,
    ReportReceived,
)
from robots.protocol.capture import SensorCapture
from robots.protocol.commands import Command
from robots.protocol.messages import (
    Abort,
    Clear,
    CommandMessage,
    FaultFlag,
    HelloAck,
    Message,
    Pause,
    Resume,
    State,
)

__all__ = [
    "CONNECTED_STATES",
    "CaptureReceived",
    "Connected",
    "EstopLatched",
    "FrameAcked",
    "FrameRefused",
    "LinkConfig",
    "LinkDownError",
    "LinkEvent",
    "LinkState",
    "LinkStateChanged",
    "LinkStatus",
    "ReportReceived",
    "RobotLink",
]


class RobotLink(_IoLoop):
    """One robot connection over a pyserial URL; see the module docstring.

    Its parts, each a layer on the one before (same lock, same single I/O
    thread; only this class is public):
    :class:`~robots.adapters.link_core._LinkCore` (state, events, link loss
    and backoff) → :class:`~robots.adapters.link_stream._CommandStream`
    (sequenced frames, ACK/NAK, go-back-N, E-stop frame) →
    :class:`~robots.adapters.link_session._Session` (port, handshake,
    authentication) → :class:`~robots.adapters.link_io._IoLoop` (I/O thread,
    heartbeat and watchdog timers, state reports) → this class (the public,
    thread-safe API).
    """

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

    def subscribe_captures(self, callback: Callable[[SensorCapture], None]) -> Callable[[], None]:
        """Call ``callback(capture)`` for every sensor frame the robot sends; returns
        a function that unsubscribes.

        Called like every subscriber: from whichever thread dispatches the
        link's events — normally its I/O thread, sometimes a thread calling
        one of its methods (``close``, ``flush_captures``, ``send_command``…)
        — one event at a time, never concurrently, in order with the other
        events: a capture arrives before the state report that shows its
        command done.  Like every
        subscriber it must only hand the capture on (a queue,
        ``loop.call_soon_threadsafe``), never block: storing it belongs on
        another thread.  ``capture.complete`` is False when chunks were lost.
        """

        def on_event(event: LinkEvent) -> None:
            if isinstance(event, CaptureReceived):
                callback(event.capture)

        return self.subscribe(on_event)

    def flush_captures(self) -> None:
        """Hand on a capture still being reassembled now (incomplete), e.g. at a run's end."""
        with self._lock:
            self._flush_captures_locked()
        self._dispatch()

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
                stats={**self._stats, **self._captures.stats},
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
