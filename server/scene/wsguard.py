"""Per-connection authentication of viser's websocket with one-time tickets.

viser (1.1.x) has no authentication: anyone who can reach its port can open
its websocket and send clicks.  SteelPath's ``/scene`` proxy authenticates the
operator; this module makes viser refuse every websocket that the proxy did
not open:

- :class:`TicketDesk` issues one-time tickets (256-bit random, single use,
  valid ``ttl_s``).  The proxy takes one per upstream connection and sends it
  in the ``X-SteelPath-Scene-Ticket`` header; it never reaches the browser.
- :func:`guarded_viser_start` wraps viser's handshake.  viser builds its
  server with ``websockets.asyncio.server.serve(ws_handler, host, port,
  process_request=viser_http_server, ...)`` from its own thread while
  ``ViserServer()`` waits for it to bind, and offers no hook of its own.  For
  the duration of that constructor we substitute a subclass of ``serve``
  whose ``process_request`` first checks the ticket on any request carrying
  an ``Upgrade`` header (HTTP 403 without a valid one) and otherwise defers to
  viser's (which serves its static client page).  Only servers whose handler
  comes from the ``viser`` package are wrapped; the substitution is undone
  as soon as the constructor returns, under a lock.

The refusal happens in the HTTP handshake, before viser creates any client
state, so an unauthenticated client never gets a message handled.  If a viser
upgrade stops building its server this way, :func:`guarded_viser_start`
reports that nothing was wrapped and the scene refuses to run (fail closed).
"""

from __future__ import annotations

import http
import inspect
import logging
import secrets
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

log = logging.getLogger(__name__)

TICKET_HEADER = "X-SteelPath-Scene-Ticket"

_patch_lock = threading.Lock()


class TicketDesk:
    """One-time tickets: ``issue()`` (proxy side) and ``redeem()`` (viser's thread)."""

    def __init__(self, ttl_s: float = 30.0, max_open: int = 256) -> None:
        self.ttl_s = ttl_s
        self.max_open = max_open
        self._lock = threading.Lock()
        self._open: dict[str, float] = {}
        self.refused = 0

    def issue(self) -> str:
        ticket = secrets.token_urlsafe(32)
        now = time.monotonic()
        with self._lock:
            self._open = {t: exp for t, exp in self._open.items() if exp > now}
            if len(self._open) >= self.max_open:  # unredeemed tickets: keep the newest
                for t in sorted(self._open, key=self._open.__getitem__)[: len(self._open) // 2]:
                    del self._open[t]
            self._open[ticket] = now + self.ttl_s
        return ticket

    def redeem(self, ticket: str | None) -> bool:
        """True once for a ticket issued within ``ttl_s``; False for anything else."""
        if not ticket:
            return False
        with self._lock:
            expiry = self._open.pop(ticket, None)
        return expiry is not None and expiry > time.monotonic()


def _guard(inner: Callable[..., Any] | None, desk: TicketDesk) -> Callable[..., Any]:
    async def process_request(connection: Any, request: Any) -> Any:
        # Any upgrade attempt needs a ticket, however its header is spelt.
        upgrade = request.headers.get("Upgrade") is not None
        if upgrade and not desk.redeem(request.headers.get(TICKET_HEADER)):
            desk.refused += 1
            log.warning(
                "refused a scene websocket from %s without a valid proxy ticket",
                getattr(connection, "remote_address", "?"),
            )
            return connection.respond(
                http.HTTPStatus.FORBIDDEN,
                "the SteelPath scene is reached through the console's /scene/ proxy\n",
            )
        if inner is None:
            return None
        result = inner(connection, request)
        if inspect.isawaitable(result):
            result = await result
        return result

    return process_request


@contextmanager
def guarded_viser_start(desk: TicketDesk) -> Iterator[list[str]]:
    """While active, viser servers being built get the ticket check.

    Yields a list that receives one entry per server wrapped; empty after the
    block means viser was not built through ``serve`` and is unguarded.
    """
    import websockets.asyncio.server as wss

    original = wss.serve
    wrapped: list[str] = []

    class GuardedServe(original):  # type: ignore[misc,valid-type]
        def __init__(self, handler: Any, *args: Any, **kwargs: Any) -> None:
            if str(getattr(handler, "__module__", "")).startswith("viser"):
                kwargs["process_request"] = _guard(kwargs.get("process_request"), desk)
                wrapped.append(getattr(handler, "__qualname__", "?"))
            super().__init__(handler, *args, **kwargs)

    with _patch_lock:
        wss.serve = GuardedServe  # type: ignore[misc]
        try:
            yield wrapped
        finally:
            wss.serve = original  # type: ignore[misc]
