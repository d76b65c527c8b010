"""Recording captures as they arrive: from the robot's link to the store.

The robot link (``robots.adapters``) reassembles a capture's header and
point chunks into a :class:`robots.protocol.capture.SensorCapture`, on its
I/O thread.  The dispatch engine, which owns the links inside the robot-link
service process (:mod:`server.linkservice.service`), hands each one to a
:class:`CaptureRecorder` (``submit``: a put on a bounded queue, never a
blocking call), whose own thread finds the execution by the robot and the
capture's ``run_id`` and calls :func:`record_capture`.

The link service writes the same store (database and data directory) as the
web server, so the points never cross the service's channel: only a small
``capture`` event does (execution, capture id, point count), which the web
server publishes on its event bus (the console's event stream) and the scene
draws from the store (:mod:`server.scene.captures`).

A capture refused (a bound of :class:`server.captures.limits.CaptureLimits`
reached, the disk at its reserve, a malformed capture) is recorded on its
execution as an audit event ``capture-refused``, once per execution and
reason, and announced as a ``capture`` event with ``refused``; nothing else
changes: the run goes on.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from typing import TYPE_CHECKING, Any

from robots.protocol.capture import SensorCapture
from server.captures.limits import CaptureLimits, capture_limits
from server.captures.store import CaptureRecord, CaptureRefused, CaptureStore

if TYPE_CHECKING:
    from server.diskspace import DiskGauge
    from server.store import ExecutionRecord, Store

log = logging.getLogger(__name__)

#: Captures waiting for the recorder thread; beyond this they are refused.
QUEUE_CAPTURES = 64
#: Audit action of a refused capture.
REFUSED_ACTION = "capture-refused"


def execution_for_run(store: Store, robot: str, run_id: int) -> ExecutionRecord | None:
    """The newest execution of ``robot`` with ``run_id`` (a resumed run keeps its id)."""
    row = store.db.query_one(
        "SELECT id FROM executions WHERE robot = ? AND run_id = ? ORDER BY created_at DESC LIMIT 1",
        (robot, int(run_id)),
    )
    return None if row is None else store.get_execution(str(row["id"]))


def _note_refusal(store: Store, execution_id: str, exc: CaptureRefused) -> bool:
    """Audit the refusal on the execution, once per reason; whether it was written."""
    reason = f"[{exc.why}] {exc}"
    seen = store.db.query_one(
        "SELECT 1 FROM audit_events WHERE entity = 'execution' AND entity_id = ? "
        "AND action = ? AND reason LIKE ? LIMIT 1",
        (execution_id, REFUSED_ACTION, f"[{exc.why}]%"),
    )
    if seen is not None:
        return False
    more = " (later captures refused for the same reason are not recorded one by one)"
    store.audit("robot", "execution", execution_id, REFUSED_ACTION, reason + more)
    return True


def record_capture(
    store: Store,
    execution_id: str,
    capture: SensorCapture,
    *,
    events: Any = None,
    limits: CaptureLimits | None = None,
    gauge: DiskGauge | None = None,
    received_at: float | None = None,
) -> CaptureRecord | None:
    """Store ``capture`` with ``execution_id``: its record, or ``None`` when it
    was refused (recorded on the execution, announced on ``events``)."""
    ex = store.get_execution(execution_id)
    captures = CaptureStore(store, limits=limits, gauge=gauge)
    try:
        rec = captures.add(ex.id, capture, received_at)
    except CaptureRefused as exc:
        log.warning("execution %s: %s", ex.id, exc)
        try:
            _note_refusal(store, ex.id, exc)
        except Exception:  # the audit is small, but a broken store must not stop the run
            log.exception("could not record the refused capture of %s", ex.id)
        if events is not None:
            events.publish(
                "capture",
                {
                    "execution_id": ex.id,
                    "plan_id": ex.plan_id,
                    "robot": ex.robot,
                    "capture_id": int(capture.capture_id),
                    "refused": exc.why,
                    "reason": str(exc),
                },
            )
        return None
    if events is not None:
        events.publish(
            "capture",
            {
                "execution_id": ex.id,
                "plan_id": ex.plan_id,
                "robot": ex.robot,
                "capture_id": rec.capture_id,
                "command_index": rec.command_index,
                "n_points": rec.n_points,
                "complete": rec.complete,
                "received_at": rec.received_at,
            },
        )
    return rec


class CaptureRecorder:
    """Takes captures from link I/O threads, stores them on a thread of its own."""

    def __init__(
        self,
        store: Store,
        events: Any,
        settings: Any = None,
        *,
        limits: CaptureLimits | None = None,
        gauge: DiskGauge | None = None,
    ) -> None:
        self.store = store
        self.events = events
        self.limits = limits or capture_limits(settings)
        if gauge is None and settings is not None:
            from server.diskspace import DiskGauge

            gauge = DiskGauge(store.data_dir, int(settings.disk_reserve_bytes))
        self.gauge = gauge
        self._q: queue.Queue[tuple[str, SensorCapture, float] | None] = queue.Queue(QUEUE_CAPTURES)
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()
        self._closed = False
        self.recorded = 0
        self.dropped = 0

    def submit(self, robot: str, capture: SensorCapture) -> bool:
        """Queue a capture of ``robot`` (any thread, never blocks); ``False`` if
        the queue is full (counted, logged) or the recorder is closed."""
        with self._lock:
            if self._closed:
                return False
            if self._thread is None:
                self._thread = threading.Thread(
                    target=self._run, name="capture recorder", daemon=True
                )
                self._thread.start()
        try:
            self._q.put_nowait((robot, capture, time.time()))
        except queue.Full:
            self.dropped += 1
            log.warning(
                "capture %s of %s dropped: the recorder is behind", capture.capture_id, robot
            )
            return False
        return True

    def close(self, timeout: float = 2.0) -> None:
        with self._lock:
            self._closed = True
            thread = self._thread
        if thread is not None:
            try:
                self._q.put(None, timeout=timeout)
            except queue.Full:
                return
            thread.join(timeout)

    def drain(self, timeout: float = 10.0) -> bool:
        """Wait until every queued capture is handled (tests)."""
        deadline = time.monotonic() + timeout
        while self._q.unfinished_tasks and time.monotonic() < deadline:
            time.sleep(0.01)
        return not self._q.unfinished_tasks

    def _run(self) -> None:
        while True:
            item = self._q.get()
            try:
                if item is None:
                    return
                self.handle(*item)
            except Exception:
                log.exception("could not record a capture")
            finally:
                self._q.task_done()

    def handle(self, robot: str, capture: SensorCapture, received_at: float) -> None:
        ex = execution_for_run(self.store, robot, capture.run_id)
        if ex is None:
            log.warning(
                "capture %s of %s names run %s, which no execution of it has: dropped",
                capture.capture_id,
                robot,
                capture.run_id,
            )
            self.dropped += 1
            return
        rec = record_capture(
            self.store,
            ex.id,
            capture,
            events=self.events,
            limits=self.limits,
            gauge=self.gauge,
            received_at=received_at,
        )
        if rec is not None:
            self.recorded += 1


def capture_of(event: Any) -> SensorCapture | None:
    """The capture a link event carries (the event itself, or its ``capture``), or
    ``None``; cheap enough for a link's I/O thread."""
    if isinstance(event, SensorCapture):
        return event
    cap = getattr(event, "capture", None)
    return cap if isinstance(cap, SensorCapture) else None
