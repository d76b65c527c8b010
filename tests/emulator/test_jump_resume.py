"""Resume mid-jump (ARA): the emulator is restarted from its state file (a) with the
moving foot in the air and (b) between a magnet release and the trajectory after it;
the resumed run releases no magnet the program had not released at that point, never
leaves the robot without a held foot, and does nothing twice (the emulators' own logs)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from robots.adapters import ExecState, RobotLink, Streamer
from robots.emulator import Emulator, ExecutionRecord, check_exactly_once
from robots.protocol import (
    BasePose,
    Capture,
    JointMove,
    Program,
    SensorCapture,
    SetMagnet,
    Stop,
    WheelSpeeds,
)
from robots.protocol.messages import FaultFlag

from .helpers import link_config

Q_MOBILE = (0.0,) * 6
Q_LIFT = (0.0, 0.3, 0.0, 0.0, 0.3, 0.0)
Q_CONV = tuple(float(v) for v in np.radians([0.0, 80.0, 0.0, 0.0, 90.0, 0.0]))
Q_LAND = (0.6, 0.0, 0.0, 0.0, 0.0, -0.6)  # foot 1 down again, 0.5 m away on the surface

JUMP = Program(
    (
        JointMove(Q_MOBILE, 0.0),  # 0
        SetMagnet(1, True),  # 1  foot 2 anchors
        JointMove(Q_LIFT, 1.0),  # 2  foot 1 lifts off
        JointMove(Q_CONV, 3.0),  # 3  … to P_conv (cut here: foot 1 in the air)
        JointMove(Q_LAND, 2.0),  # 4  foot 1 lands
        SetMagnet(0, True),  # 5  swap
        SetMagnet(1, False),  # 6  (cut after this: foot 2 released, not yet lifted)
        JointMove(Q_CONV, 2.0),  # 7  foot 2 swings
        JointMove(Q_MOBILE, 2.0),  # 8  and lands
        SetMagnet(0, False),  # 9  mobile configuration
        BasePose((4.0, 1.0, 0.0), (0.0, 0.0, math.pi)),  # 10
        Capture(),  # 11
        WheelSpeeds((0.1, 0.1), 1.0),  # 12
        Stop(),  # 13
    ),
    robot="ara",
)
RELEASES = [(1, True), (0, True), (1, False), (0, False)]  # in the program's order
RUN_ID = 5150


class Watch:
    """Evidence from inside the robot: at every record, a foot was held; magnet changes."""

    def __init__(self) -> None:
        self.unheld: list[ExecutionRecord] = []
        self.magnet_ops: list[tuple[int, bool]] = []

    def attach(self, emu: Emulator) -> None:
        robot = emu.robot

        def on_record(rec: ExecutionRecord) -> None:
            if robot.feet_held() == 0:
                self.unheld.append(rec)
            if rec.op == "magnet" and rec.outcome == "done":
                cmd = JUMP[rec.index]
                assert isinstance(cmd, SetMagnet)
                self.magnet_ops.append((cmd.magnet, cmd.touched))

        with emu._lock:
            robot.on_record = on_record


def stream(emu: Emulator, acked: list[int], *, stop_when=None, on_capture=None) -> ExecState | None:
    """A (restarted) server: a new link and streamer from the last recorded ack.

    ``stop_when(emu) → bool``: close the link as soon as it holds (mid-motion);
    otherwise stream to the end.
    """

    def on_ack(index: int) -> None:
        assert index == (acked[-1] + 1 if acked else 0)
        acked.append(index)
        if stop_when == "after_6" and index == 6:
            raise RuntimeError("server goes down after recording command 6")

    with RobotLink(emu.url, link_config(emu)) as link:
        streamer = Streamer(
            JUMP,
            link,
            run_id=RUN_ID,
            start=len(acked),
            on_ack=on_ack,
            on_capture=on_capture,
            window=1 if stop_when == "after_6" else 8,
        )
        with streamer:
            if callable(stop_when):
                assert emu.wait_for(stop_when, 20), "never reached the cut"
                return None
            if stop_when == "after_6":
                state = streamer.wait({ExecState.FAULTED}, timeout=20)
                assert state == ExecState.FAULTED, streamer.fault
                return state
            return streamer.wait(timeout=30)


def foot1_flying(emu: Emulator) -> bool:
    seg = emu.robot.current
    if seg is None or (seg.msg.run_id, seg.msg.index) != (RUN_ID, 3):
        return False
    point = emu.robot.resume_point()
    return point is not None and point.progress >= 0.3


def finish_and_check(path: Path, acked: list[int], logs: list[ExecutionRecord], watch: Watch):
    captures: list[SensorCapture] = []
    with Emulator("ara", time_scale=6, state_file=path) as emu:
        watch.attach(emu)
        assert stream(emu, acked, on_capture=captures.append) == ExecState.COMPLETED
        assert emu.wait_for(lambda e: not e.robot.busy, 5)
        robot = emu.robot
        assert robot.magnets == 0 and robot.faults == 0 and robot.feet_held() == 0b11
        assert np.allclose(robot.q, 0.0, atol=1e-6)
        assert np.allclose(robot.base_pose()[:3, 3], [3.9, 1.0, 0.0], atol=1e-5)
        logs += emu.execution_log()
    assert acked == list(range(len(JUMP)))
    assert check_exactly_once(logs, RUN_ID, len(JUMP)) == []
    assert watch.unheld == [], watch.unheld  # never a moment without a held foot
    assert watch.magnet_ops == RELEASES  # each magnet command once, in order
    assert [c.command_index for c in captures] == [11] and captures[0].complete


def test_restart_with_the_moving_foot_in_the_air(tmp_path: Path) -> None:
    path = tmp_path / "state.json"
    acked: list[int] = []
    logs: list[ExecutionRecord] = []
    watch = Watch()
    with Emulator("ara", time_scale=6, state_file=path) as emu:
        watch.attach(emu)
        stream(emu, acked, stop_when=foot1_flying)
        assert emu.wait_for(lambda e: not e.robot.busy, 5)
        robot = emu.robot
        assert robot.magnets == 0b10 and robot.feet_in_air() == 0b01
        q_stop = robot.q.copy()
        logs += emu.execution_log()
    # The power cycle: the new emulator stands where the old one stopped,
    # foot 2 still holding, foot 1 still in the air, the cut command remembered.
    with Emulator("ara", time_scale=6, state_file=path) as emu:
        robot = emu.robot
        assert emu.state_loaded and robot.magnets == 0b10 and robot.feet_in_air() == 0b01
        assert np.allclose(robot.q, q_stop) and robot.faults == FaultFlag.LINK_RESET
        assert robot.interrupted is not None and robot.interrupted.msg.index == 3
    assert watch.magnet_ops == RELEASES[:1]
    finish_and_check(path, acked, logs, watch)
    cut = [r for r in logs if r.index == 3]
    assert [(r.outcome, r.continued_from is None) for r in cut] == [
        ("interrupted", True),
        ("done", False),
    ]
    assert cut[1].continued_from is not None and cut[0].progress is not None
    assert abs(cut[1].continued_from - cut[0].progress) < 1e-6


def test_restart_between_magnet_release_and_the_trajectory(tmp_path: Path) -> None:
    path = tmp_path / "state.json"
    acked: list[int] = []
    logs: list[ExecutionRecord] = []
    watch = Watch()
    with Emulator("ara", time_scale=6, state_file=path) as emu:
        watch.attach(emu)
        stream(emu, acked, stop_when="after_6")
        assert emu.wait_for(lambda e: not e.robot.busy, 5)
        assert emu.robot.last_done == 6 and emu.robot.current is None
        logs += emu.execution_log()
    assert acked == list(range(7)) and watch.magnet_ops == RELEASES[:3]
    with Emulator("ara", time_scale=6, state_file=path) as emu:
        robot = emu.robot
        # Foot 1 holds, foot 2 is released (as the program had it), nothing moved.
        assert robot.magnets == 0b01 and robot.last_done == 6
        assert np.allclose(robot.q, Q_LAND, atol=1e-6) and robot.feet_held() == 0b01
    finish_and_check(path, acked, logs, watch)
    # Command 7 (the trajectory) ran once, from its beginning, after the restart.
    assert [(r.index, r.outcome, r.continued_from) for r in logs if r.index in (6, 7)] == [
        (6, "done", None),
        (7, "done", None),
    ]


def test_a_fall_risk_refusal_reaches_the_streamer_as_a_robot_fault() -> None:
    from robots.adapters import FaultKind

    program = Program((SetMagnet(1, True), JointMove(Q_CONV, 1.0), SetMagnet(1, False)), "ara")
    faults = []
    with Emulator("ara", time_scale=4) as emu, RobotLink(emu.url, link_config(emu)) as link:
        streamer = Streamer(program, link, run_id=8, on_fault=faults.append)
        with streamer:
            assert streamer.wait({ExecState.FAULTED}, timeout=20) == ExecState.FAULTED
        assert emu.wait_for(lambda e: not e.robot.busy, 5)
        assert emu.robot.faults & FaultFlag.FALL_RISK and emu.robot.magnets == 0b10
    assert [f.kind for f in faults] == [FaultKind.ROBOT_FAULT], faults
    assert "FALL_RISK" in faults[0].message
