"""``/api/v1/webhooks`` (admin): receivers of signed event deliveries.

How deliveries are signed, retried and listed: :mod:`server.webhooks`.  Where
they may go: :mod:`server.netpolicy` (public addresses only, unless the
webhook's ``allow_private_network``), checked here at registration and again
before every delivery.
"""

from __future__ import annotations

import socket
from collections.abc import Sequence
from typing import Annotated, Any, Literal, get_args
from urllib.parse import urlsplit

from fastapi import APIRouter, Depends, HTTPException, Query, Request, Response
from pydantic import BaseModel, ConfigDict, Field, field_validator

from server.auth import Admin
from server.netpolicy import SCHEMES, Address, UnsafeWebhookUrl, check_url, kind
from server.routers.responses import errors
from server.services import Services, get_services
from server.store.webhooks import WEBHOOK_EVENTS, WebhookStore

router = APIRouter(prefix="/webhooks", tags=["webhooks"])

#: http(s)://host[:port][/path…], the host a name, an IPv4 or a bracketed IPv6
#: address — in the schema, so clients see the rule.
_URL = (
    r"^https?://(?:[A-Za-z0-9](?:[A-Za-z0-9.-]*[A-Za-z0-9])?|\[[0-9A-Fa-f:.]+\])"
    r"(?::[0-9]{1,5})?(?:[/?#]\S*)?$"
)
EventName = Literal[
    "execution.completed", "execution.faulted", "execution.interrupted", "estop", "finding.created"
]
assert set(get_args(EventName)) == set(WEBHOOK_EVENTS)

Svc = Annotated[Services, Depends(get_services)]


class WebhookRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")

    url: str = Field(
        ...,
        max_length=2000,
        pattern=_URL,
        description="http(s) URL that receives the POSTs",
    )
    events: list[EventName] = Field(
        default_factory=lambda: list(get_args(EventName)),
        min_length=1,
        description=f"events to receive, of: {', '.join(WEBHOOK_EVENTS)} (default: all)",
    )
    allow_private_network: bool = Field(
        False,
        description="also deliver to loopback, private (RFC 1918, fc00::/7) and shared "
        "(100.64.0.0/10) addresses, for a lab receiver on the LAN; never to link-local, "
        "multicast, unspecified or reserved ones, nor to this server itself",
    )

    @field_validator("url")
    @classmethod
    def _http_url(cls, v: str) -> str:
        parts = urlsplit(v)
        if parts.scheme not in ("http", "https") or not parts.hostname:
            raise ValueError(f"must be an http:// or https:// URL with a host, got {v!r}")
        return v

    @field_validator("events")
    @classmethod
    def _once_each(cls, v: list[EventName]) -> list[EventName]:
        return sorted(set(v), key=WEBHOOK_EVENTS.index)


def _hooks(services: Services) -> WebhookStore:
    return WebhookStore(services.store.db)


_SELF = "webhook URL points at this SteelPath server itself; it may not POST to its own API"


def _is_this_server(url: str, ips: Sequence[Address], request: Request) -> bool:
    """Whether ``url`` leads back to this server: the host and port this
    request came in on, the address and port it arrived at, or a loopback
    address on that port (a port on loopback belongs to one process)."""
    hook = urlsplit(url)
    port = hook.port or SCHEMES[hook.scheme]
    own = {(request.url.hostname, request.url.port or SCHEMES.get(request.url.scheme, 80))}
    server = request.scope.get("server")
    own_port = None
    if server and server[1] is not None:
        own_port = int(server[1])
        own.add((str(server[0]), own_port))
    if (hook.hostname, port) in own:
        return True
    return any(
        (str(ip), port) in own or (port == own_port and kind(ip) == "loopback") for ip in ips
    )


@router.post("", status_code=201, responses=errors(401, 403, 422))
def create_webhook(
    req: WebhookRequest, request: Request, services: Svc, who: Admin
) -> dict[str, Any]:
    """Register a receiver.  The answer holds its signing ``secret``, shown
    only here: deliveries carry ``X-SteelPath-Signature: sha256=HMAC(secret,
    "{X-SteelPath-Timestamp}.{body}")``.

    Its host must resolve, and only to public addresses; with
    ``allow_private_network`` also to loopback, private and shared ones (a
    lab receiver), never to link-local (a cloud's metadata service),
    multicast, unspecified or reserved ones, nor to this server itself.
    Otherwise 422, ``detail`` saying why.  Checked again before each delivery.
    """
    # The dispatcher's resolver: one way of resolving names for both checks
    # (and the one tests replace).
    resolve = getattr(services.webhooks, "resolve", socket.getaddrinfo)
    try:
        if _is_this_server(req.url, [], request):  # by name: it may not resolve from here
            raise UnsafeWebhookUrl(_SELF)
        ips = check_url(req.url, allow_private=req.allow_private_network, resolve=resolve)
        if _is_this_server(req.url, ips, request):
            raise UnsafeWebhookUrl(_SELF)
    except UnsafeWebhookUrl as exc:
        raise HTTPException(422, str(exc)) from exc
    hook = _hooks(services).add(
        req.url, list(req.events), who.actor, allow_private_network=req.allow_private_network
    )
    return {**hook.public(), "secret": hook.secret}


@router.get("", responses=errors(401, 403))
def list_webhooks(
    services: Svc,
    _: Admin,
    include_removed: Annotated[bool, Query(description="also the removed ones")] = False,
) -> list[dict[str, Any]]:
    return [h.public() for h in _hooks(services).listed(include_removed)]


@router.get("/{webhook_id}", responses=errors(401, 403, 404))
def get_webhook(webhook_id: str, services: Svc, _: Admin) -> dict[str, Any]:
    return _hooks(services).get(webhook_id).public()


@router.delete("/{webhook_id}", status_code=204, responses=errors(401, 403, 404))
def remove_webhook(webhook_id: str, services: Svc, who: Admin) -> Response:
    """Stop delivering to it (its pending deliveries fail); it and its
    deliveries stay listed (``include_removed``)."""
    store = _hooks(services)
    store.get(webhook_id)  # 404 when unknown
    store.remove(webhook_id, who.actor)
    return Response(status_code=204)


@router.get("/{webhook_id}/deliveries", responses=errors(401, 403, 404))
def list_deliveries(
    webhook_id: str,
    services: Svc,
    _: Admin,
    limit: Annotated[int, Query(ge=1, le=1000)] = 100,
) -> list[dict[str, Any]]:
    """Its deliveries, newest first: event, state (pending / delivered /
    failed), attempts, the last status or error, and the payload."""
    store = _hooks(services)
    store.get(webhook_id)  # 404 when unknown
    return [d.public() for d in store.deliveries(webhook_id, limit)]
