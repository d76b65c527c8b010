"""Shared helpers: run a program to completion through faults, the way a server would."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

from robots.adapters import TERMINAL_STATES, ExecState, Outcome, RobotLink, Streamer, StreamFault
from robots.protocol import JointMove, LiftArm, Nozzle, Program, SetMagnet, Stop, WheelSpeeds

STOPPED = TERMINAL_STATES | {ExecState.INTERRUPTED, ExecState.FAULTED}


def generic_program(n_moves: int = 24, step_s: float = 0.1) -> Program:
    """Every command kind the generic robot has, mostly timed way-points."""
    cmds: list = []
    for k in range(n_moves):
        a = 0.02 * (k + 1)
        cmds.append(JointMove((a, -a, a, 0.0, a, 0.0), step_s))
        if k == 2:
            cmds += [Nozzle(True), SetMagnet(0, True), WheelSpeeds((0.1, 0.1), step_s)]
        if k == n_moves // 2:
            cmds += [LiftArm(0.5, step_s), Stop(), Nozzle(False), SetMagnet(0, False)]
    return Program(tuple(cmds), robot="generic")


@dataclass
class Run:
    """What a dispatch engine would have persisted."""

    acked: list[int] = field(default_factory=list)
    faults: list[StreamFault] = field(default_factory=list)
    outcomes: list[Outcome] = field(default_factory=list)
    streamers: int = 0
    resumes_in_place: int = 0

    def on_ack(self, index: int) -> None:
        # A persisted ack must be exactly the next index: no gap, no repeat.
        expected = self.acked[-1] + 1 if self.acked else index
        assert index == expected, f"on_ack({index}) after {self.acked[-3:]}"
        self.acked.append(index)


def run_to_completion(
    link: RobotLink,
    program: Program,
    run_id: int,
    *,
    timeout: float = 40.0,
    max_resumes: int = 25,
    window: int = 8,
) -> Run:
    """Stream ``program``, resuming after every interruption or fault until it completes.

    Alternates the two resume paths a server has: ``Streamer.resume()`` in place,
    and a new streamer from the persisted index (as after a server restart).
    """
    run = Run()
    deadline = time.monotonic() + timeout
    start = 0
    while True:
        streamer = Streamer(
            program,
            link,
            run_id=run_id,
            start=start,
            on_ack=run.on_ack,
            on_fault=run.faults.append,
            on_done=run.outcomes.append,
            window=window,
            # Operator decision after a robot fault: clear it when starting again.
            clear_robot_faults=bool(run.faults),
        )
        run.streamers += 1
        with streamer:
            while True:
                state = streamer.wait(STOPPED, timeout=max(0.0, deadline - time.monotonic()))
                assert state is not None, f"timed out; faults so far: {run.faults}"
                if state in TERMINAL_STATES:
                    assert state == ExecState.COMPLETED, (state, run.faults)
                    assert run.outcomes == [Outcome.COMPLETED]
                    return run
                assert len(run.faults) <= max_resumes, f"too many faults: {run.faults}"
                if len(run.faults) % 2 == 1:
                    run.resumes_in_place += 1
                    streamer.resume(clear_robot_faults=True)
                    streamer.wait({ExecState.PENDING, ExecState.RUNNING, *TERMINAL_STATES}, 5)
                    continue
                break
        start = run.acked[-1] + 1 if run.acked else 0
