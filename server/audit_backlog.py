"""Safety audit records that the store could not write yet, kept until it can.

The E-stop acts first and records after (``server.routers.safety``): when that
record cannot be written (a full disk, a lost database), the answer still says
what happened to each robot, and the record is kept here, in memory, with the
time it happened, and written by a background thread as soon as the store takes
writes again — in the order the events happened, each exactly once.  Nothing in
the backlog is lost while the server runs; across a crash it is (the robots'
latches and the emulators' own logs still show the stop).
"""

from __future__ import annotations

import logging
import threading
from concurrent.futures import ThreadPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout
from dataclasses import dataclass

from server.diskspace import describe
from server.store import Store
from server.store.database import utcnow

log = logging.getLogger(__name__)

#: Far more E-stops than any outage could hold; past it the oldest are logged and dropped.
MAX_PENDING = 100_000


@dataclass(frozen=True)
class PendingAudit:
    ts: str
    actor: str
    entity: str
    entity_id: str
    action: str
    reason: str


class AuditBacklog:
    """``record()`` writes now or keeps the record; a thread retries every ``retry_s``."""

    def __init__(self, store: Store, retry_s: float = 1.0) -> None:
        self.store = store
        self.retry_s = retry_s
        self._pending: list[PendingAudit] = []
        self._lock = threading.Lock()  # the pending list
        self._write_lock = threading.Lock()  # one writer, so records keep their order
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        # Writes a caller does not wait for to the end (record(wait_s=...)).
        self._writer = ThreadPoolExecutor(1, thread_name_prefix="audit-write")

    def record(
        self,
        actor: str,
        entity: str,
        entity_id: str,
        action: str,
        reason: str,
        *,
        wait_s: float | None = None,
    ) -> str:
        """Write the record (after any older ones still pending) and say how it went:
        ``"recorded"``, or ``"failed: <why>; kept and written when the store accepts
        writes again"``.

        With ``wait_s``, the write runs on the backlog's writer thread and the
        caller waits at most that long: past it the answer is ``"queued: …"``
        and the record is written in order when the store takes it (an E-stop
        has already acted and must not wait for a busy database to say so)."""
        rec = PendingAudit(utcnow(), actor, entity, entity_id, action, reason)
        with self._lock:
            self._pending.append(rec)
            if len(self._pending) > MAX_PENDING:
                dropped = self._pending.pop(0)
                log.error("audit backlog full; dropped %s", dropped)
        if wait_s is None:
            return self._write_pending(rec)
        try:
            future = self._writer.submit(self._write_pending, rec)
        except RuntimeError:  # stopped: write from this thread
            return self._write_pending(rec)
        try:
            return future.result(timeout=wait_s)
        except FutureTimeout:
            return (
                f"queued: the store did not take the record within {wait_s * 1000:.0f} ms; "
                "it is written in order as soon as it does"
            )

    def _write_pending(self, rec: PendingAudit) -> str:
        try:
            self.flush()
        except Exception as exc:
            log.warning("audit record kept for later (%s): %s", describe(exc), rec)
            self._start()
            self._wake.set()
            return f"failed: {describe(exc)}; kept and written when the store accepts writes again"
        return "recorded"

    def pending(self) -> int:
        with self._lock:
            return len(self._pending)

    def flush(self) -> int:
        """Write every pending record, oldest first; raises at the first that fails."""
        written = 0
        with self._write_lock:
            while True:
                with self._lock:
                    if not self._pending:
                        return written
                    rec = self._pending[0]
                self.store.audit(
                    rec.actor, rec.entity, rec.entity_id, rec.action, rec.reason, ts=rec.ts
                )
                with self._lock:
                    self._pending.pop(0)
                written += 1

    def _start(self) -> None:
        with self._lock:
            if self._thread is not None or self._stop.is_set():
                return
            self._thread = threading.Thread(target=self._run, name="audit-backlog", daemon=True)
            self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            self._wake.wait(self.retry_s)
            self._wake.clear()
            with self._lock:  # decided under the lock that record() appends under
                if not self._pending:
                    self._thread = None
                    return
            try:
                n = self.flush()
                if n:
                    log.info("wrote %d audit record(s) kept while the store refused writes", n)
            except Exception as exc:
                log.debug("audit backlog still waiting: %s", describe(exc))

    def stop(self) -> None:
        """Try a last time to write what is pending, then stop the thread."""
        self._stop.set()
        self._wake.set()
        self._writer.shutdown(wait=True)
        try:
            self.flush()
        except Exception as exc:
            log.error("%d audit record(s) could not be written: %s", self.pending(), exc)
        thread = self._thread
        if thread is not None:
            thread.join(timeout=5)
