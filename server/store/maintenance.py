"""Maintenance plans made from a finding, and what their runs achieved.

One row per plan made by ``POST /findings/{id}/plan``: which finding, which
kind, who and when.  When an execution of such a plan ends, its outcome is
written here (:class:`server.maintenance.OutcomeRecorder`): the execution,
its final state, the blast spots whose way-points the robot acknowledged,
and — for a completed blast run — the coverage the planner measured for
those spots; a completed run also asks the operator for a new condition
state (``review_requested_at``), which the finding's next condition-state
edit answers (``reviewed_at``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from server.store.database import RowLike, StoreDatabase, utcnow


@dataclass(frozen=True)
class MaintenanceLink:
    plan_id: str
    finding_id: str
    kind: str
    created_by: str
    created_at: str
    execution_id: str | None
    outcome: str | None
    coverage_pct: float | None
    spots_done: int | None
    spots_planned: int | None
    review_requested_at: str | None
    reviewed_at: str | None

    @classmethod
    def from_row(cls, r: RowLike) -> MaintenanceLink:
        return cls(**dict(r))

    @property
    def awaiting_review(self) -> bool:
        return self.review_requested_at is not None and self.reviewed_at is None


class MaintenanceStore:
    """The ``finding_plans`` table over the service's :class:`Database`."""

    def __init__(self, db: StoreDatabase) -> None:
        self.db = db

    def link(self, finding_id: str, plan_id: str, kind: str, actor: str) -> None:
        with self.db.transaction() as conn:
            conn.execute(
                "INSERT INTO finding_plans (plan_id, finding_id, kind, created_by, created_at) "
                "VALUES (?,?,?,?,?)",
                (plan_id, finding_id, kind, actor, utcnow()),
            )
            conn.execute(
                "INSERT INTO audit_events (ts, actor, entity, entity_id, action, reason) "
                "VALUES (?,?,?,?,?,?)",
                (utcnow(), actor, "finding", finding_id, "plan", f"{kind} plan {plan_id}"),
            )

    def of_finding(self, finding_id: str) -> list[MaintenanceLink]:
        rows = self.db.query(
            "SELECT * FROM finding_plans WHERE finding_id = ? ORDER BY created_at, rowid",
            (finding_id,),
        )
        return [MaintenanceLink.from_row(r) for r in rows]

    def of_plan(self, plan_id: str) -> MaintenanceLink | None:
        r = self.db.query_one("SELECT * FROM finding_plans WHERE plan_id = ?", (plan_id,))
        return None if r is None else MaintenanceLink.from_row(r)

    def unrecorded(self) -> list[tuple[str, str]]:
        """(plan, newest execution) pairs whose ended execution has no outcome yet."""
        rows = self.db.query(
            "SELECT l.plan_id, e.id AS execution_id FROM finding_plans l "
            "JOIN executions e ON e.plan_id = l.plan_id "
            "WHERE e.state IN ('completed', 'aborted', 'faulted', 'interrupted') "
            "AND (l.execution_id IS NULL OR l.execution_id != e.id) "
            "ORDER BY e.created_at"
        )
        return [(str(r["plan_id"]), str(r["execution_id"])) for r in rows]

    def record_outcome(
        self, plan_id: str, fields: dict[str, Any], finding_id: str, why: str
    ) -> None:
        cols = ", ".join(f"{k} = ?" for k in fields)
        with self.db.transaction() as conn:
            conn.execute(
                f"UPDATE finding_plans SET {cols} WHERE plan_id = ?", (*fields.values(), plan_id)
            )
            conn.execute(
                "INSERT INTO audit_events (ts, actor, entity, entity_id, action, reason) "
                "VALUES (?,?,?,?,?,?)",
                (utcnow(), "system", "finding", finding_id, "maintenance", why[:2000]),
            )

    def reviewed(self, finding_id: str) -> None:
        """The finding's condition state was set again: pending requests are answered."""
        with self.db.transaction() as conn:
            conn.execute(
                "UPDATE finding_plans SET reviewed_at = ? "
                "WHERE finding_id = ? AND review_requested_at IS NOT NULL AND reviewed_at IS NULL",
                (utcnow(), finding_id),
            )
