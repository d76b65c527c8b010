"""Persistent state: rows in SQLite (or PostgreSQL) + ``.npy`` arrays under the data directory."""

from server.store.records import AuditEvent, CloudRecord, ExecutionRecord, PlanRecord, TokenRecord
from server.store.store import NotFoundError, Store, new_id

__all__ = [
    "AuditEvent",
    "CloudRecord",
    "ExecutionRecord",
    "NotFoundError",
    "PlanRecord",
    "Store",
    "TokenRecord",
    "new_id",
]
