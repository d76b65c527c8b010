"""Authenticated WebSocket proxy to the live Foxglove server ("Live").

The Foxglove SDK's server (:mod:`server.foxglove_live`) speaks the Foxglove
WebSocket protocol, which has no authentication, and listens on 127.0.0.1
only.  Remote users connect Foxglove (or Lichtblick) to this route instead:
``ws://<api host>:<api port>/foxglove?token=<token>`` — at the app root like
the scene's ``/scene`` proxy, not under ``/api/v1``, since it is a websocket
speaking Foxglove's protocol, not a REST resource.

The token (viewer role is enough: the live channels only show a run) comes
from, first found:

- the ``token`` query parameter — Foxglove's connection dialog takes only a
  URL, so this is how Foxglove authenticates; prefer a viewer token with an
  expiry for it (``steelpath token create --role viewer --expires-in 1d``),
  as a URL may end up in a history or log;
- an ``Authorization: Bearer`` header;
- the console's session cookie, from a same-origin page only (the check of
  :func:`server.scene.proxy.same_origin`): the cookie is an ambient
  credential, the other two are not, so they are accepted from any origin
  (the Foxglove web app's page is on its own origin).

Refusals come before the handshake completes, as HTTP responses with a JSON
``detail``: 401/403 for a missing, invalid or under-privileged token, 503
when the live server is off (``STEELPATH_FOXGLOVE_PORT`` unset or 0), 400
when the client offers neither ``foxglove.sdk.v1`` nor
``foxglove.websocket.v1``.  The SDK's server accepts only ``foxglove.sdk.v1``
(the same protocol under its new name), so the proxy connects upstream with
it and answers the client with the name it offered, ``foxglove.sdk.v1``
first.  The connection is closed (code 1008) once its token is revoked or
expires.
"""

from __future__ import annotations

import logging

import websockets
from fastapi import APIRouter, WebSocket
from fastapi.responses import JSONResponse
from starlette.concurrency import run_in_threadpool
from websockets.typing import Subprotocol

from server.auth import COOKIE, Principal, TokenRefused, resolve
from server.scene.proxy import same_origin
from server.services import Services
from server.wsrelay import relay

log = logging.getLogger(__name__)

router = APIRouter(include_in_schema=False)

#: Watching the live channels needs this role.
FOXGLOVE_ROLE = "viewer"
#: The subprotocol the SDK's server speaks (foxglove-sdk 0.30 accepts no other).
UPSTREAM = "foxglove.sdk.v1"
#: Subprotocols a client may offer, preferred first: Foxglove states that
#: ``foxglove.sdk.v1`` is, for now, the ``foxglove.websocket.v1`` protocol under
#: a new name, which older clients (Lichtblick before 1.22) offer alone.
SUBPROTOCOLS = (UPSTREAM, "foxglove.websocket.v1")


async def _refuse(websocket: WebSocket, status: int, detail: str) -> None:
    """Refuse the handshake: an HTTP response saying why, or HTTP 403 where the
    ASGI server cannot send one (a close before accept)."""
    if "websocket.http.response" in websocket.scope.get("extensions", {}):
        await websocket.send_denial_response(JSONResponse({"detail": detail}, status))
    else:
        await websocket.close(code=1008 if status in (401, 403) else 1013, reason=detail)


async def _principal(websocket: WebSocket, services: Services) -> Principal | str:
    """Who connects, or why the handshake is refused."""
    token = websocket.query_params.get("token")
    header = websocket.headers.get("authorization", "")
    if not token and header.lower().startswith("bearer "):
        token = header[7:].strip()
    if not token:
        token = websocket.cookies.get(COOKIE)
        origin = websocket.headers.get("origin")
        if token and not same_origin(origin, websocket.headers.get("host")):
            log.warning(
                "refused a cross-origin Foxglove websocket with a cookie (Origin %r)", origin
            )
            return "cross-origin request with a session cookie: pass ?token=<token> instead"
    try:
        return await run_in_threadpool(resolve, services.store, token)
    except TokenRefused as exc:
        return exc.detail


@router.websocket("/foxglove")
async def foxglove_socket(websocket: WebSocket) -> None:
    """Forward an authenticated client to the live Foxglove server on 127.0.0.1."""
    services: Services = websocket.app.state.services
    who = await _principal(websocket, services)
    if isinstance(who, str):
        await _refuse(websocket, 401, who)
        return
    if not who.has(FOXGLOVE_ROLE):
        await _refuse(websocket, 403, f"the live Foxglove channels need the {FOXGLOVE_ROLE} role")
        return
    live = services.foxglove
    if live is None or not live.running:
        await _refuse(
            websocket,
            503,
            "the live Foxglove server is off: start the service with STEELPATH_FOXGLOVE_PORT set",
        )
        return
    offered = list(websocket.scope.get("subprotocols") or [])
    chosen = next((p for p in SUBPROTOCOLS if p in offered), None)
    if chosen is None:
        await _refuse(
            websocket, 400, f"offer the subprotocol {' or '.join(SUBPROTOCOLS)} (offered {offered})"
        )
        return
    try:
        upstream = await websockets.connect(
            f"ws://127.0.0.1:{live.port}/",
            subprotocols=[Subprotocol(UPSTREAM)],
            max_size=None,
            compression=None,
            open_timeout=10,
        )
    except (OSError, websockets.InvalidHandshake) as exc:
        await _refuse(websocket, 502, f"the live Foxglove server did not answer: {exc}")
        return
    await websocket.accept(subprotocol=chosen)

    await relay(websocket, upstream, services.store, who, "Foxglove")
