"""Robot leases: the store's conditional upsert and the keeper's
adopt / drop / fence decisions, on a real store (SQLite, and PostgreSQL from
Debian's package when installed) with a recording engine in place of the link
service's (no robots, no link processes)."""

from __future__ import annotations

import threading
import time
from typing import Any

import pytest

from server.ownership.keeper import MIN_LEASE_S, LeaseKeeper, check_lease
from server.store import Store
from server.store.ownership import OwnershipStore
from tests.support.postgres import pg_url, postgres_server  # noqa: F401

ROBOTS = ["ara", "cmbot"]
LEASE = MIN_LEASE_S  # 2.5 s: the shortest allowed


class FakeEngine:
    """Records what the keeper asks of the dispatch engine."""

    def __init__(self, store: Store) -> None:
        self.store = store
        self.owned: dict[str, str] = {}
        self.log: list[tuple[str, str, float]] = []
        self.estops: list[tuple[str, str]] = []
        self._lock = threading.Lock()

    def owns(self, name: str) -> bool:
        return name in self.owned

    def adopt(self, name: str, url: str, emulated: dict[str, str] | None = None) -> bool:
        with self._lock:
            self.owned[name] = url
            self.log.append(("adopt", name, time.monotonic()))
        return True

    def drop(self, name: str, why: str) -> bool:
        with self._lock:
            self.owned.pop(name, None)
            self.log.append(("drop", name, time.monotonic()))
        return True

    def sync_url(self, name: str, url: str) -> None:
        self.owned[name] = url

    def estop(self, robot: str | None, reason: str) -> list[str]:
        with self._lock:
            self.log.append(("estop", str(robot), time.monotonic()))
            self.estops.append((str(robot), reason))
        return [str(robot)]

    def set_store_emulated(self, urls: dict[str, str]) -> None:
        pass


def keeper(store: Store, server_id: str) -> tuple[LeaseKeeper, FakeEngine]:
    eng = FakeEngine(store)
    k = LeaseKeeper(
        eng,
        store.db,
        server_id=server_id,
        url=f"http://{server_id}",
        lease_s=LEASE,
        robots=ROBOTS,
        emulator_urls={"ara": "socket://127.0.0.1:1"},
    )
    return k, eng


@pytest.fixture(params=["sqlite", pytest.param("postgresql", marks=pytest.mark.integration)])
def store(request: pytest.FixtureRequest, tmp_path) -> Any:
    """The same SQL on both stores (the PostgreSQL one is a real server on loopback)."""
    url = request.getfixturevalue("pg_url") if request.param == "postgresql" else None
    s = Store(tmp_path / "var", database_url=url)
    yield s
    s.close()


def test_a_lease_is_taken_only_if_absent_expired_or_already_mine(store) -> None:
    own = OwnershipStore(store.db)
    now = 1000.0
    got = own.claim("a", "http://a", ["ara"], 3.0, now)
    assert got["ara"].server_id == "a" and got["ara"].expires_at == 1003.0
    taken_at = got["ara"].taken_at
    # Another server, before it lapses: refused (the row stays a's).
    assert own.claim("b", "http://b", ["ara"], 3.0, now + 2.9)["ara"].server_id == "a"
    # The holder renews: expiry moves, taken_at stays.
    got = own.claim("a", "http://a", ["ara"], 3.0, now + 2.0)["ara"]
    assert (got.server_id, got.expires_at, got.taken_at) == ("a", 1005.0, taken_at)
    # Lapsed: the other server takes it.
    got = own.claim("b", "http://b", ["ara"], 3.0, now + 5.1)["ara"]
    assert got.server_id == "b" and got.url == "http://b"
    # Release touches only one's own rows.
    own.release("a", ["ara"])
    assert own.leases()["ara"].server_id == "b"
    own.unregister("b")
    assert own.leases() == {} and [s.id for s in own.servers()] == ["a"]


def test_emulator_urls_never_overwrite_an_operators_url(store) -> None:
    own = OwnershipStore(store.db)
    store.set_robot_url("cmbot", "socket://10.0.0.7:5000", "admin")
    own.record_emulator_urls({"ara": "socket://127.0.0.1:1", "cmbot": "socket://127.0.0.1:2"}, "a")
    own.record_emulator_urls({"ara": "socket://127.0.0.1:3"}, "b")
    assert store.robot_urls() == {"ara": "socket://127.0.0.1:3", "cmbot": "socket://10.0.0.7:5000"}
    assert own.emulator_urls() == {"ara": "socket://127.0.0.1:3"}


def test_too_short_a_lease_is_refused() -> None:
    with pytest.raises(ValueError, match="watchdog"):
        check_lease(1.0)
    check_lease(3.0)


def test_one_owner_then_takeover_only_after_the_lease_lapses(store) -> None:
    a, eng_a = keeper(store, "a")
    b, eng_b = keeper(store, "b")
    a.start()
    b.start()
    try:
        assert set(eng_a.owned) == set(ROBOTS) and eng_b.owned == {}
        assert eng_a.owned["ara"] == "socket://127.0.0.1:1"  # its own emulator
        assert eng_a.owned["cmbot"] == "loop://"  # nothing configured
        time.sleep(1.5)  # a few renewals: nothing moves
        assert set(eng_a.owned) == set(ROBOTS) and eng_b.owned == {}
        # a stops without releasing (as when killed): b waits for the lapse.
        a.stop()
        stopped = time.monotonic()
        deadline = stopped + LEASE + 3
        while set(eng_b.owned) != set(ROBOTS) and time.monotonic() < deadline:
            time.sleep(0.02)
        assert set(eng_b.owned) == set(ROBOTS)
        first = min(t for op, _, t in eng_b.log if op == "adopt")
        # a's last renewal was at most one interval before it stopped.
        assert first - stopped >= LEASE - LEASE / 3 - 0.05, first - stopped
    finally:
        a.stop()
        b.stop()


