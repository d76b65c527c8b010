"""``GET /api/v1/events``: server-sent events of plan, execution and robot changes."""

from __future__ import annotations

import asyncio
import json
from collections.abc import AsyncIterator
from typing import Annotated

from fastapi import APIRouter, Depends, HTTPException, Query, Request
from fastapi.responses import StreamingResponse

from server.auth import Viewer, until_invalid
from server.routers.robots import statuses_now
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
    robots_every_s: Annotated[
        float,
        Query(
            ge=0,
            le=300,
            description="also send every robot's status (as GET /robots) this often, "
            "as `event: robots` without an id; 0 (default) never; from 0.5 s",
        ),
    ] = 0.0,
    once: bool = False,
) -> StreamingResponse:
    """A ``text/event-stream``: ``event: plan|execution|robot|estop|cloud|proposal|measurement``,
    JSON ``data``; a last ``event: auth`` when the token is revoked or expires.
    Reconnecting clients send ``Last-Event-ID`` to replay what they missed
    (from a bounded history).  ``once=true`` sends the backlog and ends (for
    scripts and tests).  With ``robots_every_s`` the stream also carries the
    robots' statuses (heartbeats, faults, E-stop latches), so a console
    follows them without polling ``GET /robots``."""
    if 0 < robots_every_s < 0.5:
        raise HTTPException(422, detail="robots_every_s must be 0 (off) or at least 0.5 s")
    last = request.headers.get("last-event-id")
    after = int(last) if last and last.isdigit() else (0 if once else None)
    queue = services.events.subscribe(after=after)
    loop = asyncio.get_running_loop()

    async def robots_event() -> bytes | None:
        if services.dispatch is None:
            return None
        statuses = await statuses_now(services.dispatch, services.peers)
        return f"event: robots\ndata: {json.dumps(statuses)}\n\n".encode()

    async def stream() -> AsyncIterator[bytes]:
        # Ends the stream (with a final ``event: auth``) once the token is
        # revoked or expires, instead of streaming to it forever.
        invalid = asyncio.create_task(until_invalid(services.store, who))
        try:
            yield b": steelpath event stream\n\n"
            next_robots = loop.time() if robots_every_s and not once else None
            while True:
                if next_robots is not None and loop.time() >= next_robots:
                    snapshot = await robots_event()
                    if snapshot is not None:
                        yield snapshot
                    next_robots = loop.time() + robots_every_s
                wait = 0.05 if once else heartbeat_s
                if next_robots is not None:
                    wait = min(wait, max(0.0, next_robots - loop.time()))
                get = asyncio.ensure_future(queue.get())
                done, _ = await asyncio.wait(
                    {get, invalid}, timeout=wait, return_when=asyncio.FIRST_COMPLETED
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
                    if next_robots is not None and loop.time() >= next_robots:
                        continue  # the robots' statuses are due: no heartbeat needed
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
