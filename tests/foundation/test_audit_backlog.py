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