def test_an_estop_that_reached_nobody_is_latched_by_the_robots_next_driver(store) -> None:
    """An E-stop pressed while ara's owner is dead and its lease not lapsed is held
    in the store; the server that takes ara over latches it right after adopting
    it (same tick), and only ara's: a held E-stop of a robot nobody drives stays."""
    own = OwnershipStore(store.db)
    own.claim("dead", "http://dead", ["ara"], LEASE, time.time())  # a killed owner
    own.hold_estops(["ara", "ghost"], "op", "operator E-stop")
    assert set(own.held_estops()) == {"ara", "ghost"}
    b, eng = keeper(store, "b")
    b.start()
    try:
        deadline = time.monotonic() + LEASE + 3
        # The latch comes right after the adoption in the same tick: wait for
        # both (polling between the two saw ara owned and nothing latched yet).
        while not ("ara" in eng.owned and eng.estops) and time.monotonic() < deadline:
            time.sleep(0.02)
        assert "ara" in eng.owned
        assert eng.estops == [("ara", eng.estops[0][1])] and "operator E-stop" in eng.estops[0][1]
        ops = [(op, name) for op, name, _ in eng.log if name == "ara"]
        assert ops == [("adopt", "ara"), ("estop", "ara")], ops
        assert set(own.held_estops()) == {"ghost"}
        time.sleep(LEASE / 3 + 0.2)  # later ticks latch nothing again
        assert len(eng.estops) == 1
        assert [e.action for e in store.list_audit("robot", "ara")] == ["estop"]
    finally:
        b.stop()


def test_a_clean_release_hands_over_at_the_next_tick(store) -> None:
    a, _ = keeper(store, "a")
    b, eng_b = keeper(store, "b")
    a.start()
    b.start()
    try:
        a.stop()
        a.release()
        released = time.monotonic()
        while set(eng_b.owned) != set(ROBOTS) and time.monotonic() < released + 5:
            time.sleep(0.02)
        assert time.monotonic() - released < LEASE / 3 + 0.5
    finally:
        b.stop()


def test_a_renewal_in_flight_at_shutdown_does_not_outlive_the_release(store) -> None:
    """The CI failure of stop 31: a renewal still inside a slow store when the
    service stopped committed after the release, so the leases came back with
    a fresh heartbeat and a restarted server did not take its robots (nor
    interrupt the run left on them) for a whole lease."""
    a, eng_a = keeper(store, "a")
    real_claim = a.store.claim
    inside, gate = threading.Event(), threading.Event()

    def slow_claim(*args: Any, **kwargs: Any) -> Any:
        if a._ticks >= 1:  # the loop's renewals, not the first claim
            inside.set()
            gate.wait(10)
        return real_claim(*args, **kwargs)

    a.store.claim = slow_claim  # type: ignore[method-assign]
    a.start()
    assert set(eng_a.owned) == set(ROBOTS)
    assert inside.wait(LEASE), "no renewal started"
    a.stop()  # its join gives up on the stuck renewal, as on a loaded machine
    releaser = threading.Thread(target=a.release)
    releaser.start()
    time.sleep(0.3)
    gate.set()  # the store answers: the renewal commits, then the release runs
    releaser.join(10)
    for t in [releaser, *a._threads]:  # the renewal has ended, committed or not
        t.join(10)
        assert not t.is_alive()
    own = OwnershipStore(store.db)
    assert own.leases() == {} and own.servers() == []
    # A server starting now takes every robot in its first claim.
    b, eng_b = keeper(store, "b")
    b.start()
    try:
        assert set(eng_b.owned) == set(ROBOTS)
    finally:
        b.stop()


def test_a_server_that_cannot_renew_drops_its_robots_before_the_lease_lapses(store) -> None:
    a, eng_a = keeper(store, "a")
    b, _ = keeper(store, "b")
    a.start()
    b.start()  # a live peer that could take the robots over
    try:
        time.sleep(LEASE / 3 + 0.2)  # a has seen b

        def broken(*_a: Any, **_k: Any) -> Any:
            raise RuntimeError("the store is unreachable")

        a.store.claim = broken  # type: ignore[method-assign]
        time.sleep(0.1)  # a renewal in flight has committed
        expiry = min(lease.expires_at for lease in OwnershipStore(store.db).leases().values())
        assert eng_a.owned, "dropped at once"
        deadline = time.monotonic() + LEASE + 1
        while eng_a.owned and time.monotonic() < deadline:
            time.sleep(0.01)
        assert eng_a.owned == {}
        assert time.time() < expiry, "dropped only after another server could have taken over"
    finally:
        a.stop()
        b.stop()


def test_alone_a_slow_store_never_stops_the_robots(store) -> None:
    a, eng_a = keeper(store, "a")
    a.start()
    try:

        def broken(*_a: Any, **_k: Any) -> Any:
            raise RuntimeError("the store is unreachable")

        a.store.claim = broken  # type: ignore[method-assign]
        time.sleep(LEASE + 0.5)
        assert set(eng_a.owned) == set(ROBOTS)
    finally:
        a.stop()
