"""Events across servers that share a PostgreSQL store: LISTEN/NOTIFY.

Each server's :class:`~server.events.EventBus` is in-process.  With PostgreSQL
as the store, a :class:`PgEventRelay` on every server makes each ``publish``
reach every other server's bus: a bus listener queues the event, a sender
thread ``NOTIFY``\\ s it on :data:`CHANNEL`, and a listener thread on a
dedicated connection (``LISTEN``) republishes what other servers sent with
``remote=True``, so it reaches the SSE streams there but not the listeners
(webhooks and the like run once, where the event was published; and the
relay does not send it back out).  A console on server B so sees the plan
events of server A's jobs, typically within milliseconds.

The payload is JSON ``{"o": origin server id, "n": sequence, "t": type, "d":
data}``: the origin id lets a server skip its own notifications, the
sequence keeps PostgreSQL from folding two identical events sent in one
transaction into one.  PostgreSQL refuses payloads of 8000 bytes or more;
a larger event is sent reduced (:func:`encode`): only its top-level scalar
fields (ids, states, names, numbers, strings up to 256 characters), plus
``"truncated": [the keys left out]``, so a receiver knows to fetch the full
record (``GET /plans/{id}``…) if it needs more.

Delivery is best effort, like the local bus's bounded queues: a send on a
connection the database closed is retried once on a new one; while the
database stays unreachable the relay reconnects every second, and events
published meanwhile on one server are not seen on the others (the stored
state is, on the next read); ``dropped`` counts them.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import logging
import queue
import secrets
import threading
from typing import Any

import psycopg
from psycopg import sql

from server.events import EventBus

log = logging.getLogger(__name__)

CHANNEL = "steelpath_events"

#: Largest NOTIFY payload PostgreSQL takes is 7999 bytes (``< 8000``).
MAX_PAYLOAD = 7999

#: Strings longer than this are left out of a reduced event.
_SHORT = 256

#: Fields kept by the last-resort reduction (an event whose scalars alone are too big).
_KEY_FIELDS = ("id", "plan_id", "execution_id", "name", "robot", "kind", "state")


def encode(origin: str, seq: int, type_: str, data: dict[str, Any]) -> str:
    """The NOTIFY payload for one event; reduced to fit :data:`MAX_PAYLOAD` if needed."""

    def dump(d: dict[str, Any]) -> str:
        msg = {"o": origin, "n": seq, "t": type_, "d": d}
        return json.dumps(msg, separators=(",", ":"), default=str, allow_nan=True)

    text = dump(data)
    if len(text.encode()) <= MAX_PAYLOAD:
        return text
    kept: dict[str, Any] = {
        k: v
        for k, v in data.items()
        if v is None
        or isinstance(v, bool | int | float)
        or (isinstance(v, str) and len(v) <= _SHORT)
    }
    kept["truncated"] = sorted(k for k in data if k not in kept)
    text = dump(kept)
    if len(text.encode()) <= MAX_PAYLOAD:
        return text
    minimal: dict[str, Any] = {k: kept[k] for k in _KEY_FIELDS if k in kept}
    minimal["truncated"] = sorted(k for k in data if k not in minimal)
    return dump(minimal)


class PgEventRelay:
    """Relays one server's :class:`EventBus` to and from every other server's."""

    def __init__(
        self,
        bus: EventBus,
        database_url: str,
        *,
        server_id: str | None = None,
        channel: str = CHANNEL,
    ) -> None:
        self.bus = bus
        self.url = database_url
        self.server_id = server_id or f"srv_{secrets.token_hex(6)}"
        self.channel = channel
        self._outbox: queue.SimpleQueue[tuple[str, dict[str, Any]] | None] = queue.SimpleQueue()
        self._seq = itertools.count(1)
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self.listening = threading.Event()  # LISTEN is active (set again after a reconnect)
        self.sent = 0
        self.received = 0
        #: Events given up after a failed send and a failed retry; LISTEN
        #: connections lost, and made again.
        self.dropped = 0
        self.listen_losses = 0
        self.reconnects = 0

    def start(self) -> PgEventRelay:
        """Listen first (so nothing sent after ``start`` returns is missed), then relay."""
        for target, name in (
            (self._listen_loop, "pg-events-listen"),
            (self._send_loop, "pg-events-send"),
        ):
            th = threading.Thread(target=target, name=name, daemon=True)
            th.start()
            self._threads.append(th)
        if not self.listening.wait(30):
            log.warning("event relay: not listening on PostgreSQL after 30 s; retrying")
        self.bus.add_listener(self._on_publish)
        return self

    def stop(self) -> None:
        self._stop.set()
        self._outbox.put(None)
        for th in self._threads:
            th.join(10)

    # ----------------------------------------------------------------- sending
    def _on_publish(self, type_: str, data: dict[str, Any]) -> None:
        """Bus listener (runs on the publisher's thread): only queue it."""
        self._outbox.put((type_, data))

    def _send_loop(self) -> None:
        conn: psycopg.Connection[Any] | None = None
        stopping = False
        while not stopping:
            item = self._outbox.get()
            if item is None:
                break
            batch = [item]
            while len(batch) < 200:  # what queued up meanwhile goes in the same commit
                try:
                    more = self._outbox.get_nowait()
                except queue.Empty:
                    break
                if more is None:
                    stopping = True
                    break
                batch.append(more)
            payloads = [encode(self.server_id, next(self._seq), t, d) for t, d in batch]
            # Twice: a connection the database closed while it sat idle (a
            # restart, a fail-over) is found dead only by this send, and the
            # batch goes on a new one rather than being lost.
            for attempt in (1, 2):
                try:
                    if conn is None:
                        conn = self._connect("send")
                    with conn.transaction():  # one commit; delivered in this order
                        for p in payloads:
                            conn.execute("SELECT pg_notify(%s, %s)", (self.channel, p))
                    self.sent += len(payloads)
                    break
                except psycopg.Error as exc:
                    _close(conn)
                    conn = None
                    if attempt == 1:
                        log.info("event relay: notify failed (%s); reconnecting", exc)
                        continue
                    self.dropped += len(payloads)
                    log.warning(
                        "event relay: cannot notify (%s); %d events not relayed",
                        exc,
                        len(payloads),
                    )
                    self._stop.wait(1.0)  # do not spin while the database is away
        _close(conn)

    def _connect(self, role: str) -> psycopg.Connection[Any]:
        """A connection of this relay, named so that an administrator sees it in
        ``pg_stat_activity`` (``steelpath-events-send``/``-listen``)."""
        return psycopg.connect(
            self.url, autocommit=True, application_name=f"steelpath-events-{role}"
        )

    # --------------------------------------------------------------- receiving
    def _listen_loop(self) -> None:
        conn: psycopg.Connection[Any] | None = None
        while not self._stop.is_set():
            try:
                if conn is None:
                    conn = self._connect("listen")
                    conn.execute(sql.SQL("LISTEN {}").format(sql.Identifier(self.channel)))
                    if self.listening.is_set() or self.listen_losses:
                        self.reconnects += 1
                    self.listening.set()
                for note in conn.notifies(timeout=0.5):
                    self._receive(note.payload)
                    if self._stop.is_set():
                        break
            except psycopg.Error as exc:
                self.listening.clear()
                self.listen_losses += 1
                log.warning("event relay: lost the LISTEN connection (%s); reconnecting", exc)
                _close(conn)
                conn = None
                self._stop.wait(1.0)
        _close(conn)

    def _receive(self, payload: str) -> None:
        try:
            msg = json.loads(payload)
            if msg.get("o") == self.server_id:
                return  # our own, already on our bus
            type_, data = str(msg["t"]), dict(msg["d"])
        except (ValueError, KeyError, TypeError) as exc:
            log.warning("event relay: unreadable notification ignored (%s)", exc)
            return
        self.received += 1
        self.bus.publish(type_, data, remote=True)


def _close(conn: psycopg.Connection[Any] | None) -> None:
    if conn is not None:
        with contextlib.suppress(psycopg.Error):
            conn.close()
