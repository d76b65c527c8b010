"""Execute a :class:`~robots.protocol.program.Program` over a :class:`RobotLink`.

:class:`Streamer` (alias :data:`ExecutionDriver`) is what a dispatch engine
drives.  It keeps at most ``window`` commands in the robot's buffer ahead of
the last *completed* one, and reports progress through callbacks:

``on_ack(index)``
    command ``index`` has been executed to completion by the robot.  Called
    once per index, in order, on the streamer's thread; command
    ``index + window`` is not sent before it returns, so persisting here
    (SQLite) is "record before advancing".  The resume point is
    ``last acked + 1``.  If it raises, streaming stops (robot paused) and
    ``on_fault`` reports a ``host`` fault.
``on_acks(first, last)``
    instead of ``on_ack``: commands ``first`` … ``last`` (inclusive) have
    completed, once per state report that advances ``last_done``, with the
    same ordering and "record before advancing" guarantee.  One report often
    completes several short commands; one call lets the caller persist them
    in one transaction (one ``fsync``) instead of one each.
``on_state(report)``
    every robot state report (:class:`robots.protocol.messages.State`) while the
    streamer is alive — mirror it into the store / scene.
``on_capture(capture)``
    every sensor frame (:class:`robots.protocol.capture.SensorCapture`) of
    this run (``capture.run_id == run_id``) the link reassembles, on the
    streamer's thread, before the ``on_ack`` of its ``capture`` command when
    its frames arrived intact (they precede the report that completes it).
    An incomplete one (``complete=False``: chunks lost) may come later.
``on_done(outcome)``
    once, when the execution ends for good: ``completed``, ``aborted`` or
    ``estopped``.
``on_fault(fault)``
    the execution stopped but can be resumed (:class:`StreamFault`:
    ``link_lost`` → interrupted, ``robot_fault``/``rejected``/``host`` → faulted).

Resume and exactly-once: a command counts as executed only when a state report
says so (``last_done``, cumulative).  After a link loss the robot has stopped
(watchdog / new session) and dropped its queue; the streamer — this one via
:meth:`Streamer.resume`, or a new one created with ``start=last_acked + 1``
after a server restart — first takes the robot's own ``last_done`` for this
``run_id`` (acknowledging what completed while the link was down) and then
streams from there.  The robot also refuses to re-execute an index at or
below its ``last_done`` (it answers ``ALREADY_DONE``), so a stale resume point
cannot run a command twice.
"""

from __future__ import annotations

import enum
import logging
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from robots.adapters.link import (
    CONNECTED_STATES,
    CaptureReceived,
    EstopLatched,
    FrameAcked,
    FrameRefused,
    LinkDownError,
    LinkEvent,
    LinkStateChanged,
    ReportReceived,
    RobotLink,
)
from robots.protocol.capture import SensorCapture
from robots.protocol.commands import CommandError
from robots.protocol.messages import (
    LINK_FAULTS,
    ROBOT_FAULTS,
    AckStatus,
    CommandMessage,
    FaultFlag,
    Mode,
    NakReason,
    State,
)
from robots.protocol.program import Program

log = logging.getLogger(__name__)


class ExecState(enum.StrEnum):
    """Streamer state; the last three are terminal."""

    PENDING = "pending"  # created, waiting for the link
    RUNNING = "running"
    PAUSED = "paused"
    INTERRUPTED = "interrupted"  # link lost; resumable
    FAULTED = "faulted"  # robot fault / refusal / host callback error; resumable
    COMPLETED = "completed"
    ABORTED = "aborted"
    ESTOPPED = "estopped"


TERMINAL_STATES = frozenset({ExecState.COMPLETED, ExecState.ABORTED, ExecState.ESTOPPED})


class Outcome(enum.StrEnum):
    COMPLETED = "completed"
    ABORTED = "aborted"
    ESTOPPED = "estopped"


