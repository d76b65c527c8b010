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
