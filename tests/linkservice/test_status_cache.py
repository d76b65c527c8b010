"""GET /robots load cannot reach the link service unbounded: statuses are shared for 0.1 s."""

from __future__ import annotations

from typing import Any

from server.linkservice.client import LinkServiceClient


class Sink:
    def __init__(self) -> None:
        self.published: list[str] = []

    def publish(self, type_: str, data: dict[str, Any]) -> None:
        self.published.append(type_)


class Counting(LinkServiceClient):
    def __init__(self) -> None:
        super().__init__(store=None, events=Sink(), settings=None)  # type: ignore[arg-type]
        self.calls: list[str] = []

    def _roundtrip(self, op: str, args: dict[str, Any], timeout: float) -> Any:
        self.calls.append(op)
        return [{"name": "ara", "state": "ready", "n": len(self.calls)}]


def test_pollers_share_one_round_trip_and_changes_refresh_it() -> None:
    c = Counting()
    c.STATUS_TTL_S = 60.0  # type: ignore[misc]
    first = [c.robot_statuses() for _ in range(20)]
    assert c.calls == ["robot_statuses"]
    assert all(f == first[0] for f in first)
    first[0][0]["state"] = "mutated by a caller"
    assert c.robot_statuses()[0]["state"] == "ready"  # callers get copies
    c._on_event("execution", {"id": "ex_1"})  # pushed change
    assert c.robot_statuses()[0]["n"] == 2
    c._call("clear_estop", {"name": "ara"})  # an operator action
    assert c.robot_statuses()[0]["n"] == 4
    assert c.calls == ["robot_statuses", "robot_statuses", "clear_estop", "robot_statuses"]


def test_the_answer_expires_after_the_ttl() -> None:
    c = Counting()
    c.STATUS_TTL_S = 0.0  # type: ignore[misc]
    c.robot_statuses()
    c.robot_statuses()
    assert c.calls == ["robot_statuses", "robot_statuses"]


def test_reports_and_progress_keep_the_answer_state_changes_drop_it() -> None:
    c = Counting()
    c.STATUS_TTL_S = 60.0  # type: ignore[misc]
    c._on_event("execution", {"id": "ex_1", "state": "executing", "acked": 0})
    c.robot_statuses()
    for k in range(1, 30):  # acks while it streams, and the robot's reports
        c._on_event("execution", {"id": "ex_1", "state": "executing", "acked": k})
        c._on_event("robot", {"name": "ara", "report": {"last_done": k}})
    assert c._status_cache is not None
    assert c.calls == ["robot_statuses"]
    c._on_event("execution", {"id": "ex_1", "state": "completed", "acked": 30})
    assert c._status_cache is None  # an execution's state changed
    c.robot_statuses()
    c._on_event("robot", {"name": "ara", "estop_latched": False})
    assert c._status_cache is None  # an E-stop / link change
    c.robot_statuses()
    c._on_event("execution", {"id": "ex_2", "state": "executing", "acked": 0})
    assert c._status_cache is None  # a new execution
    assert c.calls == ["robot_statuses"] * 3


def test_recent_statuses_answer_at_once_and_refresh_once_in_the_background() -> None:
    import threading
    import time

    gate = threading.Event()

    class Slow(Counting):
        def _roundtrip(self, op: str, args: dict[str, Any], timeout: float) -> Any:
            if self.calls:  # the first fills the cache; later ones wait for the gate
                gate.wait(10)
            return super()._roundtrip(op, args, timeout)

    c = Slow()
    c.STATUS_TTL_S = 0.0  # type: ignore[misc]
    c.STATUS_STALE_OK_S = 60.0  # type: ignore[misc]
    assert c.recent_statuses() is None  # nothing yet: the route does the round trip
    c.robot_statuses()
    answers = [c.recent_statuses() for _ in range(20)]  # expired, but recent
    assert all(a == [{"name": "ara", "state": "ready", "n": 1}] for a in answers)
    gate.set()
    deadline = time.monotonic() + 10
    while (len(c.calls) < 2 or c._refreshing) and time.monotonic() < deadline:
        time.sleep(0.01)
    assert c.calls == ["robot_statuses"] * 2  # one background refresh for 20 polls
    assert c.recent_statuses() == [{"name": "ara", "state": "ready", "n": 2}]
    c._on_event("robot", {"name": "ara", "estop_latched": True})
    assert c.recent_statuses() is None  # an E-stop change is never shown late
    c.STATUS_STALE_OK_S = 0.0  # type: ignore[misc]
    c.robot_statuses()
    assert c.recent_statuses() is None  # too old to show
