"""The dispatch engine inside the link service: nothing that blocks runs on a
link's I/O thread (the one that sends heartbeats and reads state reports)."""

from __future__ import annotations

import threading
import time
from typing import Any

from robots.emulator.server import Emulator
from server.dispatch import DispatchEngine
from server.settings import Settings
from server.store import Store


class _Sink:
    def __init__(self) -> None:
        self.events: list[tuple[str, dict[str, Any]]] = []
        self._lock = threading.Lock()

    def publish(self, type_: str, data: dict[str, Any]) -> None:
        with self._lock:
            self.events.append((type_, data))


def _engine(store: Store, data: Any, emu: Emulator) -> DispatchEngine:
    """An engine driving ``ara`` at ``emu`` (with its secret), no embedded emulators."""
    return DispatchEngine(
        store,
        _Sink(),
        Settings(data=data, emulators=False, scene_port=0),
        emulator_urls={"ara": emu.url},
        secret_for=lambda name: emu.secret if name == "ara" else None,
    )


def test_a_stuck_store_write_does_not_stall_the_link(tmp_path) -> None:
    """A state-mirror write that hangs in SQLite (another process holding the
    database, a slow disk) must not stop heartbeats or state reports: with
    the write on the I/O thread the host declared the link lost after 1 s."""
    data = tmp_path / "var"
    store = Store(data)
    gate, entered = threading.Event(), threading.Event()
    real_save = store.save_robot_state

    def stuck_save(name: str, state: dict[str, Any]) -> None:
        entered.set()
        gate.wait(30)
        real_save(name, state)

    store.save_robot_state = stuck_save  # type: ignore[method-assign]
    with Emulator("ara", time_scale=1.0) as emu:
        engine = _engine(store, data, emu)
        engine.start()
        try:
            assert engine.wait_connected("ara", 20)
            assert entered.wait(10), "the mirror never tried to store a report"
            before = engine.robot_status("ara")["stats"]
            time.sleep(2.5)  # more than twice the host's 1 s link timeout
            during = engine.robot_status("ara")
            assert during["connected"], during["state"]
            assert during["stats"].get("links_lost", 0) == before.get("links_lost", 0)
            # Reports kept arriving on the I/O thread while the write hung.
            assert during["stats"]["frames_rx"] > before["frames_rx"] + 10
        finally:
            gate.set()
            engine.shutdown()
    store.close()


def test_a_stale_url_from_the_lease_keeper_does_not_undo_an_operators_reconnect(
    tmp_path,
) -> None:
    """A fresh-clone run of this suite: the keeper read the robots' URLs, an operator's PUT
    /connection then moved cmbot to a new robot, and the keeper's
    ``sync_url`` with the URL it had read put the link back on the old one
    for a tick, closing the link the PUT had made; a wait for the robot on
    that link never ended well.  The stale URL is ignored now, and a wait
    follows a link that is replaced while it waits."""
    data = tmp_path / "var"
    store = Store(data)
    with Emulator("ara", time_scale=1.0) as old, Emulator("ara", secret=old.secret) as new:
        engine = _engine(store, data, old)
        engine.start()
        try:
            assert engine.wait_connected("ara", 20)
            engine.set_connection("ara", new.url, "admin")
            link = engine._robots["ara"].link
            engine.sync_url("ara", old.url)  # what the keeper had read before the PUT
            assert engine._robots["ara"].url == new.url
            assert engine._robots["ara"].link is link
            assert engine.wait_connected("ara", 20)
            # A wait begun on a dead URL ends when the robot is reconnected.
            engine.set_connection("ara", "socket://127.0.0.1:9", "admin")
            got: list[bool] = []
            waiter = threading.Thread(target=lambda: got.append(engine.wait_connected("ara", 20)))
            waiter.start()
            time.sleep(0.5)
            engine.set_connection("ara", new.url, "admin")
            waiter.join(25)
            assert got == [True]
        finally:
            engine.shutdown()
    store.close()
