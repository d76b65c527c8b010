"""Relay an accepted browser websocket to an upstream one until either side
ends or the session's token stops being valid (revoked, expired): the
``/scene`` (viser) and ``/foxglove`` proxies share it."""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable
from typing import Any

from fastapi import WebSocket
from starlette.websockets import WebSocketDisconnect

from server.auth import Principal, until_invalid

log = logging.getLogger(__name__)


async def relay(
    websocket: WebSocket,
    upstream: Any,
    store: Any,
    principal: Principal,
    what: str,
    *,
    may_send: Callable[[bytes | str], bool] | None = None,
) -> None:
    """Pump frames both ways; close the browser's side with 1008 and the
    reason once the token is no longer valid, and the upstream always.

    ``may_send`` (when given) decides which of the browser's frames go
    upstream: a frame it refuses is dropped (a read-only viewer's clicks)."""

    async def client_to_upstream() -> None:
        while True:
            msg = await websocket.receive()
            if msg["type"] == "websocket.disconnect":
                return
            data = msg.get("bytes") if msg.get("bytes") is not None else msg.get("text")
            if data is None:
                continue
            if may_send is not None and not may_send(data):
                continue
            await upstream.send(data)

    async def upstream_to_client() -> None:
        async for data in upstream:
            if isinstance(data, bytes):
                await websocket.send_bytes(data)
            else:
                await websocket.send_text(data)

    invalid = asyncio.create_task(until_invalid(store, principal))
    tasks = [
        asyncio.create_task(client_to_upstream()),
        asyncio.create_task(upstream_to_client()),
        invalid,
    ]
    reason = ""
    try:
        await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
        if invalid.done() and not invalid.cancelled() and invalid.exception() is None:
            reason = invalid.result()
            log.info("closing %s websocket of %s: %s", what, principal.actor, reason)
    finally:
        for t in tasks:
            t.cancel()
        for t in tasks:
            with contextlib.suppress(asyncio.CancelledError, WebSocketDisconnect, Exception):
                await t
        await upstream.close()
        with contextlib.suppress(Exception):
            if reason:
                await websocket.close(code=1008, reason=reason)
            else:
                await websocket.close()
