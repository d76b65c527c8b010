"""State machine of a robot link (docs/protocol.md §6): every piece of a
link's state (one ``RLock`` guards it; the write lock and the dispatch lock
are taken inside it in that order), the ready / streaming / fault
recomputation, event queueing and in-order dispatch outside the lock,
and losing a link: close the port, back off exponentially, retry.
"""

from __future__ import annotations

import collections
import contextlib
import logging
import threading
import time
from collections.abc import Callable
from typing import Any

import serial

from robots.adapters.link_types import (
    CONNECTED_STATES,
    CaptureReceived,
    LinkConfig,
    LinkEvent,
    LinkState,
    LinkStateChanged,
    _fault_names,
    _Pending,
)
from robots.protocol.auth import HostHandshake, SessionMac
from robots.protocol.capture import CaptureAssembler
from robots.protocol.framing import FrameDecoder
from robots.protocol.messages import (
    HelloAck,
    Mode,
    State,
)

# One logger for the whole link (its parts are modules of one component).
log = logging.getLogger("robots.adapters.link")


class _LinkCore:
    """State, events and link loss of :class:`~robots.adapters.link.RobotLink`."""

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
        self._tx_in_session = False  # the last frame written went out in a session
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
        # Reassembles the robot's captures (bounded: one at a time, ≤ MAX_CAPTURE_POINTS).
        self._captures = CaptureAssembler(timeout_s=self.config.capture_timeout_s)

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

    def _schedule_retry_locked(self, reason: str) -> None:
        self._next_attempt = time.monotonic() + self._backoff
        self._set_state(LinkState.DISCONNECTED, f"{reason}; retrying in {self._backoff:.1f} s")
        self._backoff = min(self._backoff * 2, self.config.backoff_max_s)

    def _flush_captures_locked(self) -> None:
        """Hand on the capture being reassembled (incomplete if chunks are missing)."""
        for cap in self._captures.flush():
            self._emit_locked(CaptureReceived(cap, self._session))

    def _close_port(self) -> None:
        # Whatever part of a capture arrived goes on: the rest is lost with the link.
        self._flush_captures_locked()
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
