"""``/api/v1/webhooks`` (admin): receivers of signed event deliveries (issue #16 §5).

How deliveries are signed, retried and listed: :mod:`server.webhooks`.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal, get_args
from urllib.parse import urlsplit

from fastapi import APIRouter, Depends, Query, Response
from pydantic import BaseModel, ConfigDict, Field, field_validator

from server.auth import Admin
from server.routers.responses import errors
from server.services import Services, get_services
from server.store.webhooks import WEBHOOK_EVENTS, WebhookStore

router = APIRouter(prefix="/webhooks", tags=["webhooks"])

#: http(s)://host[:port][/path…] — in the schema, so clients see the rule.
_URL = r"^https?://[A-Za-z0-9](?:[A-Za-z0-9.-]*[A-Za-z0-9])?(?::[0-9]{1,5})?(?:[/?#]\S*)?$"
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


@router.post("", status_code=201, responses=errors(401, 403, 422))
def create_webhook(req: WebhookRequest, services: Svc, who: Admin) -> dict[str, Any]:
    """Register a receiver.  The answer holds its signing ``secret``, shown
    only here: deliveries carry ``X-SteelPath-Signature: sha256=HMAC(secret,
    "{X-SteelPath-Timestamp}.{body}")``."""
    hook = _hooks(services).add(req.url, list(req.events), who.actor)
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
