"""Scene interactions as proposals: bounded, rate-limited, confirmed over REST.

Nothing that arrives through viser (vertex clicks, surface picks…) creates a
plan by itself (DESIGN §8, §10).  A scene interaction becomes a *proposal* —
"a new revision of plan P with params patched by X" — kept here in memory.
An authenticated operator lists it and accepts it (which submits the plan
through the same ``submit_plan`` path a REST client uses, as that operator)
or dismisses it.

Limits, so a flood of clicks cannot grow memory or bury the operator:

- per scene client, at most one proposal every ``min_interval_s`` (1 s);
- across all clients, at most one every ``global_interval_s`` (0.2 s), since
  a client can reconnect under a new id;
- at most ``max_pending`` (20) pending; pending ones lapse after ``ttl_s``
  (15 min) and decided ones are kept only up to ``max_kept`` (100).

Excess proposals are dropped with a log line.  All methods are thread-safe:
proposals arrive on viser's callback threads and are decided on FastAPI's.
"""

from __future__ import annotations

import logging
import secrets
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

from server.store import NotFoundError

log = logging.getLogger(__name__)

PENDING = "pending"
ACCEPTING = "accepting"  # an accept is submitting the plan: a second accept must wait
ACCEPTED = "accepted"
DISMISSED = "dismissed"
LAPSED = "lapsed"
STATES = (PENDING, ACCEPTING, ACCEPTED, DISMISSED, LAPSED)


class ProposalDecidedError(Exception):
    """The proposal is no longer pending; ``state`` says what happened to it."""

    def __init__(self, proposal_id: str, state: str) -> None:
        super().__init__(f"proposal {proposal_id} is {state}, not pending")
        self.state = state


def _iso(ts: float) -> str:
    return datetime.fromtimestamp(ts, UTC).isoformat(timespec="milliseconds")


@dataclass
class Proposal:
    id: str
    plan_id: str  # the plan it derives from
    kind: str
    patch: dict[str, Any]
    source: str  # which scene client, for the operator to judge
    created: float  # Unix time
    state: str = PENDING
    decided_by: str | None = None
    decided_at: float | None = None
    result_plan_id: str | None = None
    #: ``revise``: a new revision of ``plan_id`` with ``patch``; ``finding``:
    #: a finding at the place in ``patch`` (:mod:`server.scene.finding_pick`).
    action: str = "revise"
    result_finding_id: str | None = None
    _mono: float = field(default=0.0, repr=False)

    def public(self) -> dict[str, Any]:
        return {
            "id": self.id,
            "plan_id": self.plan_id,
            "kind": self.kind,
            "patch": self.patch,
            "source": self.source,
            "created_at": _iso(self.created),
            "state": self.state,
            "decided_by": self.decided_by,
            "decided_at": None if self.decided_at is None else _iso(self.decided_at),
            "result_plan_id": self.result_plan_id,
            "action": self.action,
            "result_finding_id": self.result_finding_id,
        }


