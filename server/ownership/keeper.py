"""The lease keeper: inside the robot-link service, it decides which robots this
server drives.

It lives in the link service, not the web server, because that is the process
that drives the robots: if it cannot renew its leases, it is the one that must
let go of the robots.  Every ``lease_s / 3`` it heartbeats this server's row
and takes or renews each robot's lease in one transaction
(:meth:`server.store.ownership.OwnershipStore.claim`), then makes the engine
drive exactly the robots whose lease it holds:

- a lease it holds and the engine does not drive → :meth:`DispatchEngine.adopt`
  (what the store shows running on that robot is interrupted first);
- a lease another server holds and the engine drives → :meth:`DispatchEngine.drop`
  (the link closes, the robot stops, the streamer is detached).

**Fencing.**  When other servers are alive and this one has not renewed for
``lease_s - interval/2`` (a stuck store, a stalled process), it drops every
robot before the lease can lapse and another server take one over.  Alone
(the embedded single-server set-up), nobody can take a robot over, so a slow
store never stops a robot: behaviour stays as it was before leases.

**Timing.**  ``lease_s`` must exceed the longest watchdog a robot accepts
(:data:`MAX_ROBOT_WATCHDOG_S`, docs/protocol.md §6) plus a margin: when an
owner dies without releasing, its leases lapse only after every robot it drove
has stopped on its own watchdog (a TCP robot stops at once on the closed
connection; a serial one within its watchdog), so a new owner never finds a
robot still moving under a dead server's last command.  The robot's
one-controller rule (docs/protocol.md §12.6) is the last guard: a robot
refuses a second controller while the first is heard from, so even a lease
bug cannot make two servers drive one robot.

A clean shutdown releases the leases after the links have closed, so another
server takes the robots over at its next tick; a killed server's leases lapse.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Iterable, Mapping
from typing import Any

from server.store.ownership import LeaseRow, OwnershipStore, ServerRow

log = logging.getLogger(__name__)

#: The longest watchdog a robot honours (the protocol clamps ``watchdog_ms`` to
#: 100…2000 ms; the emulator's ``max_watchdog_s``).
MAX_ROBOT_WATCHDOG_S = 2.0
#: How much longer than that a lease lasts at least: the robot's watchdog check
#: runs on its own loop, and a new owner's handshake takes time of its own.
TAKEOVER_MARGIN_S = 0.5
MIN_LEASE_S = MAX_ROBOT_WATCHDOG_S + TAKEOVER_MARGIN_S


def check_lease(lease_s: float) -> None:
    """Refuse a lease too short for a dead owner's robots to have stopped when it lapses."""
    if lease_s < MIN_LEASE_S:
        raise ValueError(
            f"robot_lease_s={lease_s:g} s is shorter than a robot's longest watchdog "
            f"({MAX_ROBOT_WATCHDOG_S:g} s) plus {TAKEOVER_MARGIN_S:g} s: a server could take a "
            f"robot over before it has stopped; use at least {MIN_LEASE_S:g} s"
        )


