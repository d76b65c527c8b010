"""The robot side of the protocol, driven directly with a fake clock (no I/O)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from robots.emulator import FaultConfig, SimRobot, check_exactly_once, resolve_profile
from robots.emulator.robot import ExecutionRecord
from robots.protocol.messages import (
    Abort,
    Ack,
    AckStatus,
    Clear,
    Estop,
    FaultFlag,
    Heartbeat,
    Hello,
    HelloAck,
    HelloStatus,
    JointsCmd,
    LiftCmd,
    MagnetCmd,
    Mode,
    Nak,
    NakReason,
    NozzleCmd,
    Pause,
    PlateCmd,
    Resume,
    State,
    WheelsCmd,
)


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


LIMITS = np.array([[-1.0, 1.0], [-0.5, 0.5]])


def make(faults: FaultConfig | None = None, **kw) -> tuple[SimRobot, Clock]:
    clock = Clock()
    profile = resolve_profile("generic", LIMITS)
    robot = SimRobot(profile, clock=clock, faults_injected=faults or FaultConfig(), **kw)
    return robot, clock


def hello(robot: SimRobot, watchdog_ms: int = 500) -> HelloAck:
    ack, state = robot.receive(Hello(watchdog_ms=watchdog_ms), 0)
    assert isinstance(ack, HelloAck) and isinstance(state, State)
    return ack


def joints(index: int, q=(0.5, 0.25), ms: int = 1000, run: int = 9) -> JointsCmd:
    return JointsCmd(
        run_id=run, index=index, duration_ms=ms, q_urad=tuple(round(v * 1e6) for v in q)
    )


def test_hello_reports_hardware_and_progress() -> None:
    robot, _ = make(buffer_capacity=4)
    ack = hello(robot, watchdog_ms=50_000)
    assert ack.status == HelloStatus.OK and ack.name == "generic"
    assert (ack.n_joints, ack.n_wheels, ack.n_magnets, ack.n_plates) == (2, 2, 2, 2)
    assert ack.buffer_capacity == 4 and ack.last_done == -1
    assert ack.watchdog_ms == 2000  # clamped: a robot never trusts an endless watchdog


def test_sequenced_frames_need_a_session() -> None:
    robot, _ = make()
    (nak,) = robot.receive(joints(0), 1)
    assert isinstance(nak, Nak) and nak.reason == NakReason.NOT_READY


def test_executes_in_simulated_time_and_reports() -> None:
    robot, clock = make(time_scale=2.0)
    hello(robot)
    (ack,) = robot.receive(joints(0, ms=1000), 1)
    assert isinstance(ack, Ack) and ack.status == AckStatus.OK
    robot.advance()
    assert robot.mode == Mode.MOVING
    clock.t += 0.25  # half of 1 s sim at 2× speed
    robot.advance()
    assert robot.q == pytest.approx([0.25, 0.125])
    assert robot.next_deadline() == pytest.approx(clock.t + 0.25)
    clock.t += 0.25
    robot.advance()
    rep = robot.report()
    assert rep.last_done == 0 and rep.mode == Mode.IDLE and rep.q_urad == (500000, 250000)
    assert [(r.index, r.outcome) for r in robot.log] == [(0, "done")]


def test_every_command_kind_changes_the_state() -> None:
    robot, clock = make()
    hello(robot)
    cmds = [
        WheelsCmd(run_id=1, index=0, duration_ms=2000, speeds_um_s=(100_000, -50_000)),
        MagnetCmd(run_id=1, index=1, magnet=1, touched=True),
        PlateCmd(run_id=1, index=2, plate=0, engaged=True),
        LiftCmd(run_id=1, index=3, duration_ms=0, angle_urad=700_000),
        NozzleCmd(run_id=1, index=4, on=True),
    ]
    for seq, c in enumerate(cmds, start=1):
        assert isinstance(robot.receive(c, seq)[0], Ack)
    for _ in range(10):
        clock.t += 0.25  # heartbeats well inside the watchdog
        robot.receive(Heartbeat(), 0)
    rep = robot.report()
    assert rep.last_done == 4
    assert rep.odometry_um == (200_000, -100_000)
    assert (rep.magnets, rep.plates, rep.nozzle, rep.lift_urad) == (0b10, 0b01, True, 700_000)


@pytest.mark.parametrize(
    ("msg", "reason", "detail"),
    [
        (joints(0, q=(0.0, 0.6)), NakReason.LIMIT, 1),
        (joints(0, q=(0.0,)), NakReason.INVALID, 1),
        (MagnetCmd(run_id=9, index=0, magnet=5, touched=True), NakReason.INVALID, 5),
        (LiftCmd(run_id=9, index=0, angle_urad=-1_000_000), NakReason.LIMIT, 0),
        (WheelsCmd(run_id=9, index=0, speeds_um_s=(1,)), NakReason.INVALID, 1),
    ],
)
def test_refuses_what_it_cannot_do(msg, reason: NakReason, detail: int) -> None:
    robot, _ = make()
    hello(robot)
    (nak,) = robot.receive(msg, 1)
    assert isinstance(nak, Nak) and (nak.reason, nak.detail) == (reason, detail)
    assert robot.expected_seq == 2  # a refusal consumes the seq
    assert not robot.busy


def test_limits_edge_is_accepted() -> None:
    robot, _ = make()
    hello(robot)
    assert isinstance(robot.receive(joints(0, q=(1.0, -0.5)), 1)[0], Ack)


def test_gap_nak_and_repeated_replies() -> None:
    robot, _ = make()
    hello(robot)
    (gap,) = robot.receive(joints(1), 2)  # seq 1 lost
    assert isinstance(gap, Nak) and gap.reason == NakReason.SEQ_GAP and gap.expected_seq == 1
    first = robot.receive(joints(0), 1)
    again = robot.receive(joints(0), 1)  # retransmission: same answer, not queued twice
    assert first == again and len(robot.buffer) + (robot.current is not None) == 1
    refused = robot.receive(joints(1, q=(9.0, 0.0)), 2)
    assert robot.receive(joints(1, q=(9.0, 0.0)), 2) == refused  # a NAK repeats too


def test_already_done_is_never_executed_again() -> None:
    robot, _clock = make()
    hello(robot)
    robot.receive(joints(0, ms=0), 1)
    robot.advance()
    assert robot.last_done == 0
    # New session (host reconnected and resumes from a stale point).
    hello(robot)
    (ack,) = robot.receive(joints(0, ms=0), 1)
    assert isinstance(ack, Ack) and ack.status == AckStatus.ALREADY_DONE
    (gap,) = robot.receive(joints(5), 2)
    assert isinstance(gap, Nak) and gap.reason == NakReason.INDEX and gap.detail == 1
    assert [r.index for r in robot.log] == [0]


def test_another_run_is_refused_while_busy() -> None:
    robot, _ = make()
    hello(robot)
    robot.receive(joints(0, run=1), 1)
    (nak,) = robot.receive(joints(0, run=2), 2)
    assert isinstance(nak, Nak) and nak.reason == NakReason.RUN_ACTIVE
    robot.receive(Abort(), 3)
    assert isinstance(robot.receive(joints(0, run=2), 4)[0], Ack)


def test_buffer_full_is_transient() -> None:
    robot, _ = make(buffer_capacity=2)
    hello(robot)
    robot.receive(joints(0), 1)
    robot.receive(joints(1), 2)
    (busy,) = robot.receive(joints(2), 3)
    assert isinstance(busy, Nak) and busy.reason == NakReason.BUSY
    assert robot.expected_seq == 3  # not consumed: the host sends seq 3 again later


def test_watchdog_stops_motion_and_latches() -> None:
    robot, clock = make()
    hello(robot, watchdog_ms=300)
    robot.receive(joints(0, ms=10_000), 1)
    robot.receive(joints(1, ms=10_000), 2)
    clock.t += 0.2
    robot.receive(Heartbeat(), 0)  # fed
    clock.t += 0.29
    robot.advance()
    assert robot.mode == Mode.MOVING
    clock.t += 0.2  # 0.49 s since the last frame
    robot.advance()
    assert robot.faults == FaultFlag.WATCHDOG and robot.mode == Mode.FAULT
    stop = robot.stops[-1]
    assert (stop.reason, stop.moving, stop.index) == ("watchdog", True, 0)
    # Motion integrated only up to the watchdog deadline (0.5 s of 10 s).
    assert robot.q[0] == pytest.approx(0.5 * 0.5 / 10, rel=1e-6)
    assert not robot.buffer and robot.log[-1].outcome == "interrupted"
    (nak,) = robot.receive(joints(0), 3)
    assert isinstance(nak, Nak) and nak.reason == NakReason.FAULTED
    robot.receive(Clear(faults=FaultFlag.WATCHDOG), 4)
    assert isinstance(robot.receive(joints(0), 5)[0], Ack)


def test_idle_robot_does_not_trip_its_watchdog() -> None:
    robot, clock = make()
    hello(robot, watchdog_ms=300)
    clock.t += 10
    robot.advance()
    assert robot.faults == 0 and not robot.stops


def test_new_session_stops_a_running_robot() -> None:
    robot, _clock = make()
    hello(robot)
    robot.receive(joints(0, ms=10_000), 1)
    robot.advance()
    hello(robot)
    assert robot.faults == FaultFlag.LINK_RESET and robot.stops[-1].reason == "link_reset"


def test_estop_any_state_and_clear() -> None:
    robot, clock = make()
    (ack,) = robot.receive(Estop(), 77)  # even before a session
    assert isinstance(ack, Ack) and ack.ref_seq == 77 and robot.mode == Mode.ESTOP
    hello(robot)
    (nak,) = robot.receive(joints(0), 1)
    assert isinstance(nak, Nak) and nak.reason == NakReason.FAULTED
    robot.receive(Clear(faults=FaultFlag.ESTOP), 2)
    robot.receive(joints(0, ms=5000), 3)
    robot.advance()
    clock.t += 0.1
    robot.receive(Estop(), 78)
    assert robot.stops[-1].reason == "estop" and robot.stops[-1].moving
    assert robot.mode == Mode.ESTOP and robot.current is None


def test_pause_holds_and_resume_continues() -> None:
    robot, clock = make()
    hello(robot)
    robot.receive(joints(0, ms=1000), 1)
    clock.t += 0.25
    robot.receive(Pause(), 2)
    q = robot.q.copy()
    clock.t += 0.25
    robot.receive(Heartbeat(), 0)
    assert robot.mode == Mode.PAUSED and np.allclose(robot.q, q)
    robot.receive(Resume(), 3)
    clock.t += 0.3
    robot.receive(Heartbeat(), 0)
    clock.t += 0.5
    robot.advance()
    assert robot.last_done == 0


def test_injected_nak_and_fault() -> None:
    robot, clock = make(FaultConfig(nak_index=1, nak_times=2, fault_at_index=2, fault_code=7))
    hello(robot)
    robot.receive(joints(0, ms=0), 1)
    for _ in range(2):
        (nak,) = robot.receive(joints(1, ms=0), 2)
        assert isinstance(nak, Nak) and nak.reason == NakReason.BUSY
    assert isinstance(robot.receive(joints(1, ms=0), 2)[0], Ack)
    robot.receive(joints(2, q=(0.4, 0.0), ms=1000), 3)
    clock.t += 0.3
    robot.receive(Heartbeat(), 0)
    assert robot.mode == Mode.MOVING
    clock.t += 0.3
    robot.advance()
    assert robot.faults == FaultFlag.DRIVE and robot.fault_code == 7
    assert robot.q[0] == pytest.approx(0.45)  # halfway from 0.5 to 0.4
    robot.receive(Clear(faults=FaultFlag.DRIVE), 4)
    robot.receive(joints(2, q=(0.4, 0.0), ms=1000), 5)
    clock.t += 0.5
    robot.receive(Heartbeat(), 0)
    clock.t += 0.6
    robot.advance()
    assert robot.last_done == 2 and robot.q[0] == pytest.approx(0.4)
    assert check_exactly_once(robot.log, 9, 3) == []
    assert [r.outcome for r in robot.log if r.index == 2] == ["interrupted", "done"]


def _rec(index: int, outcome: str = "done", run: int = 1) -> ExecutionRecord:
    return ExecutionRecord(run, index, "joints", outcome, "", 0, 0, 0, 0)


def test_check_exactly_once_finds_every_problem() -> None:
    ok = [_rec(0), _rec(1, "interrupted"), _rec(1), _rec(2), _rec(0, run=2)]
    assert check_exactly_once(ok, 1, 3) == []
    assert any("more than once" in p for p in check_exactly_once([_rec(0), _rec(0)], 1, 1))
    assert any("never completed: [1]" in p for p in check_exactly_once([_rec(0)], 1, 2))
    assert any("out of order" in p for p in check_exactly_once([_rec(1), _rec(0)], 1, 2))
    again = check_exactly_once([_rec(0), _rec(0, "interrupted")], 1, 1)
    assert any("started again" in p for p in again)
    assert check_exactly_once([_rec(2), _rec(3)], 1, 4, start=2) == []


def test_profiles_fall_back_and_accept_limits() -> None:
    p = resolve_profile("no_such_robot")
    assert p.name == "no_such_robot" and p.n_joints == 6 and p.source == "fallback"
    p = resolve_profile("denso_vm6083", [[-1, 1]] * 6)
    assert p.source == "arguments" and p.nozzle and p.n_wheels == 0
    with pytest.raises(ValueError, match="lower limit"):
        resolve_profile("ara", [[1, -1]])
    vm = resolve_profile("denso_vm6083")
    assert vm.n_joints == 6
    assert vm.joint_limits[0, 1] == pytest.approx(math.radians(170))


def test_unparseable_sequenced_frame_is_refused_and_consumed() -> None:
    robot, _ = make()
    hello(robot)
    (nak,) = robot.receive_invalid(0x17, 1)  # a command type from a newer minor version
    assert isinstance(nak, Nak) and nak.reason == NakReason.INVALID and nak.detail == -1
    assert robot.receive_invalid(0x17, 1) == [nak]  # retransmission: same answer
    assert isinstance(robot.receive(joints(0), 2)[0], Ack)
    assert robot.receive_invalid(0x7E, 0) == []  # not sequenced: ignored


# --- continuation of an interrupted command (docs/protocol.md §8.2) -----------------------


def wheels(index: int = 0, ms: int = 2000, speeds=(1.0, 0.5), run: int = 9) -> WheelsCmd:
    return WheelsCmd(
        run_id=run,
        index=index,
        duration_ms=ms,
        speeds_um_s=tuple(round(v * 1e6) for v in speeds),
    )


def run_for(robot: SimRobot, clock: Clock, seconds: float, step: float = 0.1) -> None:
    """Let simulated time pass with heartbeats well inside the watchdog."""
    for _ in range(round(seconds / step)):
        clock.t += step
        robot.receive(Heartbeat(), 0)


def reconnect(robot: SimRobot) -> int:
    """What a resuming host does: new session, clear the link fault; returns the next seq."""
    hello(robot)
    (ack,) = robot.receive(Clear(faults=FaultFlag.LINK_RESET | FaultFlag.WATCHDOG), 1)
    assert isinstance(ack, Ack)
    return 2


def test_wheels_resume_drives_only_the_remainder() -> None:
    # The case: link lost 1.03 m into a 2.0 m wheels command, then resumed.
    robot, clock = make()
    hello(robot, watchdog_ms=2000)
    cmd = wheels(ms=2000, speeds=(1.0, 0.5))
    robot.receive(cmd, 1)
    robot.advance()
    clock.t += 1.03
    robot.link_lost()
    assert robot.odometry == pytest.approx([1.03, 0.515])
    assert robot.interrupted is not None and robot.interrupted.progress == pytest.approx(0.515)
    seq = reconnect(robot)
    (ack,) = robot.receive(cmd, seq)  # the resume sends the same command again
    assert isinstance(ack, Ack) and ack.status == AckStatus.OK
    robot.advance()
    assert robot.current is not None and robot.current.duration == pytest.approx(0.97)
    run_for(robot, clock, 1.5)
    assert robot.last_done == 0 and robot.mode == Mode.IDLE
    assert robot.odometry == pytest.approx([2.0, 1.0], abs=1e-9)  # not 3.03 m
    first, second = robot.log
    assert (first.outcome, first.reason, first.continued_from) == ("interrupted", "link_lost", None)
    assert first.progress == pytest.approx(0.515)
    assert (second.outcome, second.progress) == ("done", 1.0)
    assert second.continued_from == pytest.approx(0.515)
    assert check_exactly_once(robot.log, 9, 1) == []
    (again,) = robot.receive(cmd, seq + 1)  # completed: still never executed again
    assert isinstance(again, Ack) and again.status == AckStatus.ALREADY_DONE
    assert robot.interrupted is None and len(robot.log) == 2


def test_wheels_interrupted_twice_ends_at_the_planned_total() -> None:
    robot, clock = make()
    hello(robot, watchdog_ms=300)
    cmd = wheels(ms=3000, speeds=(0.2, 0.2))
    robot.receive(cmd, 1)
    robot.advance()
    clock.t += 0.7
    robot.advance()  # watchdog: stops at 0.3 s
    assert robot.faults & FaultFlag.WATCHDOG
    seq = reconnect(robot)
    robot.receive(cmd, seq)
    run_for(robot, clock, 1.0)
    robot.receive(Abort(), seq + 1)  # stopped again, at 1.3 s of 3 s
    seq = reconnect(robot)
    robot.receive(cmd, seq)
    run_for(robot, clock, 2.0)
    assert robot.odometry == pytest.approx([0.6, 0.6], abs=1e-9)
    assert [(r.outcome, r.reason) for r in robot.log] == [
        ("interrupted", "watchdog"),
        ("interrupted", "abort"),
        ("done", ""),
    ]
    p = [r.progress for r in robot.log]
    assert p[:2] == pytest.approx([0.1, 1.3 / 3])
    assert [r.continued_from for r in robot.log][1:] == pytest.approx(p[:2])
    assert check_exactly_once(robot.log, 9, 1) == []


@pytest.mark.parametrize("kind", ["joints", "lift"])
def test_absolute_target_resumes_to_it_at_no_more_than_the_planned_speed(kind: str) -> None:
    robot, clock = make()
    hello(robot)
    if kind == "joints":
        cmd = joints(0, q=(0.5, 0.25), ms=1000)
    else:
        cmd = LiftCmd(run_id=9, index=0, duration_ms=1000, angle_urad=1_000_000)
    robot.receive(cmd, 1)
    robot.advance()
    clock.t += 0.4
    robot.receive(Pause(), 2)  # pause, then abort: the command is interrupted at 40 %
    clock.t += 0.3
    robot.receive(Abort(), 3)
    assert robot.log[-1].progress == pytest.approx(0.4)
    seq = reconnect(robot)
    robot.receive(cmd, seq)
    robot.advance()
    seg = robot.current
    assert seg is not None and seg.continued_from == pytest.approx(0.4)
    # Rule: remaining duration = planned × remaining-distance fraction (0.6 s), so
    # each joint moves at exactly its planned speed, never faster.
    assert seg.duration == pytest.approx(0.6)
    before = robot.q.copy() if kind == "joints" else np.array([robot.lift])
    clock.t += 0.3
    robot.receive(Heartbeat(), 0)
    after = robot.q.copy() if kind == "joints" else np.array([robot.lift])
    planned_speed = np.array([0.5, 0.25]) if kind == "joints" else np.array([1.0])
    assert np.abs(after - before) / 0.3 == pytest.approx(planned_speed)
    run_for(robot, clock, 0.5)
    assert robot.last_done == 0
    if kind == "joints":
        assert robot.q == pytest.approx([0.5, 0.25], abs=1e-12)
    else:
        assert robot.lift == pytest.approx(1.0, abs=1e-12)
    assert check_exactly_once(robot.log, 9, 1) == []


def test_resume_of_a_dwell_waits_only_the_rest() -> None:
    robot, clock = make()
    hello(robot)
    robot.receive(joints(0, q=(0.0, 0.0), ms=0), 1)  # where the robot already is
    robot.receive(joints(1, q=(0.0, 0.0), ms=1000), 2)  # a 1 s dwell
    robot.advance()
    clock.t += 0.25
    robot.link_lost()
    seq = reconnect(robot)
    robot.receive(joints(1, q=(0.0, 0.0), ms=1000), seq)
    robot.advance()
    assert robot.current is not None and robot.current.duration == pytest.approx(0.75)


def test_state_commands_resume_idempotently() -> None:
    # A fault injected "halfway" through an instantaneous magnet command interrupts it
    # before it acts; the resume applies the (absolute) state once.
    robot, _ = make(FaultConfig(fault_at_index=0))
    hello(robot)
    cmd = MagnetCmd(run_id=9, index=0, magnet=1, touched=True)
    robot.receive(cmd, 1)
    robot.advance()
    assert robot.faults == FaultFlag.DRIVE and robot.magnets == 0
    robot.receive(Clear(faults=FaultFlag.DRIVE), 2)
    robot.receive(cmd, 3)
    robot.advance()
    assert robot.magnets == 0b10 and robot.last_done == 0
    assert [(r.outcome, r.continued_from) for r in robot.log] == [
        ("interrupted", None),
        ("done", 0.0),
    ]
    assert check_exactly_once(robot.log, 9, 1) == []


def test_another_run_or_another_command_clears_the_memory() -> None:
    robot, clock = make()
    hello(robot)
    robot.receive(wheels(ms=2000, run=9), 1)
    robot.advance()
    clock.t += 0.5
    robot.link_lost()
    seq = reconnect(robot)
    robot.receive(wheels(ms=2000, run=10), seq)  # a new execution: runs in full
    assert robot.interrupted is None
    run_for(robot, clock, 2.5)
    assert robot.odometry[0] == pytest.approx(2.5)
    assert robot.log[-1].continued_from is None and robot.counters["continuations"] == 0
    # Same (run, index) but other content is not a resume of what was interrupted.
    robot.receive(wheels(index=1, ms=2000, run=10), seq + 1)
    robot.advance()
    clock.t += 0.5
    robot.link_lost()
    seq = reconnect(robot)
    robot.receive(wheels(index=1, ms=1000, run=10), seq)
    robot.advance()
    assert robot.current is not None and robot.current.duration == pytest.approx(1.0)
    assert robot.counters["continuation_mismatch"] == 1


def test_resume_point_of_a_paused_command_and_power_down() -> None:
    robot, clock = make()
    hello(robot)
    robot.receive(wheels(ms=2000), 1)
    robot.advance()
    clock.t += 0.5
    robot.receive(Pause(), 2)
    point = robot.resume_point()  # what a state file written now keeps
    assert point is not None and point.progress == pytest.approx(0.25)
    assert point.done_s == pytest.approx(0.5) and robot.interrupted is None
    robot.power_down()
    assert robot.log[-1].reason == "shutdown" and robot.faults == FaultFlag.LINK_RESET
    assert robot.interrupted == point


def _rec_p(index: int, outcome: str, progress: float | None, cont: float | None) -> ExecutionRecord:
    return ExecutionRecord(1, index, "wheels", outcome, "", 0, 0, 0, 0, progress, cont)


def test_check_exactly_once_finds_repeated_and_skipped_motion() -> None:
    ok = [_rec_p(0, "interrupted", 0.4, None), _rec_p(0, "done", 1.0, 0.4)]
    assert check_exactly_once(ok, 1, 1) == []
    restarted = [_rec_p(0, "interrupted", 0.4, None), _rec_p(0, "done", 1.0, None)]
    assert any("motion repeated" in p for p in check_exactly_once(restarted, 1, 1))
    # Interrupted before anything moved: starting over repeats nothing.
    nothing = [_rec_p(0, "interrupted", 0.0, None), _rec_p(0, "done", 1.0, None)]
    assert check_exactly_once(nothing, 1, 1) == []
    back = [_rec_p(0, "interrupted", 0.4, None), _rec_p(0, "done", 1.0, 0.2)]
    assert any("motion repeated" in p for p in check_exactly_once(back, 1, 1))
    ahead = [_rec_p(0, "interrupted", 0.4, None), _rec_p(0, "done", 1.0, 0.6)]
    assert any("motion skipped" in p for p in check_exactly_once(ahead, 1, 1))
    orphan = [_rec_p(0, "done", 1.0, 0.4)]
    assert any("first part is not in the log" in p for p in check_exactly_once(orphan, 1, 1))


def test_progress_reports_are_paced_but_a_stop_is_reported_at_once() -> None:
    """Queued/started/done changes wait for the next report slot
    (``min_report_gap_s``); an E-stop or an operator command never waits."""
    robot, clock = make(min_report_gap_s=0.02)
    hello(robot, watchdog_ms=50_000)
    robot.reported(clock.t)
    seq = 1
    for i in range(3):  # three short commands queued back to back
        (ack,) = robot.receive(joints(i, ms=5), seq)
        assert isinstance(ack, Ack)
        seq += 1
    assert robot.changed and not robot.report_due(clock.t)
    assert robot.report_at() == pytest.approx(clock.t + 0.02)
    clock.t += 0.019
    robot.advance(clock.t)  # all three done (15 ms of motion) inside the slot
    assert robot.last_done == 2 and not robot.report_due(clock.t)
    clock.t += 0.001
    assert robot.report_due(clock.t)  # one report carries all three completions
    robot.reported(clock.t)
    assert not robot.changed and robot.report_at() is None
    robot.receive(joints(3, ms=1000), seq)
    seq += 1
    clock.t += 0.001
    robot.advance(clock.t)
    assert robot.busy and not robot.report_due(clock.t)
    robot.receive(Estop(), 0)
    assert robot.report_due(clock.t)  # 1 ms after the last report: not held back
    assert robot.report().mode == Mode.ESTOP
    robot.reported(clock.t)
    robot.receive(Pause(), seq)
    assert robot.report_due(clock.t)
