"""Authenticated reverse proxy to the viser scene, plus scene control endpoints.

viser has no authentication and listens on 127.0.0.1 only; the console
embeds ``/scene/`` from FastAPI, which forwards the page and the websocket
after checking the operator's token (cookie from ``POST /api/v1/session``
or a bearer header).  viser's client derives its websocket address from the
page URL (``/scene/`` → ``ws://host/scene``), so both routes live here.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from typing import Annotated, Any

import httpx
import websockets
from fastapi import APIRouter, Depends, HTTPException, Request, Response, WebSocket
from fastapi.responses import RedirectResponse
from pydantic import BaseModel, model_validator
from starlette.websockets import WebSocketDisconnect

from server.auth import Operator, Viewer, authenticate
from server.services import Services, get_services

log = logging.getLogger(__name__)

Svc = Annotated[Services, Depends(get_services)]

proxy_router = APIRouter(include_in_schema=False)
api_router = APIRouter(prefix="/scene", tags=["scene"])

SCENE_ROLE = "operator"  # the scene can propose plans, so viewing it needs operator


def _scene_port(services: Services) -> int:
    scene = services.scene
    if scene is None or not scene.running or scene.port is None:
        raise HTTPException(503, detail="the 3D scene is not running (STEELPATH_SCENE_PORT=0?)")
    return int(scene.port)


@proxy_router.get("/scene")
def scene_redirect() -> RedirectResponse:
    return RedirectResponse("/scene/")


@proxy_router.get("/scene/{path:path}")
async def scene_page(path: str, request: Request, services: Svc, _: Operator) -> Response:
    port = _scene_port(services)
    async with httpx.AsyncClient(timeout=10.0) as client:
        upstream = await client.get(
            f"http://127.0.0.1:{port}/{path}",
            params=dict(request.query_params),
            headers={"accept-encoding": "identity"},
        )
    headers = {
        k: v
        for k, v in upstream.headers.items()
        if k.lower() in ("content-type", "cache-control", "etag", "last-modified")
    }
    return Response(upstream.content, status_code=upstream.status_code, headers=headers)


@proxy_router.websocket("/scene")
@proxy_router.websocket("/scene/")
async def scene_socket(websocket: WebSocket) -> None:
    services: Services = websocket.app.state.services
    token = websocket.cookies.get("steelpath_token")
    header = websocket.headers.get("authorization", "")
    if header.lower().startswith("bearer "):
        token = header[7:].strip()
    principal = authenticate(services, token)
    if principal is None or not principal.has(SCENE_ROLE):
        # Closing before accept refuses the handshake (HTTP 403).
        await websocket.close(code=1008)
        return
    scene = services.scene
    if scene is None or not scene.running:
        await websocket.close(code=1013)
        return
    offered = [
        p.strip()
        for p in websocket.headers.get("sec-websocket-protocol", "").split(",")
        if p.strip()
    ]
    try:
        upstream = await websockets.connect(
            f"ws://127.0.0.1:{scene.port}/",
            subprotocols=offered or None,  # type: ignore[arg-type]
            max_size=None,
            compression=None,
            open_timeout=10,
        )
    except OSError:
        await websocket.close(code=1011)
        return
    await websocket.accept(subprotocol=upstream.subprotocol)

    async def client_to_upstream() -> None:
        while True:
            msg = await websocket.receive()
            if msg["type"] == "websocket.disconnect":
                return
            if msg.get("bytes") is not None:
                await upstream.send(msg["bytes"])
            elif msg.get("text") is not None:
                await upstream.send(msg["text"])

    async def upstream_to_client() -> None:
        async for data in upstream:
            if isinstance(data, bytes):
                await websocket.send_bytes(data)
            else:
                await websocket.send_text(data)

    tasks = [asyncio.create_task(client_to_upstream()), asyncio.create_task(upstream_to_client())]
    try:
        await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
    finally:
        for t in tasks:
            t.cancel()
        for t in tasks:
            with contextlib.suppress(asyncio.CancelledError, WebSocketDisconnect, Exception):
                await t
        await upstream.close()
        with contextlib.suppress(Exception):
            await websocket.close()


class ShowRequest(BaseModel):
    plan_id: str | None = None
    cloud_id: str | None = None

    @model_validator(mode="after")
    def _one(self) -> ShowRequest:
        if (self.plan_id is None) == (self.cloud_id is None):
            raise ValueError("give exactly one of plan_id or cloud_id")
        return self


@api_router.get("")
def scene_state(services: Svc, _: Viewer) -> dict[str, Any]:
    scene = services.scene
    if scene is None or not scene.running:
        return {"running": False}
    return {
        "running": True,
        "path": "/scene/",
        "current": scene.current,
        "proposals": scene.proposals[-20:],
    }


@api_router.post("/show")
def scene_show(req: ShowRequest, services: Svc, _: Operator) -> dict[str, Any]:
    """Draw a stored plan or cloud in the shared scene."""
    scene = services.scene
    if scene is None or not scene.running:
        raise HTTPException(503, detail="the 3D scene is not running")
    if req.plan_id is not None:
        return scene.show_plan(req.plan_id)
    assert req.cloud_id is not None
    return scene.show_cloud(req.cloud_id)