class LeaseKeeper:
    """Takes, renews and releases this server's robot leases; adopts and drops links."""

    def __init__(
        self,
        engine: Any,
        db: Any,
        *,
        server_id: str,
        url: str,
        lease_s: float,
        robots: Iterable[str],
        emulator_urls: Mapping[str, str] | None = None,
    ) -> None:
        check_lease(lease_s)
        self.engine = engine
        self.store = OwnershipStore(db)
        self.robot_urls = engine.store.robot_urls
        self.server_id = server_id
        self.url = url
        self.lease_s = lease_s
        self.interval = lease_s / 3.0
        self.robots = list(robots)
        self.emulator_urls = dict(emulator_urls or {})
        self._stop = threading.Event()
        self._lock = threading.Lock()  # one adopt/drop pass at a time (loop vs fence)
        # One claim or release at a time: a renewal still in flight when the
        # service stops (its thread outlives ``stop``'s join on a slow store)
        # must not commit after the release and hand the leases back to a
        # server that is gone, with a fresh heartbeat that keeps a restarted
        # server from taking its robots for a whole lease.
        self._claim_lock = threading.Lock()
        self._released = False
        self._last_ok: float | None = None  # monotonic start of the last renewal that committed
        self._peers_seen = False
        self._fenced = False
        self._ticks = 0
        self.servers: list[ServerRow] = []
        self._threads: list[threading.Thread] = []

    # -------------------------------------------------------------- lifecycle
    def start(self) -> LeaseKeeper:
        """Take the leases once before the service reports ready (so a lone server
        drives its robots from its first answer, as before), then keep them."""
        self._first_claim()
        for target, name in ((self._loop, "lease keeper"), (self._fence_loop, "lease fence")):
            t = threading.Thread(target=target, name=name, daemon=True)
            t.start()
            self._threads.append(t)
        return self

    def stop(self) -> None:
        self._stop.set()
        for t in self._threads:
            t.join(timeout=1.0)

    def release(self, wait_s: float = 5.0) -> None:
        """A clean shutdown, after the links closed: the leases go now, not in ``lease_s``.

        Waits up to ``wait_s`` for a renewal in flight to end, and no renewal
        starts after it."""
        if not self._claim_lock.acquire(timeout=wait_s):
            log.error(
                "a lease renewal is still running after %.1f s: the robot leases "
                "are not released (they lapse in %.1f s)",
                wait_s,
                self.lease_s,
            )
            return
        try:
            self._released = True
            self.store.unregister(self.server_id)
        except Exception:
            log.exception("could not release the robot leases (they lapse in %.1f s)", self.lease_s)
        finally:
            self._claim_lock.release()

    # ----------------------------------------------------------------- claims
    def _first_claim(self) -> None:
        """Claim; while a lease is held by a server that stopped heartbeating (killed,
        e.g. this server before a restart), wait for it to lapse (≤ ``lease_s``)."""
        deadline = time.monotonic() + self.lease_s + 0.5
        while not self._stop.is_set():
            leases = self._tick()
            if leases is None:
                return
            now = time.time()
            beats = {s.id: s.heartbeat_at for s in self.servers}
            stale = [
                lease.expires_at
                for name, lease in leases.items()
                if name in self.robots
                and lease.server_id != self.server_id
                and now - beats.get(lease.server_id, 0.0) > 1.5 * self.interval
            ]
            left = deadline - time.monotonic()
            if not stale or left <= 0:
                return
            log.info("waiting up to %.1f s for the leases of a stopped server to lapse", left)
            time.sleep(min(max(max(stale) - now + 0.05, 0.05), left))

    def _tick(self) -> dict[str, LeaseRow] | None:
        with self._claim_lock:
            if self._released:
                return None
            return self._claim_and_apply()

    def _claim_and_apply(self) -> dict[str, LeaseRow] | None:
        started = time.monotonic()
        try:
            leases = self.store.claim(
                self.server_id, self.url, self.robots, self.lease_s, time.time()
            )
            self.servers = self.store.servers()
            stored = dict(self.robot_urls())
            emulated = self.store.emulator_urls()
            self._ticks += 1
            if self._ticks % 20 == 0:
                self.store.forget_dead_servers(time.time() - 10 * self.lease_s)
        except Exception:
            log.exception("could not renew the robot leases")
            return None
        now = time.time()
        self._peers_seen = any(
            s.id != self.server_id and now - s.heartbeat_at < 2 * self.lease_s for s in self.servers
        )
        with self._lock:
            self._last_ok = started
            self._fenced = False
            if self._stop.is_set():
                return leases  # stopping: the engine is shutting its links, adopt nothing
            self._apply(leases, stored, emulated)
            self._latch_held_estops()
        return leases

    def _latch_held_estops(self) -> None:
        """Latch every E-stop that reached no server for a robot this server now
        drives (pressed while its dead owner's lease was lapsing): the robot
        stopped on its watchdog then, and stays stopped until an operator clears it."""
        owned = [name for name in self.robots if self.engine.owns(name)]
        try:
            held = self.store.take_estops(owned)
        except Exception:
            log.exception("could not read the E-stops held for this server's robots")
            return
        for name, e in held.items():
            why = f"{e['reason']} (held since {e['at']}: no server reached the robot then)"
            log.warning("latching the E-stop of %s by %s: %s", name, e["actor"], why)
            try:
                self.engine.estop(name, why)
                self.engine.store.audit(e["actor"], "robot", name, "estop", why)
            except Exception:
                log.exception("could not latch the held E-stop of %s", name)

    def _apply(
        self, leases: Mapping[str, LeaseRow], stored: Mapping[str, str], emulated: dict[str, str]
    ) -> None:
        self.engine.set_store_emulated(emulated)
        for name in self.robots:
            lease = leases.get(name)
            try:
                if lease is not None and lease.server_id == self.server_id:
                    url = stored.get(name) or self.emulator_urls.get(name) or "loop://"
                    if self.engine.owns(name):
                        self.engine.sync_url(name, url)
                    else:
                        self.engine.adopt(name, url, emulated)
                elif self.engine.owns(name):
                    holder = lease.server_id if lease is not None else "no server"
                    self.engine.drop(name, f"its lease is held by {holder} now")
            except Exception:
                log.exception("could not adopt or drop robot %s", name)

    def _loop(self) -> None:
        while not self._stop.wait(self.interval):
            self._tick()

    def _fence_loop(self) -> None:
        """Drop every robot before an unrenewed lease can lapse (only with live peers)."""
        margin = self.interval / 2
        while not self._stop.wait(0.05):
            last = self._last_ok
            if last is None or self._fenced or not self._peers_seen:
                continue
            if time.monotonic() - last < self.lease_s - margin:
                continue
            with self._lock:
                if self._last_ok != last:
                    continue  # renewed meanwhile
                self._fenced = True
                for name in self.robots:
                    if self.engine.owns(name):
                        self.engine.drop(
                            name,
                            f"the lease could not be renewed for {self.lease_s - margin:.1f} s "
                            "(the store is unreachable or this server stalled)",
                        )
