"""Typed rows of the store."""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from datetime import datetime
from typing import Any

import numpy as np

from server.store.database import RowLike


def _loads(text: str | None, default: Any) -> Any:
    return default if text is None else json.loads(text)


@dataclass
class CloudRecord:
    id: str
    name: str
    source: str
    n_points: int
    bounds: dict[str, list[float]]
    dropped: int
    array_file: str
    created_at: str
    created_by: str
    survey: dict[str, Any] = field(default_factory=dict)
    #: The upload's coordinate reference system as WKT (None: the file named none).
    crs_wkt: str | None = None
    #: Per-point attribute name → its array file (relative name, beside the points).
    attributes: dict[str, str] = field(default_factory=dict)

    @classmethod
    def from_row(cls, row: RowLike) -> CloudRecord:
        d = dict(row)
        d["bounds"] = json.loads(d["bounds"])
        d["survey"] = _loads(d.get("survey"), {})
        d["attributes"] = _loads(d.get("attributes"), {})
        return cls(**d)

    def public(self) -> dict[str, Any]:
        return {
            "id": self.id,
            "name": self.name,
            "source": self.source,
            "n_points": self.n_points,
            "bounds": self.bounds,
            "dropped_nonfinite": self.dropped,
            "survey": self.survey,
            "attributes": list(self.attributes),
            "crs_wkt": self.crs_wkt,
            "created_at": self.created_at,
            "created_by": self.created_by,
        }


@dataclass
class PlanRecord:
    """A stored plan; ``array(name)`` loads one of its stored arrays."""

    id: str
    kind: str
    state: str
    params: dict[str, Any]
    parent_id: str | None
    progress: float
    stage: str
    result: dict[str, Any]
    metrics: dict[str, float]
    checks: list[dict[str, Any]]
    arrays: dict[str, str]
    error: str | None
    created_at: str
    updated_at: str
    created_by: str
    approved_by: str | None
    approved_at: str | None
    program: list[dict[str, Any]] | None = None
    #: In a summary listing (no program loaded): how many commands it has.
    program_length_hint: int | None = None
    #: Times a planning job started on this plan (a second start is a re-run
    #: after a worker died), whether a cancel was asked, and where it ran.
    attempts: int = 0
    cancel_requested: int = 0
    worker: str | None = None
    #: The server whose job runner plans it (``server/store/plan_owners.py``).
    planner: str | None = None
    _loader: Any = field(default=None, repr=False, compare=False)

    @classmethod
    def from_row(cls, row: RowLike, loader: Any = None) -> PlanRecord:
        return cls.from_mapping(dict(row), loader)

    @classmethod
    def from_mapping(cls, d: dict[str, Any], loader: Any = None) -> PlanRecord:
        d["params"] = json.loads(d["params"])
        d["result"] = _loads(d["result"], {})
        d["metrics"] = _loads(d["metrics"], {})
        d["checks"] = _loads(d["checks"], [])
        d["arrays"] = _loads(d["arrays"], {})
        d["program"] = _loads(d.get("program"), None)
        return cls(**d, _loader=loader)

    @staticmethod
    def summary_json(row: RowLike | dict[str, Any]) -> str:
        """``public(include_result=False)`` of a summary row as JSON text, with
        ``params``, ``metrics`` and ``checks`` spliced in as stored (strict
        JSON written by the store): a listing decodes none of them."""
        from server.lifecycle import allowed_actions

        d = dict(row)
        arrays = _loads(d["arrays"], {})
        head = {
            "id": d["id"],
            "kind": d["kind"],
            "state": d["state"],
            "progress": d["progress"],
            "stage": d["stage"],
            "parent_id": d["parent_id"],
            "error": d["error"],
            "created_at": d["created_at"],
            "updated_at": d["updated_at"],
            "created_by": d["created_by"],
            "approved_by": d["approved_by"],
            "approved_at": d["approved_at"],
            "allowed_actions": allowed_actions(d["state"]),
            "arrays": {k: f"/api/v1/plans/{d['id']}/arrays/{k}" for k in sorted(arrays)},
            "program_length": d["program_length_hint"],
        }
        text = json.dumps(head, allow_nan=False, separators=(",", ":"))
        raw = ",".join(
            f'"{key}":{d[key] if d[key] is not None else default}'
            for key, default in (("params", "{}"), ("metrics", "{}"), ("checks", "[]"))
        )
        return f"{text[:-1]},{raw}}}"

    def array(self, name: str) -> np.ndarray:
        if name not in self.arrays:
            raise KeyError(f"plan {self.id} has no array {name!r}; it has {sorted(self.arrays)}")
        return self._loader(self.arrays[name])

    @property
    def failed_checks(self) -> list[dict[str, Any]]:
        return [c for c in self.checks if not c.get("passed")]

    def public(self, *, include_result: bool = True) -> dict[str, Any]:
        from server.lifecycle import allowed_actions

        out: dict[str, Any] = {
            "id": self.id,
            "kind": self.kind,
            "state": self.state,
            "progress": self.progress,
            "stage": self.stage,
            "params": self.params,
            "parent_id": self.parent_id,
            "metrics": self.metrics,
            "checks": self.checks,
            "error": self.error,
            "created_at": self.created_at,
            "updated_at": self.updated_at,
            "created_by": self.created_by,
            "approved_by": self.approved_by,
            "approved_at": self.approved_at,
            "allowed_actions": allowed_actions(self.state),
            "arrays": {k: f"/api/v1/plans/{self.id}/arrays/{k}" for k in sorted(self.arrays)},
            "program_length": (
                self.program_length_hint if self.program is None else len(self.program)
            ),
        }
        if include_result:
            out["result"] = self.result
            out["program"] = self.program
        return out


