"""Session set-up of a robot link (docs/protocol.md §12,
:mod:`robots.protocol.auth`): opening the port, the mutual challenge–response
handshake (HELLO → CHALLENGE → AUTH → HELLO_ACK), refusing a robot that is
busy, incompatible or fails authentication, and telling authentic frames
from plain ones.
"""

from __future__ import annotations

import contextlib
import time

from robots.adapters.link_stream import _CommandStream
from robots.adapters.link_types import (
    LinkState,
    _disable_nagle,
)
from robots.protocol.auth import AuthError, HostHandshake
from robots.protocol.framing import PROTOCOL_MAJOR, Frame
from robots.protocol.messages import (
    Challenge,
    Hello,
    HelloAck,
    HelloStatus,
    Message,
    MessageError,
    decode_message,
    encode_message,
)


class _Session(_CommandStream):
    """Handshake and authentication of :class:`~robots.adapters.link.RobotLink`."""

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
