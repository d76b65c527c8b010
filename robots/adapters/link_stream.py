"""Command streaming of a robot link (docs/protocol.md §6, §12): sequenced
frames sealed with the session MAC and counter, the plain E-stop frame,
ACK/NAK handling and bounded go-back-N retransmission.
"""

from __future__ import annotations

import logging
import time

from robots.adapters.link_core import _LinkCore
from robots.adapters.link_types import (
    CONNECTED_STATES,
    FrameAcked,
    FrameRefused,
    LinkDownError,
    _Pending,
)
from robots.protocol.auth import AuthError
from robots.protocol.messages import (
    TRANSIENT_NAKS,
    Ack,
    Estop,
    Message,
    MsgType,
    Nak,
    NakReason,
    encode_message,
    is_command,
)

log = logging.getLogger("robots.adapters.link")


class _CommandStream(_LinkCore):
    """The reliable channel of :class:`~robots.adapters.link.RobotLink`."""

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
                now = time.monotonic()
                gap, self._last_tx = now - self._last_tx, now
                self._stats["frames_tx"] += 1
                in_session = self._state in CONNECTED_STATES
                if in_session and self._tx_in_session and gap > 2.5 * self.config.heartbeat_s:
                    # Evidence for a robot watchdog that fires: was the host silent?
                    self._stats["tx_gaps_long"] += 1
                    log.warning("%s: %.3f s without a frame to the robot", self.name, gap)
                self._tx_in_session = in_session
            except Exception as exc:  # any handler's error means the link is gone
                # Closing belongs to the I/O thread (it may be inside read()).
                self._lost_reason = self._lost_reason or f"write failed: {exc}"
                self._wake.set()

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
