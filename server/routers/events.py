"""``GET /api/v1/events``: server-sent events of plan, execution and robot changes."""

from __future__ import annotations

import asyncio
import json
from collections.abc import AsyncIterator
from typing import Annotated

from fastapi import APIRouter, Depends, Request
from fastapi.responses import StreamingResponse

from server.auth import Viewer
from server.services import Services, get_services

router = APIRouter(tags=["events"])


@router.get("/events")
async def events(
    request: Request,
    services: Annotated[Services, Depends(get_services)],
    _: Viewer,
    heartbeat_s: float = 15.0,
    once: bool = False,
) -> StreamingResponse:
    """A ``text/event-stream``: ``event: plan|execution|robot|estop|cloud``, JSON
    ``data``.  Reconnecting clients send ``Last-Event-ID`` to replay what they
    missed (from a bounded history).  ``once=true`` sends the backlog and ends
    (for scripts and tests)."""
    last = request.headers.get("last-event-id")
    after = int(last) if last and last.isdigit() else (0 if once else None)
    queue = services.events.subscribe(after=after)

    async def stream() -> AsyncIterator[bytes]:
        try:
            yield b": steelpath event stream\n\n"
            while True:
                try:
                    ev = await asyncio.wait_for(queue.get(), timeout=0.05 if once else heartbeat_s)
                except TimeoutError:
                    if once:
                        return
                    yield b": heartbeat\n\n"
                    if await request.is_disconnected():
                        return
                    continue
                body = json.dumps({"id": ev.id, "ts": ev.ts, **ev.data})
                yield f"id: {ev.id}\nevent: {ev.type}\ndata: {body}\n\n".encode()
        finally:
            services.events.unsubscribe(queue)

    return StreamingResponse(
        stream(),
        media_type="text/event-stream",
        headers={"Cache-Control": "no-store", "X-Accel-Buffering": "no"},
    )