@dataclass
class ExecutionRecord:
    id: str
    plan_id: str
    robot: str
    state: str
    acked: int
    total: int
    error: str | None
    created_at: str
    updated_at: str
    created_by: str
    run_id: int = 0
    fault: str | None = None

    @classmethod
    def from_row(cls, row: RowLike) -> ExecutionRecord:
        return cls(**dict(row))

    def public(self) -> dict[str, Any]:
        from server.lifecycle import execution_allowed_actions

        d = {k: getattr(self, k) for k in self.__dataclass_fields__}
        d["progress"] = (self.acked / self.total) if self.total else 0.0
        d["allowed_actions"] = execution_allowed_actions(self.state)
        return d


@dataclass
class AuditEvent:
    id: int
    ts: str
    actor: str
    entity: str
    entity_id: str
    action: str
    from_state: str | None
    to_state: str | None
    reason: str

    @classmethod
    def from_row(cls, row: RowLike) -> AuditEvent:
        return cls(**dict(row))

    def public(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


@dataclass
class TokenRecord:
    """A bearer token's row; ``expires_at`` (ISO-8601 UTC) is ``None`` for no expiry."""

    id: str
    name: str
    role: str
    hash: str
    created_at: str
    revoked_at: str | None
    expires_at: str | None = None

    @classmethod
    def from_row(cls, row: RowLike) -> TokenRecord:
        return cls(**dict(row))

    @property
    def expires_ts(self) -> float | None:
        """Expiry as a Unix timestamp (``None``: never expires)."""
        if self.expires_at is None:
            return None
        return datetime.fromisoformat(self.expires_at).timestamp()

    def expired(self, now: float | None = None) -> bool:
        ts = self.expires_ts
        return ts is not None and (time.time() if now is None else now) >= ts

    def public(self) -> dict[str, Any]:
        return {
            "id": self.id,
            "name": self.name,
            "role": self.role,
            "created_at": self.created_at,
            "revoked_at": self.revoked_at,
            "expires_at": self.expires_at,
            "expired": self.expired(),
        }
