"""Which server runs each plan's planning job: ``plans.planner``.

Several servers may share one store, each with its own job runner (a local
pool, or a Dask client following its own tasks).  A plan waiting or being
planned belongs to the server that submitted it, named in ``plans.planner``;
no other server touches it while that server's heartbeat (``servers``) is
fresh.  When it goes silent, one other server *adopts* the plan with a
conditional UPDATE from the old owner to itself — so of several servers
sweeping at once exactly one wins — and plans it again.

A plan with no ``planner`` (written before migration 11, or created straight
in the store) belongs to whichever server adopts it first.  Plain portable SQL
only (``?`` placeholders): the PostgreSQL store runs it unchanged.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from server.lifecycle import PlanState

#: The states in which a plan has a planning job (waiting or running).
ACTIVE = (PlanState.QUEUED, PlanState.PLANNING)


@dataclass(frozen=True)
class ActivePlan:
    """A plan with a planning job, and the server that runs it."""

    id: str
    state: str
    planner: str | None


class PlanOwnerStore:
    """The ``plans.planner`` column, on any database with the store's interface."""

    def __init__(self, db: Any) -> None:
        self.db = db

    def assign(self, plan_id: str, server_id: str) -> None:
        """Record that ``server_id`` runs ``plan_id``'s job (at submission)."""
        with self.db.transaction() as conn:
            conn.execute("UPDATE plans SET planner = ? WHERE id = ?", (server_id, plan_id))

    def active(self) -> list[ActivePlan]:
        """Every plan queued or planning, oldest first, with its planner."""
        rows = self.db.query(
            "SELECT id, state, planner FROM plans WHERE state IN (?, ?) ORDER BY created_at",
            ACTIVE,
        )
        return [ActivePlan(r["id"], r["state"], r["planner"]) for r in rows]

    def orphans(self, server_id: str, live: Iterable[str]) -> list[ActivePlan]:
        """Active plans whose planner is neither ``server_id`` nor a live server."""
        alive = {server_id, *live}
        return [p for p in self.active() if p.planner is None or p.planner not in alive]

    def adopt(self, plan: ActivePlan, server_id: str) -> bool:
        """Take ``plan`` over from its (dead) planner; ``False`` if anything changed
        since it was read (another server adopted it first, or it ended)."""
        owner = "planner IS NULL" if plan.planner is None else "planner = ?"
        args: tuple[Any, ...] = (server_id, plan.id, plan.state)
        if plan.planner is not None:
            args = (*args, plan.planner)
        with self.db.transaction() as conn:
            cur = conn.execute(
                f"UPDATE plans SET planner = ? WHERE id = ? AND state = ? AND {owner}", args
            )
            return int(cur.rowcount or 0) == 1