class ProposalBook:
    def __init__(
        self,
        *,
        min_interval_s: float = 1.0,
        global_interval_s: float = 0.2,
        max_pending: int = 20,
        max_kept: int = 100,
        ttl_s: float = 900.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.min_interval_s = min_interval_s
        self.global_interval_s = global_interval_s
        self.max_pending = max_pending
        self.max_kept = max_kept
        self.ttl_s = ttl_s
        self._clock = clock
        self._lock = threading.Lock()
        self._items: OrderedDict[str, Proposal] = OrderedDict()
        self._last_by_client: dict[Any, float] = {}
        self._last_any = float("-inf")
        self.dropped = 0

    # ---------------------------------------------------------------- intake
    def propose(
        self,
        plan_id: str,
        kind: str,
        patch: dict[str, Any],
        *,
        client: Any,
        source: str,
        action: str = "revise",
    ) -> Proposal | None:
        """Record a proposal, or drop it (``None``, logged) when over a limit."""
        now = self._clock()
        with self._lock:
            self._expire(now)
            last = self._last_by_client.get(client, float("-inf"))
            why = None
            if now - last < self.min_interval_s:
                why = f"{source} proposed again within {self.min_interval_s:g} s"
            elif now - self._last_any < self.global_interval_s:
                why = f"scene proposals arrive faster than one per {self.global_interval_s:g} s"
            elif self._count(PENDING, ACCEPTING) >= self.max_pending:
                why = f"{self.max_pending} proposals already pending"
            if why is not None:
                self.dropped += 1
                log.warning("scene proposal dropped (%s): plan %s patch %s", why, plan_id, patch)
                return None
            self._last_by_client[client] = now
            if len(self._last_by_client) > 4 * self.max_kept:  # ids of long-gone clients
                self._last_by_client = {client: now}
            self._last_any = now
            p = Proposal(
                id=f"pr_{secrets.token_hex(6)}",
                plan_id=plan_id,
                kind=kind,
                patch=dict(patch),
                source=source,
                created=time.time(),
                action=action,
                _mono=now,
            )
            self._items[p.id] = p
            self._prune()
            log.info("scene proposal %s from %s: plan %s patch %s", p.id, source, plan_id, patch)
            return p

    # ----------------------------------------------------------------- reads
    def list(self, state: str | None = None) -> list[Proposal]:
        """Newest first; ``state`` filters (``pending`` includes none being accepted)."""
        with self._lock:
            self._expire(self._clock())
            items = [p for p in self._items.values() if state is None or p.state == state]
        return items[::-1]

    def get(self, proposal_id: str) -> Proposal:
        with self._lock:
            self._expire(self._clock())
            p = self._items.get(proposal_id)
        if p is None:
            raise NotFoundError(f"no scene proposal with id {proposal_id!r}")
        return p

    # ------------------------------------------------------------- decisions
    def begin_accept(self, proposal_id: str) -> Proposal:
        """Mark it being accepted (so a concurrent accept gets 409) and return it."""
        with self._lock:
            p = self._pending(proposal_id)
            p.state = ACCEPTING
            return p

    def finish_accept(
        self, proposal_id: str, plan_id: str | None, actor: str, *, finding_id: str | None = None
    ) -> Proposal:
        with self._lock:
            p = self._items[proposal_id]
            p.state, p.result_plan_id, p.result_finding_id = ACCEPTED, plan_id, finding_id
            p.decided_by, p.decided_at = actor, time.time()
            return p

    def abort_accept(self, proposal_id: str) -> None:
        """The plan could not be submitted: the proposal is pending again."""
        with self._lock:
            p = self._items.get(proposal_id)
            if p is not None and p.state == ACCEPTING:
                p.state = PENDING

    def dismiss(self, proposal_id: str, actor: str) -> Proposal:
        with self._lock:
            p = self._pending(proposal_id)
            p.state, p.decided_by, p.decided_at = DISMISSED, actor, time.time()
            return p

    # -------------------------------------------------------------- internal
    def _pending(self, proposal_id: str) -> Proposal:
        self._expire(self._clock())
        p = self._items.get(proposal_id)
        if p is None:
            raise NotFoundError(f"no scene proposal with id {proposal_id!r}")
        if p.state != PENDING:
            raise ProposalDecidedError(proposal_id, p.state)
        return p

    def _count(self, *states: str) -> int:
        return sum(1 for p in self._items.values() if p.state in states)

    def _expire(self, now: float) -> None:
        for p in self._items.values():
            if p.state == PENDING and now - p._mono > self.ttl_s:
                p.state, p.decided_by, p.decided_at = LAPSED, "system", time.time()

    def _prune(self) -> None:
        # Forget the oldest *decided* proposals first; pending ones are capped above.
        excess = len(self._items) - self.max_kept
        for pid in [pid for pid, p in self._items.items() if p.state not in (PENDING, ACCEPTING)]:
            if excess <= 0:
                break
            del self._items[pid]
            excess -= 1
