"""Webhook receivers and their deliveries, in the service's database (SQLite or PostgreSQL).

A webhook is an admin-registered URL with the events it wants and a secret
(generated here, shown once) that signs every delivery.  A delivery is one
event for one webhook: ``pending`` until the receiver answers 2xx
(``delivered``) or the attempts run out (``failed``); ``next_at`` (Unix
seconds) is when it is due again.  Rows are kept: a removed webhook gets
``removed_at`` and no new deliveries, and its history stays listed.
"""

from __future__ import annotations

import json
import secrets
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from server.store.database import RowLike, StoreDatabase, utcnow
from server.store.store import NotFoundError

#: Events a webhook can ask for.
WEBHOOK_EVENTS: tuple[str, ...] = (
    "execution.completed",
    "execution.faulted",
    "execution.interrupted",
    "estop",
    "finding.created",  # condition state 3 (poor) or 4 (severe) only
)

DELIVERY_STATES: tuple[str, ...] = ("pending", "delivered", "failed")


@dataclass(frozen=True)
class Webhook:
    id: str
    url: str
    events: list[str]
    secret: str
    created_by: str
    created_at: str
    removed_at: str | None
    removed_by: str | None
    #: May deliver to loopback, private and shared addresses (server.netpolicy).
    allow_private_network: bool = False

    @classmethod
    def from_row(cls, r: RowLike) -> Webhook:
        return cls(
            r["id"],
            r["url"],
            json.loads(r["events"]),
            r["secret"],
            r["created_by"],
            r["created_at"],
            r["removed_at"],
            r["removed_by"],
            bool(r["allow_private_network"]),
        )

    def public(self) -> dict[str, Any]:
        """Everything but the secret."""
        return {
            "id": self.id,
            "url": self.url,
            "events": self.events,
            "allow_private_network": self.allow_private_network,
            "created_by": self.created_by,
            "created_at": self.created_at,
            "removed_at": self.removed_at,
            "removed_by": self.removed_by,
        }


@dataclass(frozen=True)
class Delivery:
    id: str
    webhook_id: str
    event: str
    payload: dict[str, Any]
    state: str
    attempts: int
    next_at: float | None
    last_status: int | None
    last_error: str | None
    created_at: str
    delivered_at: str | None

    @classmethod
    def from_row(cls, r: RowLike) -> Delivery:
        return cls(
            r["id"],
            r["webhook_id"],
            r["event"],
            json.loads(r["payload"]),
            r["state"],
            int(r["attempts"]),
            r["next_at"],
            r["last_status"],
            r["last_error"],
            r["created_at"],
            r["delivered_at"],
        )

    def public(self) -> dict[str, Any]:
        return {
            "id": self.id,
            "webhook_id": self.webhook_id,
            "event": self.event,
            "state": self.state,
            "attempts": self.attempts,
            "last_status": self.last_status,
            "last_error": self.last_error,
            "created_at": self.created_at,
            "delivered_at": self.delivered_at,
            "payload": self.payload,
        }


