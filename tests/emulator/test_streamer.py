"""Streamer: completion callbacks, pause/resume/abort, resume points, refusals."""

from __future__ import annotations

import threading

import pytest

from robots.adapters import ExecState, FaultKind, Outcome, RobotLink, Streamer
from robots.emulator import Emulator, check_exactly_once
from robots.protocol import JointMove, Mode, Nozzle, Program

from .helpers import STOPPED, generic_program, link_config


def moves(n: int, step_s: float = 0.1) -> Program:
    return Program(tuple(JointMove((0.01 * (k + 1),) * 6, step_s) for k in range(n)))


def test_completes_with_one_ack_per_command_in_order() -> None:
    prog = generic_program()
    acks: list[int] = []
    states: list = []
    done: list[Outcome] = []
    with Emulator("generic", time_scale=20) as emu, RobotLink(emu.url, link_config(emu)) as link:
        s = Streamer(
            prog, link, run_id=11, on_ack=acks.append, on_state=states.append, on_done=done.append
        )
        with s:
            assert s.wait(timeout=20) == ExecState.COMPLETED
        assert acks == list(range(len(prog))) and done == [Outcome.COMPLETED]
        assert s.progress == 1.0 and s.last_acked == len(prog) - 1
        assert states and states[-1].last_done == len(prog) - 1
        assert check_exactly_once(emu.execution_log(), 11, len(prog)) == []
        rep = emu.snapshot()
        assert rep.nozzle is False and rep.magnets == 0 and rep.lift_urad == 500_000


def test_on_acks_hands_over_contiguous_ranges_once_each() -> None:
    """Commands shorter than the robot's report slot complete several per report:
    ``on_acks`` gets them as ranges that tile the program in order, none twice."""
    prog = moves(60, 0.0)  # zero-length moves: many complete between two reports
    ranges: list[tuple[int, int]] = []
    with Emulator("generic", time_scale=20) as emu, RobotLink(emu.url, link_config(emu)) as link:
        with Streamer(prog, link, run_id=12, on_acks=lambda a, b: ranges.append((a, b))) as s:
            assert s.wait(timeout=20) == ExecState.COMPLETED
        assert check_exactly_once(emu.execution_log(), 12, len(prog)) == []
    covered = [i for a, b in ranges for i in range(a, b + 1)]
    assert covered == list(range(len(prog)))
    assert all(a <= b for a, b in ranges)
    assert len(ranges) < len(prog)  # at least one report carried several completions


def test_on_ack_and_on_acks_are_exclusive() -> None:
    with (
        Emulator("generic") as emu,
        RobotLink(emu.url, link_config(emu)) as link,
        pytest.raises(ValueError, match="not both"),
    ):
        Streamer(moves(2), link, run_id=1, on_ack=print, on_acks=lambda a, b: None)


def test_window_bounds_what_is_ahead_of_the_persisted_ack() -> None:
    prog = moves(30, 0.05)
    worst = [0]
    with Emulator("generic", time_scale=5) as emu, RobotLink(emu.url, link_config(emu)) as link:
        acked = [-1]

        def on_ack(i: int) -> None:
            acked[0] = i

        def on_state(rep) -> None:
            # Robot's view: queued beyond the last persisted ack never exceeds the window.
            worst[0] = max(worst[0], rep.last_done + rep.buffer_level - acked[0])

        with Streamer(prog, link, run_id=2, on_ack=on_ack, on_state=on_state, window=3) as s:
            assert s.wait(timeout=20) == ExecState.COMPLETED
    assert 1 <= worst[0] <= 3


def test_pause_holds_and_resume_finishes() -> None:
    prog = moves(20)
    with Emulator("generic", time_scale=2) as emu, RobotLink(emu.url, link_config(emu)) as link:
        with Streamer(prog, link, run_id=5) as s:
            assert emu.wait_for(lambda e: e.robot.last_done >= 1, 10)
            s.pause()
            assert s.wait({ExecState.PAUSED}, 5) == ExecState.PAUSED
            assert emu.wait_for(lambda e: e.robot.mode == Mode.PAUSED, 5)
            held = emu.snapshot()
            # Nothing moves while paused (heartbeats keep the watchdog quiet meanwhile).
            assert not emu.wait_for(lambda e: e.robot.report().q_urad != held.q_urad, 0.8)
            s.resume()
            assert s.wait(timeout=20) == ExecState.COMPLETED
        assert check_exactly_once(emu.execution_log(), 5, len(prog)) == []


