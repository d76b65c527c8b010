"""Events across servers sharing PostgreSQL: LISTEN/NOTIFY relays.

Two :class:`EventBus`\\ es, each with a :class:`PgEventRelay`, on two stores on
one real PostgreSQL (:mod:`tests.support.postgres`) stand for two servers;
then two whole apps: a console on server B sees the plan server A planned.
"""

from __future__ import annotations

import asyncio
import json
import statistics
import time
from pathlib import Path
from typing import Any

from server.events import Event, EventBus
from server.events_pg import MAX_PAYLOAD, PgEventRelay, encode
from server.store import Store
from tests.support.postgres import pg_url, postgres_server  # noqa: F401
from tests.support.waiting import wait_for


def test_encode_keeps_small_events_and_reduces_large_ones() -> None:
    small = {"id": "pl_1", "state": "planned", "progress": 1.0}
    assert json.loads(encode("srv_a", 1, "plan", small))["d"] == small
    big = {
        "id": "pl_2",
        "state": "planned",
        "n": 3,
        "ok": True,
        "none": None,
        "note": "x" * 300,  # a long string: left out
        "result": {"path": list(range(5000))},  # nested: left out
    }
    text = encode("srv_a", 2, "plan", big)
    assert len(text.encode()) <= MAX_PAYLOAD
    msg = json.loads(text)
    assert msg["o"] == "srv_a" and msg["n"] == 2 and msg["t"] == "plan"
    assert msg["d"] == {
        "id": "pl_2",
        "state": "planned",
        "n": 3,
        "ok": True,
        "none": None,
        "truncated": ["note", "result"],
    }
    # Scalars alone too big: only the identifying fields are kept.
    wide = {"id": "pl_3", "state": "x", **{f"k{i}": "y" * 200 for i in range(100)}}
    msg = json.loads(encode("srv_a", 3, "plan", wide))
    assert len(json.dumps(msg).encode()) <= MAX_PAYLOAD
    assert msg["d"]["id"] == "pl_3" and msg["d"]["state"] == "x"
    assert len(msg["d"]["truncated"]) == 100


def test_two_servers_buses_see_each_others_events_within_a_second(
    pg_url: str,  # noqa: F811
    tmp_path: Path,
) -> None:
    store_a = Store(tmp_path / "a", database_url=pg_url)
    store_b = Store(tmp_path / "b", database_url=pg_url)
    bus_a, bus_b = EventBus(), EventBus()
    relay_a = PgEventRelay(bus_a, pg_url).start()
    relay_b = PgEventRelay(bus_b, pg_url).start()
    heard_by_b_listeners: list[str] = []
    bus_b.add_listener(lambda t, d: heard_by_b_listeners.append(t))
    try:

        async def run() -> tuple[list[Event], list[Event], list[float]]:
            q_a, q_b = bus_a.subscribe(), bus_b.subscribe()
            lags: list[float] = []
            pids: list[str] = []
            for i in range(30):
                plan = store_a.create_plan("demo.route", {"i": i}, "alice")
                pids.append(plan.id)
                t0 = time.time()
                bus_a.publish("plan", {"id": plan.id, "kind": plan.kind, "state": plan.state})
                ev = await asyncio.wait_for(q_b.get(), 1.0)  # within 1 s, or it fails
                lags.append(time.time() - t0)
                assert ev.type == "plan" and ev.data["id"] == plan.id
                # B's store reads what A wrote: the event and the row agree.
                assert store_b.get_plan(ev.data["id"]).state == ev.data["state"]
            # The other way round, and a large event in its reduced form.
            bus_b.publish("robot", {"name": "ara", "report": {"q": list(range(4000))}})
            back = await asyncio.wait_for(q_a.get(), 2.0)  # A's own first 30, then this
            seen_a = [back]
            while back.type != "robot":
                back = await asyncio.wait_for(q_a.get(), 2.0)
                seen_a.append(back)
            await asyncio.sleep(0.3)  # anything echoed back would arrive by now
            rest_a = [q_a.get_nowait() for _ in range(q_a.qsize())]
            rest_b = [q_b.get_nowait() for _ in range(q_b.qsize())]
            return seen_a + rest_a, rest_b, lags

        on_a, extra_b, lags = asyncio.run(run())
    finally:
        relay_a.stop()
        relay_b.stop()
        store_a.close()
        store_b.close()
    # A saw its own 30 events once each (no echo), then B's robot event, reduced.
    assert [e.type for e in on_a] == ["plan"] * 30 + ["robot"]
    robot = on_a[-1].data
    assert robot == {"name": "ara", "truncated": ["report"]}
    # B got each of A's events once (above), and its own robot event once, in
    # full (published locally), not a second time back through PostgreSQL.
    assert [(e.type, len(e.data["report"]["q"])) for e in extra_b] == [("robot", 4000)]
    # Relayed events reach B's subscribers, not its listeners (webhooks run once, on A).
    assert heard_by_b_listeners == ["robot"]
    assert relay_a.received == 1 and relay_b.received == 30
    print(
        f"relay lag A→B over {len(lags)} events: median {statistics.median(lags) * 1000:.1f} ms,"
        f" max {max(lags) * 1000:.1f} ms"
    )
    assert max(lags) < 1.0


