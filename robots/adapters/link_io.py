"""I/O thread of a robot link: the read loop, the timers (host heartbeat,
link watchdog, handshake repeats and timeout, E-stop repeats,
retransmission deadlines) and the robot's state reports (its heartbeat),
which open the session and drive ready / streaming / fault.
"""

from __future__ import annotations

import logging
import time
from typing import Any

from robots.adapters.link_session import _Session
from robots.adapters.link_types import (
    CaptureReceived,
    Connected,
    LinkState,
    ReportReceived,
    _raw_socket,
    _read_some,
)
from robots.protocol.framing import PROTOCOL_MAJOR
from robots.protocol.messages import (
    Ack,
    CaptureChunk,
    CaptureHeader,
    Challenge,
    FaultFlag,
    Heartbeat,
    HelloAck,
    HelloFlag,
    Message,
    Nak,
    State,
)

# One logger for the whole link (its parts are modules of one component).
log = logging.getLogger("robots.adapters.link")


class _IoLoop(_Session):
    """The daemon I/O thread of :class:`~robots.adapters.link.RobotLink`."""

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

    def _service(self, port: Any) -> None:
        try:
            data = _read_some(port, _raw_socket(port), self.config.poll_s)
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
        if self._captures.pending:
            for cap in self._captures.expire(now):
                self._emit_locked(CaptureReceived(cap, self._session))
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
        elif isinstance(msg, CaptureHeader | CaptureChunk):
            for cap in self._captures.feed(msg, now):
                self._emit_locked(CaptureReceived(cap, self._session))
        # Host-bound types only; anything else (an echo on loop://) is ignored.

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
