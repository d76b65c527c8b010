"""The plan and execution state machines (DESIGN §4).

One table of ``(state, action) → next state`` per entity.  Every change of
state goes through :func:`next_state`, and the store records each as an
audit event in the same transaction, so the audit trail and the state can
never disagree.

Plan::

    queued → planning → planned ─┬─► approved → executing → completed
         ↘        ├─► failed     └─► rejected (a check failed)   ├─► paused ⇄ executing
       cancelled  └─► cancelled                                  ├─► aborted
                                                                 └─► faulted / interrupted

``cancelled`` extends DESIGN §4: an operator's cancel of a queued or running
planning job is neither a planner failure nor a failed check.

``archived`` is the state of a plan imported from another
server's export (:mod:`server.archive`): read-only history, with no
transition out of it — it can be read, deleted or revised (a revision is a
new plan, planned, checked and approved here), never approved or dispatched.
"""

from __future__ import annotations

from enum import StrEnum


class PlanState(StrEnum):
    QUEUED = "queued"
    PLANNING = "planning"
    PLANNED = "planned"
    FAILED = "failed"
    REJECTED = "rejected"
    CANCELLED = "cancelled"
    APPROVED = "approved"
    EXECUTING = "executing"
    PAUSED = "paused"
    COMPLETED = "completed"
    ABORTED = "aborted"
    FAULTED = "faulted"
    INTERRUPTED = "interrupted"
    ARCHIVED = "archived"


S = PlanState

#: (state, action) → next state.  Actions that an operator may take through
#: the API are in :data:`OPERATOR_ACTIONS`; the rest are taken by the system.
PLAN_TRANSITIONS: dict[tuple[PlanState, str], PlanState] = {
    (S.QUEUED, "start"): S.PLANNING,
    (S.QUEUED, "cancel"): S.CANCELLED,
    (S.QUEUED, "fail"): S.FAILED,
    (S.PLANNING, "finish"): S.PLANNED,
    (S.PLANNING, "reject"): S.REJECTED,
    (S.PLANNING, "fail"): S.FAILED,
    (S.PLANNING, "cancel"): S.CANCELLED,
    (S.PLANNING, "requeue"): S.QUEUED,
    (S.PLANNED, "approve"): S.APPROVED,
    (S.APPROVED, "dispatch"): S.EXECUTING,
    (S.EXECUTING, "pause"): S.PAUSED,
    (S.EXECUTING, "complete"): S.COMPLETED,
    (S.EXECUTING, "abort"): S.ABORTED,
    (S.EXECUTING, "fault"): S.FAULTED,
    (S.EXECUTING, "interrupt"): S.INTERRUPTED,
    (S.PAUSED, "resume"): S.EXECUTING,
    (S.PAUSED, "abort"): S.ABORTED,
    (S.PAUSED, "fault"): S.FAULTED,
    (S.PAUSED, "interrupt"): S.INTERRUPTED,
    (S.INTERRUPTED, "resume"): S.EXECUTING,
    (S.INTERRUPTED, "abort"): S.ABORTED,
    (S.FAULTED, "resume"): S.EXECUTING,
    (S.FAULTED, "abort"): S.ABORTED,
}

OPERATOR_ACTIONS = frozenset(
    {"cancel", "approve", "dispatch", "pause", "resume", "abort", "delete", "revise"}
)

#: States in which the plan may be deleted (nothing is moving or about to).
DELETABLE = frozenset(
    {
        S.PLANNED,
        S.FAILED,
        S.REJECTED,
        S.CANCELLED,
        S.APPROVED,
        S.COMPLETED,
        S.ABORTED,
        S.FAULTED,
        S.ARCHIVED,
    }
)

#: States of a plan whose robot motion is under way or may resume.
ACTIVE_EXECUTION = frozenset({S.EXECUTING, S.PAUSED, S.INTERRUPTED, S.FAULTED})

TERMINAL = frozenset({S.FAILED, S.REJECTED, S.CANCELLED, S.COMPLETED, S.ABORTED, S.ARCHIVED})


class IllegalTransitionError(Exception):
    """``action`` is not allowed in ``state``; carries what is allowed instead."""

    def __init__(self, entity: str, entity_id: str, state: str, action: str, allowed: list[str]):
        self.entity = entity
        self.entity_id = entity_id
        self.state = state
        self.action = action
        self.allowed = allowed
        allowed_txt = ", ".join(allowed) if allowed else "none"
        super().__init__(
            f"cannot {action} {entity} {entity_id}: it is {state}; allowed actions: {allowed_txt}"
        )


def allowed_actions(state: str) -> list[str]:
    """Operator actions possible in ``state`` (for 409 messages and the console)."""
    st = PlanState(state)
    acts = sorted({a for (s, a) in PLAN_TRANSITIONS if s == st and a in OPERATOR_ACTIONS})
    if st in DELETABLE:
        acts.append("delete")
    acts.append("revise")  # a revision is a new plan, possible from any state
    return acts


def next_state(entity_id: str, state: str, action: str) -> PlanState:
    """The state after ``action``, or :class:`IllegalTransitionError`."""
    try:
        return PLAN_TRANSITIONS[(PlanState(state), action)]
    except KeyError:
        raise IllegalTransitionError(
            "plan", entity_id, state, action, allowed_actions(state)
        ) from None


class ExecutionState(StrEnum):
    PENDING = "pending"
    RUNNING = "running"
    PAUSED = "paused"
    COMPLETED = "completed"
    ABORTED = "aborted"
    FAULTED = "faulted"
    INTERRUPTED = "interrupted"


E = ExecutionState

EXECUTION_TRANSITIONS: dict[tuple[ExecutionState, str], ExecutionState] = {
    (E.PENDING, "start"): E.RUNNING,
    (E.PENDING, "abort"): E.ABORTED,
    (E.PENDING, "interrupt"): E.INTERRUPTED,
    (E.PENDING, "fault"): E.FAULTED,
    (E.RUNNING, "pause"): E.PAUSED,
    (E.RUNNING, "complete"): E.COMPLETED,
    (E.RUNNING, "abort"): E.ABORTED,
    (E.RUNNING, "fault"): E.FAULTED,
    (E.RUNNING, "interrupt"): E.INTERRUPTED,
    (E.PAUSED, "resume"): E.RUNNING,
    (E.PAUSED, "abort"): E.ABORTED,
    (E.PAUSED, "fault"): E.FAULTED,
    (E.PAUSED, "interrupt"): E.INTERRUPTED,
    (E.INTERRUPTED, "resume"): E.RUNNING,
    (E.INTERRUPTED, "abort"): E.ABORTED,
    (E.FAULTED, "resume"): E.RUNNING,
    (E.FAULTED, "abort"): E.ABORTED,
}


def execution_allowed_actions(state: str) -> list[str]:
    st = ExecutionState(state)
    return sorted({a for (s, a) in EXECUTION_TRANSITIONS if s == st and a in OPERATOR_ACTIONS})


def next_execution_state(entity_id: str, state: str, action: str) -> ExecutionState:
    try:
        return EXECUTION_TRANSITIONS[(ExecutionState(state), action)]
    except KeyError:
        raise IllegalTransitionError(
            "execution", entity_id, state, action, execution_allowed_actions(state)
        ) from None
