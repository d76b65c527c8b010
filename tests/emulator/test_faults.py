"""Fault matrix over TCP and a pty: after every injected fault (and a reconnect where
the fault breaks the link), the run resumes from the last acknowledged command and
the emulator's execution log shows every command completed exactly once, in order."""

from __future__ import annotations

import pytest

from robots.adapters import FaultKind, RobotLink
from robots.emulator import Emulator, FaultConfig, check_exactly_once

from .helpers import Run, generic_program, link_config

FAULTS: dict[str, FaultConfig] = {
    "none": FaultConfig(),
    # pty: silence longer than the host link timeout (1 s), so the host notices too.
    "drop": FaultConfig(drop_after_frames=12, drop_times=2, drop_for_s=1.3),
    "corrupt": FaultConfig(corrupt_rate=0.003, seed=3),
    # Round trip 0.3 s > the 0.25 s ACK timeout: every frame is retransmitted at
    # least once, so the robot sees duplicates it must not execute twice.
    "delay": FaultConfig(delay_s=0.15),
    "nak": FaultConfig(nak_index=5, nak_times=2),
    "reject": FaultConfig(nak_index=7, nak_permanent=True),
    "robot_fault": FaultConfig(fault_at_index=9, fault_code=42),
}


def check_evidence(name: str, emu: Emulator, link: RobotLink, run: Run) -> None:
    """The fault really happened and was handled the way it should be."""
    kinds = [f.kind for f in run.faults]
    link_stats = link.status().stats
    robot = emu.robot.counters
    if name == "none":
        assert kinds == []
    elif name == "drop":
        assert emu.stats["drops"] == 2 and FaultKind.LINK_LOST in kinds
        assert link.session >= 2
    elif name == "corrupt":
        assert emu.stats["bytes_corrupted"] > 0
        assert link_stats.get("frames_corrupt", 0) + emu.stats["frames_corrupt"] > 0
    elif name == "delay":
        assert link_stats["retransmits"] > 0 and robot["duplicates"] > 0
    elif name == "nak":
        assert robot["injected_naks"] == 2 and kinds == []  # recovered by retransmission
    elif name == "reject":
        assert kinds[0] == FaultKind.REJECTED and run.faults[0].index == 7
    elif name == "robot_fault":
        # One fault, not two: a resume with a clear removes it whichever of the
        # robot's report (with the code) and its refusal of a queued command
        # (with the fault bits, "FAULTED (detail 8)") reached the host first.
        assert kinds == [FaultKind.ROBOT_FAULT], run.faults
        message = run.faults[0].message
        assert "robot fault code 42" in message or "FAULTED (detail 8)" in message
        interrupted = [r for r in emu.execution_log() if r.outcome == "interrupted"]
        assert [(r.index, r.reason) for r in interrupted][:1] == [(9, "fault")]


@pytest.mark.parametrize("transport", ["tcp", "pty"])
@pytest.mark.parametrize("fault", list(FAULTS))
def test_fault_matrix_nothing_lost_nothing_twice(transport: str, fault: str) -> None:
    from .helpers import run_to_completion

    program = generic_program()
    run_id = 1000 + list(FAULTS).index(fault)
    kw = {"listen": None, "pty": True} if transport == "pty" else {}
    with Emulator("generic", faults=FAULTS[fault], time_scale=4, **kw) as emu:
        url = emu.pty_path if transport == "pty" else emu.url
        with RobotLink(url, link_config(emu)) as link:
            run = run_to_completion(link, program, run_id)
            with emu._lock:
                check_evidence(fault, emu, link, run)
        assert run.acked == list(range(len(program)))
        problems = check_exactly_once(emu.execution_log(), run_id, len(program))
        assert problems == [], problems


def test_received_bytes_are_corrupted_the_same_whatever_is_sent_between() -> None:
    """The corruption of received bytes depends on the seed and those bytes
    alone: frames sent in between (whose number depends on timing) do not
    shift it.  One shared stream let a short run see no corrupted frame at the
    robot in one CI run out of many."""
    faults = FaultConfig(corrupt_rate=0.05, seed=7)
    received = [bytes(range(40 + i)) for i in range(30)]
    with Emulator("generic", faults=faults) as quiet, Emulator("generic", faults=faults) as busy:
        alone = [quiet._corrupt(chunk, "rx") for chunk in received]
        between = []
        for i, chunk in enumerate(received):
            for _ in range(i % 3):
                busy._corrupt(bytes(64), "tx")
            between.append(busy._corrupt(chunk, "rx"))
    assert between == alone
    assert alone != received  # the rate is high enough that some byte changed