class FaultKind(enum.StrEnum):
    LINK_LOST = "link_lost"  # → execution "interrupted"
    ROBOT_FAULT = "robot_fault"  # robot latched a fault (DRIVE, FALL_RISK) or an E-stop
    REJECTED = "rejected"  # robot refused a command (limits, invalid, busy too often)
    ROBOT_BUSY = "robot_busy"  # robot is executing another run
    HOST = "host"  # a callback raised, or the program cannot be encoded


@dataclass(frozen=True)
class StreamFault:
    """Why an execution stopped; ``index`` is the command concerned, if any."""

    kind: FaultKind
    message: str
    index: int | None = None

    def __str__(self) -> str:
        return f"{self.kind.value}: {self.message}"


class Streamer:
    """Streams one program to one robot; see the module docstring.

    ``run_id`` (1 … 2³²−1) identifies the execution on the robot and must stay
    the same across resumes of that execution (store it with the execution).
    ``start`` is the first command to run (the persisted last ack + 1).
    """

    def __init__(
        self,
        program: Program,
        link: RobotLink,
        *,
        run_id: int,
        start: int = 0,
        on_ack: Callable[[int], None] | None = None,
        on_acks: Callable[[int, int], None] | None = None,
        on_state: Callable[[State], None] | None = None,
        on_done: Callable[[Outcome], None] | None = None,
        on_fault: Callable[[StreamFault], None] | None = None,
        on_capture: Callable[[SensorCapture], None] | None = None,
        window: int = 8,
        connect_timeout_s: float = 10.0,
        clear_robot_faults: bool = False,
    ) -> None:
        if not 1 <= run_id <= 0xFFFFFFFF:
            raise ValueError(f"run_id={run_id}: must be 1 … 2**32-1")
        if not 0 <= start <= len(program):
            raise ValueError(f"start={start}: must be 0 … {len(program)} (program length)")
        if window < 1:
            raise ValueError(f"window={window}: must be ≥ 1")
        self.program = program
        self.link = link
        self.run_id = run_id
        if on_ack is not None and on_acks is not None:
            raise ValueError("give on_ack or on_acks, not both")
        self._on_ack = on_ack
        self._on_acks = on_acks
        self._on_state = on_state
        self._on_done = on_done
        self._on_fault = on_fault
        self._on_capture = on_capture
        self._window = window
        self._connect_timeout_s = connect_timeout_s
        self._clear_robot_faults = clear_robot_faults
        self._acked = start - 1  # last index reported complete (and handed to on_ack)
        self._sent = start - 1  # last index sent in the current session
        self._session = -1
        self._state = ExecState.PENDING
        self._fault: StreamFault | None = None
        self._waiting_link = False  # set while waiting for a session to (re)start on
        self._link_deadline = 0.0
        # A CLEAR in flight: reports sent before the robot got it still show those
        # faults, and must not be taken for new ones.
        self._pending_clear: tuple[int, int] | None = None  # (seq, fault bits)
        # Fault bits a FAULTED refusal told us of before any report carried them:
        # a resume right after such a refusal must clear them although the last
        # report (older than the refusal) does not show them yet.
        self._refused_faults = 0
        self._lock = threading.Lock()
        self._cond = threading.Condition(self._lock)
        self._queue: queue.Queue[tuple[str, object]] = queue.Queue()
        self._unsubscribe: Callable[[], None] | None = None
        self._thread: threading.Thread | None = None

    # --- public API (thread-safe; operations run on the streamer's thread) -------------

    def start(self) -> Streamer:
        if self._thread is not None:
            return self
        self._queue.put(("op", "begin"))  # first in the queue, before any link event
        self._unsubscribe = self.link.subscribe(self._on_link_event)
        self._thread = threading.Thread(
            target=self._run, name=f"streamer run {self.run_id}", daemon=True
        )
        self._thread.start()
        return self

    def pause(self) -> None:
        self._queue.put(("op", "pause"))

    def resume(self, *, clear_robot_faults: bool = False) -> None:
        """Continue after pause, an interruption or a fault (after :meth:`RobotLink.clear_estop`
        for an E-stop).  Link faults are cleared on the robot automatically; a robot
        fault only with ``clear_robot_faults=True`` (an explicit operator decision)."""
        self._queue.put(("op", "resume_clear" if clear_robot_faults else "resume"))

    def abort(self) -> None:
        self._queue.put(("op", "abort"))

    def estop(self) -> None:
        """E-stop this robot now (written from the calling thread), then end the execution."""
        self.link.estop()
        self._queue.put(("op", "estop"))

    def estopped(self) -> None:
        """The robot was E-stopped already (by the caller): end the execution, send nothing.

        Unlike :meth:`estop` this never latches the link again, so an operator's
        clear that overtakes this call is not undone.
        """
        self._queue.put(("op", "estop"))

    def close(self, timeout: float = 5.0) -> None:
        """Stop the streamer's thread without telling the robot anything."""
        self._queue.put(("stop", None))
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout)
        if self._unsubscribe is not None:
            self._unsubscribe()
            self._unsubscribe = None

    def __enter__(self) -> Streamer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def state(self) -> ExecState:
        return self._state

    @property
    def last_acked(self) -> int:
        """Last command index reported complete (−1 / start−1 when none)."""
        return self._acked

    @property
    def fault(self) -> StreamFault | None:
        return self._fault

    @property
    def progress(self) -> float:
        n = len(self.program)
        return 1.0 if n == 0 else (self._acked + 1) / n

    def wait(
        self,
        states: set[ExecState] | frozenset[ExecState] | None = None,
        timeout: float | None = None,
    ) -> ExecState | None:
        """Block until the state is in ``states`` (default: terminal); ``None`` on timeout."""
        wanted = states or TERMINAL_STATES
        with self._cond:
            ok = self._cond.wait_for(lambda: self._state in wanted, timeout)
            return self._state if ok else None

    # --- thread ---------------------------------------------------------------------------

    def _on_link_event(self, event: LinkEvent) -> None:
        self._queue.put(("link", event))

    def _run(self) -> None:
        while True:
            try:
                kind, item = self._queue.get(timeout=self._wait_timeout())
            except queue.Empty:
                self._link_wait_expired()
                continue
            if kind == "stop":
                return
            try:
                if kind == "op":
                    self._op(str(item))
                else:
                    self._link(item)  # type: ignore[arg-type]
            except Exception as exc:  # a bug or a broken callback must not wedge the robot
                log.exception("streamer run %s failed", self.run_id)
                self._to_fault(ExecState.FAULTED, StreamFault(FaultKind.HOST, repr(exc)))

    def _wait_timeout(self) -> float | None:
        # Only the "waiting for the link" phase has a deadline; otherwise block.
        if self._waiting_link and self._active():
            return max(0.0, self._link_deadline - time.monotonic())
        return None

    def _active(self) -> bool:
        return self._state in (ExecState.PENDING, ExecState.RUNNING, ExecState.PAUSED)

    def _set_state(self, state: ExecState) -> None:
        with self._cond:
            self._state = state
            self._cond.notify_all()

    # --- operations -----------------------------------------------------------------------

    def _op(self, op: str) -> None:
        if self._state in TERMINAL_STATES:
            return
        if op == "begin":
            self._begin_when_linked(resume=False)
        elif op in ("resume", "resume_clear"):
            if op == "resume_clear":
                self._clear_robot_faults = True
            if self._state == ExecState.PAUSED and not self._waiting_link:
                self._try_send(self.link.resume)
                self._set_state(ExecState.RUNNING)
                self._pump()
            elif self._state in (ExecState.INTERRUPTED, ExecState.FAULTED, ExecState.PENDING):
                self._fault = None
                self._set_state(ExecState.PENDING)
                self._begin_when_linked(resume=True)
        elif op == "pause":
            if self._state == ExecState.RUNNING:
                self._try_send(self.link.pause)
                self._set_state(ExecState.PAUSED)
        elif op == "abort":
            if self.link.connected:
                self._try_send(self.link.abort)
            self._finish(Outcome.ABORTED)
        elif op == "estop":
            self._finish(Outcome.ESTOPPED)

    def _try_send(self, fn: Callable[[], int]) -> bool:
        try:
            fn()
            return True
        except LinkDownError:
            return False

    def _begin_when_linked(self, *, resume: bool) -> None:
        self._waiting_link = True
        self._link_deadline = time.monotonic() + self._connect_timeout_s
        if self.link.connected and self.link.last_report is not None:
            self._begin()
        # else: the next Connected/ReportReceived event (or the timeout) continues.

    def _link_wait_expired(self) -> None:
        if self._waiting_link and self._active() and time.monotonic() >= self._link_deadline:
            self._to_fault(
                ExecState.INTERRUPTED,
                StreamFault(
                    FaultKind.LINK_LOST,
                    f"robot not connected after {self._connect_timeout_s:.0f} s "
                    f"({self.link.status().reason})",
                ),
            )

    def _begin(self) -> None:
        """Reconcile with the robot's report, clear link faults, then stream."""
        report = self.link.last_report
        assert report is not None
        self._waiting_link = False
        self._session = self.link.session
        if self.link.estop_latched or report.faults & FaultFlag.ESTOP:
            self._to_fault(
                ExecState.FAULTED,
                StreamFault(FaultKind.ROBOT_FAULT, "E-stop is latched; clear it before resuming"),
            )
            return
        if report.run_id == self.run_id:
            self._advance_acks(report.last_done)
            if self._state in TERMINAL_STATES or self._fault is not None:
                return
            if report.buffer_level > 0 or report.mode in (Mode.MOVING, Mode.PAUSED):
                # Our run is still queued from an earlier streamer in this session:
                # start over from a clean queue; the robot's ALREADY_DONE guard
                # keeps anything finished meanwhile from running twice.
                self._try_send(self.link.abort)
        elif report.buffer_level > 0 or report.mode in (Mode.MOVING, Mode.PAUSED):
            self._to_fault(
                ExecState.FAULTED,
                StreamFault(FaultKind.ROBOT_BUSY, f"robot is executing run {report.run_id}"),
            )
            return
        latched = report.faults | self._refused_faults
        to_clear = latched & LINK_FAULTS
        if latched & ROBOT_FAULTS:
            if not self._clear_robot_faults:
                self._to_fault(
                    ExecState.FAULTED,
                    StreamFault(
                        FaultKind.ROBOT_FAULT,
                        f"robot fault latched (code {report.fault_code}, "
                        f"{_names(latched & ROBOT_FAULTS)}); "
                        "resume with clear_robot_faults=True to clear it",
                    ),
                )
                return
            to_clear |= latched & ROBOT_FAULTS
        self._clear_robot_faults = False
        self._refused_faults = 0
        self._pending_clear = None
        if to_clear:
            try:
                self._pending_clear = (self.link.clear_faults(to_clear), int(to_clear))
            except LinkDownError:
                return  # link dropped again; the state-change event handles it
        self._sent = self._acked
        if self._acked >= len(self.program) - 1:
            self._finish(Outcome.COMPLETED)
            return
        self._set_state(ExecState.RUNNING)
        self._pump()

    def _pump(self) -> None:
        """Send commands while fewer than ``window`` are outstanding (sent, not done)."""
        if self._state != ExecState.RUNNING or self._waiting_link:
            return
        info = self.link.robot_info
        window = min(self._window, info.buffer_capacity if info else self._window)
        n = len(self.program)
        while self._sent < n - 1 and self._sent - self._acked < window:
            index = self._sent + 1
            try:
                self.link.send_command(self.program[index], self.run_id, index)
            except LinkDownError:
                return  # the link event moves us to interrupted
            except CommandError as exc:
                self._try_send(self.link.abort)
                self._to_fault(
                    ExecState.FAULTED,
                    StreamFault(FaultKind.HOST, f"command {index} cannot be encoded: {exc}", index),
                )
                return
            self._sent = index

    def _advance_acks(self, last_done: int) -> None:
        last = min(last_done, len(self.program) - 1)
        while self._acked < last:
            first = self._acked + 1
            upto = last if self._on_acks is not None else first
            try:
                if self._on_acks is not None:
                    self._on_acks(first, upto)
                elif self._on_ack is not None:
                    self._on_ack(first)
            except Exception as exc:
                # Not persisted → not advanced: hold the robot, let the operator decide.
                self._try_send(self.link.pause)
                what = f"on_acks({first}, {upto})" if self._on_acks else f"on_ack({first})"
                self._to_fault(
                    ExecState.FAULTED,
                    StreamFault(FaultKind.HOST, f"{what} failed: {exc!r}", first),
                )
                return
            with self._cond:
                self._acked = upto
        if self._acked >= len(self.program) - 1 and len(self.program) > 0:
            self._finish(Outcome.COMPLETED)

    def _finish(self, outcome: Outcome) -> None:
        if self._state in TERMINAL_STATES:
            return
        self._set_state(ExecState(outcome.value))
        self._call(self._on_done, outcome)

    def _to_fault(self, state: ExecState, fault: StreamFault) -> None:
        if self._state in TERMINAL_STATES:
            return
        self._fault = fault
        self._waiting_link = state == ExecState.INTERRUPTED
        log.warning("run %s %s: %s", self.run_id, state.value, fault)
        self._set_state(state)
        self._call(self._on_fault, fault)

    # --- link events ----------------------------------------------------------------------

    def _link(self, event: LinkEvent) -> None:
        if isinstance(event, CaptureReceived):
            # Even after the end: what the robot saw is kept whatever the outcome.
            if event.capture.run_id == self.run_id:
                self._call(self._on_capture, event.capture)
            return
        if self._state in TERMINAL_STATES:
            return
        if isinstance(event, EstopLatched):
            # E-stop ends the execution whatever the link is doing (even reconnecting).
            self._finish(Outcome.ESTOPPED)
        elif isinstance(event, ReportReceived):
            self._on_report(event.report)
        elif isinstance(event, LinkStateChanged):
            if (
                event.new not in CONNECTED_STATES
                and event.old in CONNECTED_STATES
                and event.session == self._session
            ) and (
                self._state in (ExecState.RUNNING, ExecState.PAUSED)
                or (self._state == ExecState.PENDING and not self._waiting_link)
            ):
                self._to_fault(
                    ExecState.INTERRUPTED, StreamFault(FaultKind.LINK_LOST, event.reason)
                )
        elif isinstance(event, FrameRefused):
            msg = event.message
            if isinstance(msg, CommandMessage) and msg.run_id != self.run_id:
                return
            if self._state not in (ExecState.RUNNING, ExecState.PAUSED, ExecState.PENDING):
                return
            index = msg.index if isinstance(msg, CommandMessage) else None
            what = f"command {index}" if index is not None else type(msg).__name__
            latched = int(event.nak.detail) if event.nak.reason == NakReason.FAULTED else 0
            if event.nak.reason == NakReason.FALL_RISK:
                # Refused because the robot would fall: it latched FALL_RISK and stopped.
                latched = int(FaultFlag.FALL_RISK)
            if (
                latched
                and self._pending_clear is not None
                and not latched & ~self._pending_clear[1]
            ):
                # Refused for faults our CLEAR (in flight) removes: the robot sent
                # this before it got the CLEAR; the command is sent again anyway.
                return
            self._refused_faults |= latched
            prefix = ""
            if latched & FaultFlag.ESTOP:
                # An E-stop latched on the robot, reported as this refusal
                # before the state report that carries it.
                self._finish(Outcome.ESTOPPED)
                return
            if latched and not latched & ~LINK_FAULTS:
                # The robot's watchdog (or a link reset) latched, reaching us as
                # this refusal before the state report carrying it: the same
                # interruption the report would give, resumable without an
                # operator's fault clear.
                self._to_fault(
                    ExecState.INTERRUPTED,
                    StreamFault(
                        FaultKind.LINK_LOST,
                        f"robot stopped by its watchdog / link reset; it refused {what}: "
                        f"{event.reason}",
                        index,
                    ),
                )
                return
            if event.nak.reason == NakReason.RUN_ACTIVE:
                # Another execution owns the robot: leave it alone.
                kind = FaultKind.ROBOT_BUSY
            else:
                # Our run cannot go on as planned: stop it now rather than after
                # the commands already queued (resume restarts from the last ack).
                kind = FaultKind.REJECTED
                if latched & ROBOT_FAULTS:
                    # The robot's own fault, reaching us as this refusal before
                    # the state report carrying it: only an operator's explicit
                    # clear may resume from it.
                    kind = FaultKind.ROBOT_FAULT
                    last = self.link.last_report
                    if last is not None and last.fault_code:
                        prefix = f"robot fault code {last.fault_code}; "
                self._try_send(self.link.abort)
            self._to_fault(
                ExecState.FAULTED,
                StreamFault(kind, f"{prefix}robot refused {what}: {event.reason}", index),
            )
        elif isinstance(event, FrameAcked):
            msg = event.message
            if self._pending_clear is not None and event.seq == self._pending_clear[0]:
                self._pending_clear = None
            if (
                isinstance(msg, CommandMessage)
                and msg.run_id == self.run_id
                and event.ack.status == AckStatus.ALREADY_DONE
            ):
                # The robot finished it earlier; its reports will carry last_done ≥ index.
                log.info("run %s: command %s already done on the robot", self.run_id, msg.index)

    def _call(self, callback: Callable[[Any], None] | None, arg: object) -> None:
        """Run a mirror/notification callback; its failure is logged, not fatal."""
        if callback is None:
            return
        try:
            callback(arg)
        except Exception:
            log.exception("run %s: callback %r failed", self.run_id, callback)

    def _on_report(self, report: State) -> None:
        self._call(self._on_state, report)
        # A report is newer than any refusal before it on the link: it is the truth.
        self._refused_faults = 0
        if self._waiting_link:
            if self._state == ExecState.PENDING and self.link.connected:
                self._begin()
            return
        if self._state not in (ExecState.RUNNING, ExecState.PAUSED):
            return
        if self.link.session != self._session:
            return  # a new session without the disconnect event yet; it follows
        if report.run_id == self.run_id:
            self._advance_acks(report.last_done)
        if self._state in TERMINAL_STATES or self._state == ExecState.FAULTED:
            return
        faults = report.faults & ~(self._pending_clear[1] if self._pending_clear else 0)
        if faults & FaultFlag.ESTOP or report.mode == Mode.ESTOP:
            self._finish(Outcome.ESTOPPED)
        elif faults & ROBOT_FAULTS:
            self._to_fault(
                ExecState.FAULTED,
                StreamFault(
                    FaultKind.ROBOT_FAULT,
                    f"robot fault code {report.fault_code} ({_names(faults & ROBOT_FAULTS)}) "
                    "while executing command "
                    f"{report.executing if report.executing >= 0 else self._acked + 1}",
                    self._acked + 1,
                ),
            )
        elif faults & LINK_FAULTS:
            self._to_fault(
                ExecState.INTERRUPTED,
                StreamFault(FaultKind.LINK_LOST, "robot stopped by its watchdog / link reset"),
            )
        else:
            self._pump()


def _names(bits: int) -> str:
    return "|".join(f.name for f in FaultFlag if f and bits & f and f.name) or str(bits)


#: The name the dispatch engine may prefer.
ExecutionDriver = Streamer