def test_abort_stops_the_robot_and_ends_the_run() -> None:
    prog = moves(50, 0.2)
    done: list[Outcome] = []
    with Emulator("generic") as emu, RobotLink(emu.url, link_config(emu)) as link:
        with Streamer(prog, link, run_id=6, on_done=done.append) as s:
            assert emu.wait_for(lambda e: e.robot.current is not None, 5)
            s.abort()
            assert s.wait(timeout=5) == ExecState.ABORTED
            assert emu.wait_for(lambda e: e.robot.stops and e.robot.stops[-1].reason == "abort", 5)
            assert emu.wait_for(lambda e: not e.robot.busy, 5)
            s.abort()  # idempotent, no second on_done
        assert done == [Outcome.ABORTED]
        log = emu.execution_log()
        assert log[-1].outcome == "interrupted" and log[-1].reason == "abort"


def test_new_streamer_resumes_from_persisted_index_after_host_restart() -> None:
    """A server restart: the link and streamer vanish mid-run; new ones resume."""
    prog = moves(40, 0.1)
    persisted: list[int] = []
    with Emulator("generic", time_scale=4) as emu:
        link = RobotLink(emu.url, link_config(emu)).start()
        s = Streamer(prog, link, run_id=77, on_ack=persisted.append).start()
        assert emu.wait_for(lambda e: e.robot.last_done >= 10, 20)
        s.close()  # the process dies: nothing is said to the robot …
        link.close()  # … and the TCP connection drops, so the robot stops at once.
        assert emu.wait_for(lambda e: not e.robot.busy, 5)
        with RobotLink(emu.url, link_config(emu)) as link2:
            start = persisted[-1] + 1
            with Streamer(prog, link2, run_id=77, start=start, on_ack=persisted.append) as s2:
                assert s2.wait(timeout=30) == ExecState.COMPLETED
        assert persisted == list(range(len(prog)))
        assert check_exactly_once(emu.execution_log(), 77, len(prog)) == []
        # The robot stopped when the connection closed (if it was still busy then).
        assert {s.reason for s in emu.stop_events()} <= {"link_lost"}


def test_stale_resume_point_does_not_repeat_commands() -> None:
    """The robot completed more than the host persisted: ALREADY_DONE, not again."""
    prog = moves(12, 0.0)
    with Emulator("generic") as emu, RobotLink(emu.url, link_config(emu)) as link:
        with Streamer(prog, link, run_id=9) as s:
            assert s.wait(timeout=10) == ExecState.COMPLETED
        acks: list[int] = []
        with Streamer(prog, link, run_id=9, start=4, on_ack=acks.append) as s:
            assert s.wait(timeout=10) == ExecState.COMPLETED
        assert acks == list(range(4, 12))  # reported from the robot's own progress
        assert check_exactly_once(emu.execution_log(), 9, len(prog)) == []


def test_out_of_limits_command_is_refused_with_its_index() -> None:
    prog = Program(
        (JointMove((0.1,) * 6, 0.0), JointMove((0.1, 5.0, 0, 0, 0, 0), 0.0), Nozzle(True))
    )
    faults = []
    with (
        Emulator("generic") as emu,
        RobotLink(emu.url, link_config(emu)) as link,
        Streamer(prog, link, run_id=3, on_fault=faults.append) as s,
    ):
        assert s.wait(STOPPED, 10) == ExecState.FAULTED
    assert faults[0].kind == FaultKind.REJECTED and faults[0].index == 1
    assert "LIMIT (detail 1)" in faults[0].message
    assert [r.index for r in emu.execution_log()] == [0]


def test_failing_on_ack_holds_the_robot_and_resume_retries_it() -> None:
    prog = moves(10, 0.05)
    calls: list[int] = []
    fail = threading.Event()
    fail.set()

    def on_ack(i: int) -> None:
        if i == 3 and fail.is_set():
            fail.clear()
            raise OSError("disk full")
        calls.append(i)

    with Emulator("generic") as emu, RobotLink(emu.url, link_config(emu)) as link:
        with Streamer(prog, link, run_id=4, on_ack=on_ack) as s:
            assert s.wait(STOPPED, 10) == ExecState.FAULTED
            assert s.fault.kind == FaultKind.HOST and "disk full" in s.fault.message
            s.resume()
            assert s.wait(timeout=10) == ExecState.COMPLETED
        assert calls == list(range(10))
        assert check_exactly_once(emu.execution_log(), 4, len(prog)) == []


def test_busy_robot_refuses_another_run() -> None:
    with Emulator("generic") as emu, RobotLink(emu.url, link_config(emu)) as link:
        with Streamer(moves(30, 0.2), link, run_id=1) as first:
            assert emu.wait_for(lambda e: e.robot.current is not None, 5)
            with Streamer(moves(3), link, run_id=2) as second:
                assert second.wait(STOPPED, 5) == ExecState.FAULTED
                assert second.fault.kind == FaultKind.ROBOT_BUSY
            assert first.state == ExecState.RUNNING  # untouched by the refused newcomer
            first.abort()
            assert first.wait(timeout=5) == ExecState.ABORTED
        assert emu.wait_for(lambda e: e.robot.stops, 5)
        assert [s.reason for s in emu.stop_events()] == ["abort"]