def test_a_console_on_server_b_sees_the_plan_server_a_planned(
    pg_url: str,  # noqa: F811  (first: its database is dropped after the apps stop)
    make_api: Any,
    tmp_path: Path,
) -> None:
    """Two apps on one PostgreSQL: B's event stream (what a console reads) carries
    the ``planned`` event of a plan A's job runner planned, within 1 s of A's."""
    a = make_api(data=tmp_path / "a", database_url=pg_url)
    b = make_api(data=tmp_path / "b", database_url=pg_url)
    pid = a.submit("demo.route")["id"]
    assert a.wait(pid)["state"] == "planned"

    def planned_event(bus: EventBus) -> Event | None:
        return next(
            (
                e
                for e in bus.recent(500)
                if e.type == "plan" and e.data.get("id") == pid and e.data.get("state") == "planned"
            ),
            None,
        )

    on_a = planned_event(a.services.events)
    assert on_a is not None
    on_b = wait_for(lambda: planned_event(b.services.events), timeout=5, what="the event on B")
    assert on_b.ts - on_a.ts < 1.0, on_b.ts - on_a.ts
    # …and it is in B's SSE stream (the backlog a console gets on connecting).
    r = b.get("/api/v1/events?once=true", "viewer")
    assert r.status_code == 200
    assert f'"id": "{pid}"' in r.text and '"state": "planned"' in r.text
    # B reads the plan A planned from the shared store.
    assert b.get(f"/api/v1/plans/{pid}", "viewer").json()["state"] == "planned"


def test_the_relay_survives_its_connections_being_cut(
    pg_url: str,  # noqa: F811
) -> None:
    """PostgreSQL ends every relay connection (as a restart or fail-over does):
    B listens again by itself, and A's next event — sent on a connection found
    dead only by that send — is retried on a new one and reaches B; none dropped."""
    import psycopg

    bus_a, bus_b = EventBus(), EventBus()
    relay_a = PgEventRelay(bus_a, pg_url).start()
    relay_b = PgEventRelay(bus_b, pg_url).start()
    seen: list[str] = []
    try:

        def heard(n: int) -> bool:
            got = [e.data.get("i") for e in bus_b.recent(100) if e.type == "probe"]
            seen[:] = [str(i) for i in got]
            return len(got) >= n

        bus_a.publish("probe", {"i": 0})
        wait_for(lambda: heard(1), 5, "the first event on B")
        with psycopg.connect(pg_url, autocommit=True) as admin:
            cut = admin.execute(
                "SELECT count(pg_terminate_backend(pid)) FROM pg_stat_activity "
                "WHERE application_name LIKE 'steelpath-events-%'"
            ).fetchone()
        # A's send connection and both listens (B has sent nothing: it has none).
        assert cut is not None and cut[0] == 3, cut
        wait_for(lambda: relay_b.reconnects >= 1 and relay_b.listening.is_set(), 10, "B again")
        bus_a.publish("probe", {"i": 1})
        wait_for(lambda: heard(2), 5, "the event after the cut on B")
        assert seen == ["0", "1"]
        assert relay_a.dropped == 0 and relay_a.sent == 2
        assert relay_a.listen_losses == 1 and relay_b.listen_losses == 1
    finally:
        relay_a.stop()
        relay_b.stop()