class WebhookStore:
    """Webhooks and deliveries over the service's :class:`Database`."""

    def __init__(self, db: StoreDatabase) -> None:
        self.db = db

    # ---------------------------------------------------------------- webhooks
    def add(
        self,
        url: str,
        events: Sequence[str],
        actor: str,
        *,
        allow_private_network: bool = False,
    ) -> Webhook:
        wid = f"wh_{secrets.token_hex(6)}"
        secret = f"whsec_{secrets.token_urlsafe(24)}"
        reason = f"{url} for {', '.join(events)}"
        if allow_private_network:
            reason += " (private network allowed)"
        with self.db.transaction() as conn:
            conn.execute(
                "INSERT INTO webhooks (id, url, events, secret, created_by, created_at, "
                "allow_private_network) VALUES (?,?,?,?,?,?,?)",
                # an int, not a bool: the column is an integer on PostgreSQL too
                (
                    wid,
                    url,
                    json.dumps(list(events)),
                    secret,
                    actor,
                    utcnow(),
                    int(allow_private_network),
                ),
            )
            conn.execute(
                "INSERT INTO audit_events (ts, actor, entity, entity_id, action, reason) "
                "VALUES (?,?,?,?,?,?)",
                (utcnow(), actor, "webhook", wid, "create", reason),
            )
        return self.get(wid)

    def get(self, webhook_id: str) -> Webhook:
        r = self.db.query_one("SELECT * FROM webhooks WHERE id = ?", (webhook_id,))
        if r is None:
            raise NotFoundError(f"no webhook with id {webhook_id!r}")
        return Webhook.from_row(r)

    def listed(self, include_removed: bool = False) -> list[Webhook]:
        sql = "SELECT * FROM webhooks"
        if not include_removed:
            sql += " WHERE removed_at IS NULL"
        return [Webhook.from_row(r) for r in self.db.query(sql + " ORDER BY created_at, id")]

    def remove(self, webhook_id: str, actor: str) -> Webhook:
        """Stop delivering to it (pending deliveries fail); the rows stay."""
        self.get(webhook_id)
        with self.db.transaction() as conn:
            conn.execute(
                "UPDATE webhooks SET removed_at = ?, removed_by = ? "
                "WHERE id = ? AND removed_at IS NULL",
                (utcnow(), actor, webhook_id),
            )
            conn.execute(
                "UPDATE webhook_deliveries SET state = 'failed', next_at = NULL, "
                "last_error = 'webhook removed' WHERE webhook_id = ? AND state = 'pending'",
                (webhook_id,),
            )
            conn.execute(
                "INSERT INTO audit_events (ts, actor, entity, entity_id, action) "
                "VALUES (?,?,?,?,?)",
                (utcnow(), actor, "webhook", webhook_id, "remove"),
            )
        return self.get(webhook_id)

    # -------------------------------------------------------------- deliveries
    def enqueue(self, event: str, payload: dict[str, Any], now: float) -> list[Delivery]:
        """One pending delivery per live webhook that asked for ``event``."""
        out: list[str] = []
        with self.db.transaction() as conn:
            for r in conn.execute("SELECT id, events FROM webhooks WHERE removed_at IS NULL"):
                if event not in json.loads(r["events"]):
                    continue
                did = f"dl_{secrets.token_hex(6)}"
                conn.execute(
                    "INSERT INTO webhook_deliveries (id, webhook_id, event, payload, state, "
                    "next_at, created_at) VALUES (?,?,?,?,'pending',?,?)",
                    (did, r["id"], event, json.dumps(payload), now, utcnow()),
                )
                out.append(did)
        return [self.get_delivery(d) for d in out]

    def get_delivery(self, delivery_id: str) -> Delivery:
        r = self.db.query_one("SELECT * FROM webhook_deliveries WHERE id = ?", (delivery_id,))
        if r is None:
            raise NotFoundError(f"no webhook delivery with id {delivery_id!r}")
        return Delivery.from_row(r)

    def deliveries(self, webhook_id: str, limit: int = 100) -> list[Delivery]:
        rows = self.db.query(
            "SELECT * FROM webhook_deliveries WHERE webhook_id = ? "
            "ORDER BY created_at DESC, rowid DESC LIMIT ?",
            (webhook_id, limit),
        )
        return [Delivery.from_row(r) for r in rows]

    def due(self, now: float, limit: int = 50) -> list[Delivery]:
        rows = self.db.query(
            "SELECT * FROM webhook_deliveries WHERE state = 'pending' AND next_at <= ? "
            "ORDER BY next_at LIMIT ?",
            (now, limit),
        )
        return [Delivery.from_row(r) for r in rows]

    def next_due(self) -> float | None:
        r = self.db.query_one("SELECT MIN(next_at) FROM webhook_deliveries WHERE state = 'pending'")
        return None if r is None or r[0] is None else float(r[0])

    def record_attempt(
        self,
        delivery_id: str,
        *,
        ok: bool,
        status: int | None,
        error: str | None,
        retry_at: float | None,
    ) -> Delivery:
        """One attempt's outcome: delivered, pending again at ``retry_at``,
        or failed (no ``retry_at``)."""
        state = "delivered" if ok else ("pending" if retry_at is not None else "failed")
        with self.db.transaction() as conn:
            conn.execute(
                "UPDATE webhook_deliveries SET attempts = attempts + 1, state = ?, "
                "next_at = ?, last_status = ?, last_error = ?, delivered_at = ? "
                "WHERE id = ? AND state = 'pending'",
                (
                    state,
                    None if ok else retry_at,
                    status,
                    error,
                    utcnow() if ok else None,
                    delivery_id,
                ),
            )
        return self.get_delivery(delivery_id)
