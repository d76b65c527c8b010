"""In-process publish/subscribe of plan, execution and robot changes.

Publishers may be any thread (job listener, dispatch engine, viser
callbacks); subscribers are asyncio consumers (the SSE endpoint).  Each
subscriber has a bounded queue: a consumer that stops reading loses old
events rather than growing memory without bound.
"""

from __future__ import annotations

import asyncio
import itertools
import logging
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any


@dataclass
class Event:
    id: int
    type: str
    data: dict[str, Any]
    ts: float = field(default_factory=time.time)


class EventBus:
    def __init__(self, history: int = 500, queue_size: int = 1000) -> None:
        self._ids = itertools.count(1)
        self._lock = threading.Lock()
        self._subs: list[tuple[asyncio.AbstractEventLoop, asyncio.Queue[Event]]] = []
        self._history: deque[Event] = deque(maxlen=history)
        self._queue_size = queue_size
        self._listeners: list[Callable[[str, dict[str, Any]], None]] = []

    def add_listener(self, fn: Callable[[str, dict[str, Any]], None]) -> None:
        """Call ``fn(type, data)`` on every publish, on the publisher's thread:
        it must only hand the event over (e.g. put it on a queue)."""
        with self._lock:
            self._listeners.append(fn)

    def publish(self, type_: str, data: dict[str, Any], *, remote: bool = False) -> Event:
        """Deliver to the subscribers (and history) and call the listeners.

        ``remote``: the event was published on another server sharing the
        PostgreSQL store and relayed here (:mod:`server.events_pg`): it reaches
        this server's history and subscribers (the SSE streams) but not its
        listeners, whose effects (webhook deliveries, maintenance outcomes,
        the relay itself) happen once, on the server that published it.
        """
        with self._lock:
            ev = Event(next(self._ids), type_, data)
            self._history.append(ev)
            subs = list(self._subs)
            listeners = [] if remote else list(self._listeners)
        for fn in listeners:
            try:
                fn(type_, data)
            except Exception:  # a listener must not break the publisher
                logging.getLogger(__name__).exception("event listener failed on %s", type_)
        for loop, q in subs:
            try:
                loop.call_soon_threadsafe(self._offer, q, ev)
            except RuntimeError:  # loop closed: subscriber is gone
                self._drop(q)
        return ev

    @staticmethod
    def _offer(q: asyncio.Queue[Event], ev: Event) -> None:
        if q.full():
            q.get_nowait()
        q.put_nowait(ev)

    def subscribe(self, after: int | None = None) -> asyncio.Queue[Event]:
        """A queue receiving every later event (and history after ``after``)."""
        q: asyncio.Queue[Event] = asyncio.Queue(self._queue_size)
        loop = asyncio.get_running_loop()
        with self._lock:
            if after is not None:
                for ev in self._history:
                    if ev.id > after:
                        self._offer(q, ev)
            self._subs.append((loop, q))
        return q

    def _drop(self, q: asyncio.Queue[Event]) -> None:
        with self._lock:
            self._subs = [(lp, qq) for lp, qq in self._subs if qq is not q]

    def unsubscribe(self, q: asyncio.Queue[Event]) -> None:
        self._drop(q)

    def recent(self, n: int = 50) -> list[Event]:
        with self._lock:
            return list(self._history)[-n:]