def test_empty_program_completes_at_once() -> None:
    with (
        Emulator("generic") as emu,
        RobotLink(emu.url, link_config(emu)) as link,
        Streamer(Program(()), link, run_id=1) as s,
    ):
        assert s.wait(timeout=5) == ExecState.COMPLETED


def _refusal(link: RobotLink, prog: Program, run_id: int, index: int, detail: int):
    from robots.adapters.link import FrameRefused
    from robots.protocol.messages import Nak, NakReason

    msg = prog[index].to_message(run_id, index)
    nak = Nak(ref_seq=1, reason=NakReason.FAULTED, detail=detail)
    return FrameRefused(seq=1, message=msg, nak=nak, session=link.session)


def test_faulted_refusal_before_the_report_is_classified_by_its_bits() -> None:
    """A robot that latched a fault refuses the next command (NAK FAULTED,
    detail = fault bits) and that refusal can arrive before the state report
    carrying the fault: a drive fault still reads as a robot fault (which
    only an explicit clear resumes), an E-stop bit ends the run as
    E-stopped, and the robot's watchdog or a link reset reads as the link
    interruption the report would give (resumable without a fault clear)."""
    from robots.protocol.messages import FaultFlag

    cases = [
        (int(FaultFlag.DRIVE), ExecState.FAULTED, FaultKind.ROBOT_FAULT),
        (int(FaultFlag.ESTOP), ExecState.ESTOPPED, None),
        (int(FaultFlag.WATCHDOG), ExecState.INTERRUPTED, FaultKind.LINK_LOST),
        (int(FaultFlag.LINK_RESET), ExecState.INTERRUPTED, FaultKind.LINK_LOST),
        (int(FaultFlag.WATCHDOG | FaultFlag.DRIVE), ExecState.FAULTED, FaultKind.ROBOT_FAULT),
    ]
    for k, (bits, state, kind) in enumerate(cases):
        prog = moves(40, 0.2)
        faults: list = []
        with (
            Emulator("generic") as emu,
            RobotLink(emu.url, link_config(emu)) as link,
            Streamer(prog, link, run_id=40 + k, on_fault=faults.append) as s,
        ):
            assert emu.wait_for(lambda e: e.robot.last_done >= 0, 10)
            s._on_link_event(_refusal(link, prog, 40 + k, 3, bits))
            assert s.wait(STOPPED | {ExecState.ESTOPPED}, 10) == state, bits
            if state == ExecState.INTERRUPTED:
                # The robot has no latched fault here, so a resume runs the rest.
                s.resume()
                assert s.wait(timeout=30) == ExecState.COMPLETED
                assert check_exactly_once(emu.execution_log(), 40 + k, len(prog)) == []
        if kind is None:
            assert faults == []
        else:
            assert faults[0].kind == kind and faults[0].index == 3
            assert f"FAULTED (detail {bits})" in faults[0].message


def test_a_resume_right_after_a_drive_fault_refusal_clears_the_drive_fault() -> None:
    """The robot latched a drive fault and refused the next command before the
    report carrying the fault arrived; the operator resumes with a fault clear at
    once.  The last report the host has is older than the refusal and shows no
    fault, so the CLEAR must take its bits from the refusal: otherwise the robot
    stays faulted and the report that follows faults the resumed run again."""
    from robots.protocol.messages import FaultFlag

    drive = int(FaultFlag.DRIVE)
    prog = moves(20, 0.05)
    faults: list = []
    cleared: list[int] = []
    with (
        Emulator("generic", time_scale=4) as emu,
        RobotLink(emu.url, link_config(emu)) as link,
        Streamer(prog, link, run_id=47, on_fault=faults.append) as s,
    ):
        assert emu.wait_for(lambda e: e.robot.last_done >= 0, 10)
        real_clear = link.clear_faults

        def spy(bits: int) -> int:
            cleared.append(int(bits))
            return real_clear(bits)

        link.clear_faults = spy  # type: ignore[method-assign]
        with emu._lock:  # the robot's drive fault, really latched
            emu.robot.faults |= drive
            emu.robot.fault_code = 42
        # Refusal and resume queued back to back: no report between them.
        s._on_link_event(_refusal(link, prog, 47, 3, drive))
        s.resume(clear_robot_faults=True)
        assert s.wait(timeout=30) == ExecState.COMPLETED, faults
        assert cleared and cleared[0] & drive
        assert [f.kind for f in faults] == [FaultKind.ROBOT_FAULT]
        assert check_exactly_once(emu.execution_log(), 47, len(prog)) == []
