"""``GET /api/v1/events``: server-sent events of plan, execution and robot changes."""

from __future__ import annotations

import asyncio
import json
from collections.abc import AsyncIterator
from typing import Annotated

from fastapi import APIRouter, Depends, Query, Request
from fastapi.responses import StreamingResponse

from server.auth import Viewer, until_invalid
from server.services import Services, get_services

router = APIRouter(tags=["events"])


@router.get("/events")
async def events(
    request: Request,
    services: Annotated[Services, Depends(get_services)],
    who: Viewer,
    # Bounded: heartbeat_s=0 made the stream loop without waiting (a busy core per client).
    heartbeat_s: Annotated[
        float, Query(ge=0.5, le=300, description="seconds between heartbeats")
    ] = 15.0,
    once: bool = False,
) -> StreamingResponse:
    """A ``text/event-stream``: ``event: plan|execution|robot|estop|cloud|proposal``,
    JSON ``data``; a last ``event: auth`` when the token is revoked or expires.
    Reconnecting clients send ``Last-Event-ID`` to replay what they missed
    (from a bounded history).  ``once=true`` sends the backlog and ends (for
    scripts and tests)."""
    last = request.headers.get("last-event-id")
    after = int(last) if last and last.isdigit() else (0 if once else None)
    queue = services.events.subscribe(after=after)

    async def stream() -> AsyncIterator[bytes]:
        # Ends the stream (with a final ``event: auth``) once the token is
        # revoked or expires, instead of streaming to it forever.
        invalid = asyncio.create_task(until_invalid(services.store, who))
        try:
            yield b": steelpath event stream\n\n"
            while True:
                get = asyncio.ensure_future(queue.get())
                done, _ = await asyncio.wait(
                    {get, invalid},
                    timeout=0.05 if once else heartbeat_s,
                    return_when=asyncio.FIRST_COMPLETED,
                )
                if get not in done:
                    get.cancel()  # a cancelled Queue.get leaves its item queued
                if invalid in done:
                    body = json.dumps({"detail": invalid.result(), "token_id": who.token_id})
                    yield f"event: auth\ndata: {body}\n\n".encode()
                    return
                if get not in done:
                    if once:
                        return
                    yield b": heartbeat\n\n"
                    if await request.is_disconnected():
                        return
                    continue
                ev = get.result()
                body = json.dumps({"id": ev.id, "ts": ev.ts, **ev.data})
                yield f"id: {ev.id}\nevent: {ev.type}\ndata: {body}\n\n".encode()
        finally:
            invalid.cancel()
            services.events.unsubscribe(queue)

    return StreamingResponse(
        stream(),
        media_type="text/event-stream",
        headers={"Cache-Control": "no-store", "X-Accel-Buffering": "no"},
    )
