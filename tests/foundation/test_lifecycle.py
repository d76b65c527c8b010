"""The plan/execution state machines (DESIGN §4)."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from server.lifecycle import (
    EXECUTION_TRANSITIONS,
    PLAN_TRANSITIONS,
    IllegalTransitionError,
    PlanState,
    allowed_actions,
    next_execution_state,
    next_state,
)

ALL_ACTIONS = sorted({a for _, a in PLAN_TRANSITIONS})


def test_design_paths_exist() -> None:
    path = ["start", "finish", "approve", "dispatch", "pause", "resume", "complete"]
    s = PlanState.QUEUED
    for action in path:
        s = next_state("p", s, action)
    assert s == PlanState.COMPLETED
    assert next_state("p", "planning", "reject") == PlanState.REJECTED
    assert next_state("p", "planning", "fail") == PlanState.FAILED
    assert next_state("p", "executing", "interrupt") == PlanState.INTERRUPTED
    assert next_state("p", "interrupted", "resume") == PlanState.EXECUTING


def test_approval_only_from_planned() -> None:
    for s in PlanState:
        if s == PlanState.PLANNED:
            assert next_state("p", s, "approve") == PlanState.APPROVED
        else:
            with pytest.raises(IllegalTransitionError):
                next_state("p", s, "approve")


def test_illegal_transition_names_state_and_allowed() -> None:
    with pytest.raises(IllegalTransitionError) as ei:
        next_state("pl_1", "rejected", "approve")
    err = ei.value
    assert err.state == "rejected"
    assert "rejected" in str(err) and "approve" in str(err)
    assert set(err.allowed) == {"delete", "revise"}


def test_terminal_states_allow_no_transition() -> None:
    for s in (PlanState.COMPLETED, PlanState.ABORTED, PlanState.FAILED, PlanState.CANCELLED):
        assert not [a for (st_, a) in PLAN_TRANSITIONS if st_ == s]


@given(st.lists(st.sampled_from(ALL_ACTIONS), max_size=30))
def test_random_action_sequences_follow_the_table(actions: list[str]) -> None:
    s = PlanState.QUEUED
    for a in actions:
        if (s, a) in PLAN_TRANSITIONS:
            s = next_state("p", s, a)
        else:
            with pytest.raises(IllegalTransitionError) as ei:
                next_state("p", s, a)
            assert a not in [x for x in ei.value.allowed if (s, x) in PLAN_TRANSITIONS]
    # Operator-visible allowed actions are all legal in the final state.
    for a in allowed_actions(s):
        if a not in ("delete", "revise"):
            assert (s, a) in PLAN_TRANSITIONS


def test_execution_machine() -> None:
    s = "pending"
    for a in ("start", "pause", "resume", "interrupt", "resume", "complete"):
        s = next_execution_state("e", s, a)
    assert s == "completed"
    with pytest.raises(IllegalTransitionError):
        next_execution_state("e", "completed", "resume")
    assert ("completed", "abort") not in {(str(a), b) for a, b in EXECUTION_TRANSITIONS}
