"""Safety records a refusing store could not take: kept, then written in order, each once."""

from __future__ import annotations

import errno
import threading
from typing import Any

from server.audit_backlog import AuditBacklog
from tests.support.waiting import wait_for


class RefusingStore:
    """Refuses writes (a full disk) while ``full`` is set; records what it took."""

    def __init__(self) -> None:
        self.full = threading.Event()
        self.rows: list[tuple[Any, ...]] = []

    def audit(self, actor: str, entity: str, entity_id: str, action: str, reason: str = "",
              *, ts: str | None = None) -> None:  # fmt: skip
        if self.full.is_set():
            raise OSError(errno.ENOSPC, "No space left on device")
        self.rows.append((ts, actor, entity, entity_id, action, reason))


def test_records_kept_while_refused_are_written_in_order_once_with_their_time() -> None:
    store = RefusingStore()
    backlog = AuditBacklog(store, retry_s=0.05)  # type: ignore[arg-type]
    assert backlog.record("op", "robot", "all", "estop", "first") == "recorded"
    store.full.set()
    said = backlog.record("op", "robot", "all", "estop", "second")
    assert said.startswith("failed: disk full"), said
    backlog.record("op", "robot", "ara", "estop", "third")
    assert backlog.pending() == 2 and len(store.rows) == 1
    store.full.clear()
    wait_for(lambda: backlog.pending() == 0, 5, "the backlog written")
    assert [r[5] for r in store.rows] == ["first", "second", "third"]
    times = [r[0] for r in store.rows]
    assert all(times) and times == sorted(times)  # kept with when it happened
    backlog.stop()


def test_a_record_after_the_refusal_waits_behind_the_older_ones() -> None:
    store = RefusingStore()
    backlog = AuditBacklog(store, retry_s=3600)  # type: ignore[arg-type]  # no retry thread help
    store.full.set()
    backlog.record("op", "robot", "all", "estop", "old")
    store.full.clear()
    assert backlog.record("op", "robot", "all", "estop", "new") == "recorded"
    assert [r[5] for r in store.rows] == ["old", "new"]
    backlog.stop()


class HeldStore(RefusingStore):
    """Holds every write until ``gate`` is set (a database busy with another writer)."""

    def __init__(self) -> None:
        super().__init__()
        self.gate = threading.Event()

    def audit(self, *args: Any, **kwargs: Any) -> None:
        self.gate.wait(10)
        super().audit(*args, **kwargs)


def test_a_bounded_wait_answers_queued_and_the_record_follows_once() -> None:
    """A caller that waits at most ``wait_s`` (the E-stop) is told "queued" while
    the store holds the write; the record is written once, and before a later one."""
    store = HeldStore()
    backlog = AuditBacklog(store, retry_s=0.05)  # type: ignore[arg-type]
    said = backlog.record("op", "robot", "all", "estop", "busy store", wait_s=0.02)
    assert said.startswith("queued: the store did not take the record within 20 ms"), said
    assert backlog.pending() == 1
    store.gate.set()
    wait_for(lambda: backlog.pending() == 0, 10, "the queued record written")
    assert backlog.record("op", "robot", "all", "estop", "after", wait_s=5.0) == "recorded"
    reasons = [row[5] for row in store.rows]
    assert reasons == ["busy store", "after"], store.rows
    backlog.stop()
