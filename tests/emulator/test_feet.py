"""The ARA's feet and magnets in the emulator (robots/emulator/feet.py): a command that
would let the robot fall is refused, latches FALL_RISK and stops the robot; an E-stop
mid-jump keeps both magnets; base pose, wheels and the persisted state.

Driven directly with a fake clock (no I/O)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from robots.emulator import SimRobot, check_exactly_once, resolve_profile
from robots.emulator.feet import FeetSpec
from robots.emulator.persist import restore_robot_state, robot_state
from robots.protocol import (
    BasePose,
    Command,
    JointMove,
    SetMagnet,
    Stop,
    WheelSpeeds,
)
from robots.protocol.messages import (
    Ack,
    AckStatus,
    Clear,
    Estop,
    FallRule,
    FaultFlag,
    Heartbeat,
    Hello,
    Message,
    Mode,
    Nak,
    NakReason,
    is_sequenced,
)

ARA = resolve_profile("ara")
Q_MOBILE = (0.0,) * 6
Q_LIFT = (0.0, 0.3, 0.0, 0.0, 0.3, 0.0)  # foot 1 lifted off
Q_CONV = tuple(np.radians([0.0, 80.0, 0.0, 0.0, 90.0, 0.0]))  # P_conv, seed §3.2
# Arm straight and flat, swung 0.6 rad about joint 1, foot turned back by joint 6:
# foot 1 stands on foot 2's surface again, 0.5 m away in another direction.
Q_LAND = (0.6, 0.0, 0.0, 0.0, 0.0, -0.6)


class Host:
    """A host talking to a SimRobot: numbers its frames, owns the clock."""

    def __init__(self, profile=ARA, run_id: int = 21) -> None:
        self.t = 100.0
        self.robot = SimRobot(profile, clock=lambda: self.t)
        self.seq = 0
        self.run_id = run_id
        self.index = 0
        (ack, _) = self.send(Hello(watchdog_ms=2000))
        assert ack.status == 0

    def send(self, msg: Message) -> list[Message]:
        if not is_sequenced(msg.TYPE):
            return self.robot.receive(msg, 0, now=self.t)
        self.seq = (self.seq + 1) & 0xFFFF
        return self.robot.receive(msg, self.seq, now=self.t)

    def cmd(self, c: Command) -> Message:
        (reply,) = self.send(c.to_message(self.run_id, self.index))
        self.index += 1
        return reply

    def program(self, cmds: list[Command]) -> list[Message]:
        return [self.cmd(c) for c in cmds]

    def run(self, seconds: float, step: float = 0.05) -> None:
        end = self.t + seconds
        while self.t < end - 1e-9:
            self.t = min(end, self.t + step)
            self.send(Heartbeat())


def jump() -> list[Command]:
    """An inch-worm jump as ara.switch compiles it (magnet channels 0 = foot 1, 1 = foot 2)."""
    return [
        JointMove(Q_MOBILE, 0.0),
        SetMagnet(1, True),  # A: foot 2 anchors
        JointMove(Q_LIFT, 1.0),  # B: foot 1 lifts off …
        JointMove(Q_CONV, 1.0),  # … to P_conv
        JointMove(Q_LAND, 2.0),  # C: foot 1 lands
        SetMagnet(0, True),  # D: swap
        SetMagnet(1, False),
        JointMove(Q_CONV, 2.0),  # E: foot 2 swings …
        JointMove(Q_MOBILE, 2.0),  # … and lands
        SetMagnet(0, False),  # F: mobile configuration
        WheelSpeeds((0.1, 0.1), 1.0),
        Stop(),
    ]


def assert_fell_back(host: Host, reply: Message, rule: FallRule) -> None:
    assert isinstance(reply, Nak) and reply.reason == NakReason.FALL_RISK
    assert reply.detail == rule
    r = host.robot
    assert r.faults == FaultFlag.FALL_RISK and r.fault_code == rule
    assert r.mode == Mode.FAULT and not r.busy and not r.wheel_speeds.any()
    assert r.stops[-1].reason == "fall_risk"
    # Latched: nothing more is accepted until an operator clears it.
    (nak,) = host.send(Stop().to_message(host.run_id, host.index))
    assert isinstance(nak, Nak) and nak.reason == NakReason.FAULTED
    assert nak.detail == FaultFlag.FALL_RISK


def test_the_mobile_pose_is_geometric() -> None:
    feet = ARA.feet
    assert feet is not None and feet.foot_pose is not None
    assert feet.is_mobile(np.zeros(6)) and feet.is_mobile(np.array(Q_LAND))
    assert not feet.is_mobile(np.array(Q_LIFT)) and not feet.is_mobile(np.array(Q_CONV))
    # Without kinematics (fallback profile): a joint tolerance around the mobile pose.
    plain = FeetSpec(q_mobile=np.zeros(6))
    assert plain.is_mobile(np.full(6, 0.009)) and not plain.is_mobile(np.array(Q_LAND))
    # Along a path: a joint move from one mobile pose to another that lifts the
    # foot in between is not "staying mobile" (a made-up foot: z = 0.1 sin q0).
    assert feet.path_stays_mobile(np.zeros(6), np.array(Q_LAND))
    assert not feet.path_stays_mobile(np.array(Q_LIFT), np.zeros(6))

    def arc(Q: np.ndarray) -> np.ndarray:
        T = np.repeat(np.eye(4)[None], len(Q), axis=0)
        T[:, 2, 3] = 0.1 * np.sin(Q[:, 0])
        return T

    hop = FeetSpec(q_mobile=np.zeros(1), foot_pose=arc)
    assert hop.is_mobile(np.zeros(1)) and hop.is_mobile(np.array([math.pi]))
    assert not hop.path_stays_mobile(np.zeros(1), np.array([math.pi]))


def test_a_whole_jump_is_accepted_and_ends_in_the_mobile_configuration() -> None:
    host = Host()
    held_at_every_step = []
    host.robot.on_record = lambda rec: held_at_every_step.append(host.robot.feet_held())
    replies = host.program(jump())
    assert all(isinstance(r, Ack) and r.status == AckStatus.OK for r in replies), replies
    host.run(12.0)
    r = host.robot
    assert r.faults == 0 and r.last_done == len(jump()) - 1
    assert r.magnets == 0 and r.feet_in_air() == 0 and r.feet_held() == 0b11
    assert check_exactly_once(r.log, host.run_id, len(jump())) == []
    assert all(held_at_every_step) and len(held_at_every_step) == len(jump())


def test_joint_move_off_the_mobile_pose_without_a_magnet_is_refused() -> None:
    host = Host()
    reply = host.cmd(JointMove(Q_LIFT, 1.0))
    assert_fell_back(host, reply, FallRule.JOINTS_WITHOUT_MAGNET)
    assert np.allclose(host.robot.q, 0.0)  # never moved
    # Within the mobile pose (the arm swinging flat on the surface) it is fine.
    host = Host()
    assert isinstance(host.cmd(JointMove(Q_LAND, 1.0)), Ack)


def test_releasing_the_only_held_foot_is_refused_and_stops_the_motion() -> None:
    host = Host()
    replies = host.program([SetMagnet(1, True), JointMove(Q_CONV, 2.0)])
    assert all(isinstance(r, Ack) for r in replies)
    host.run(1.0)  # half-way: foot 1 in the air, held by foot 2 alone
    assert host.robot.feet_in_air() == 0b01 and host.robot.current is not None
    q_then = host.robot.q.copy()
    reply = host.cmd(SetMagnet(1, False))
    assert_fell_back(host, reply, FallRule.RELEASE_LAST_HOLD)
    r = host.robot
    assert r.magnets == 0b10  # foot 2 still holds
    assert np.allclose(r.q, q_then)  # stopped where it was
    (rec,) = [x for x in r.log if x.outcome == "interrupted"]
    assert (rec.index, rec.reason) == (1, "fall_risk") and 0.3 < rec.progress < 0.7
    # An operator clears it; the run's remainder may then go on from there.
    (ack,) = host.send(Clear(faults=FaultFlag.FALL_RISK))
    assert isinstance(ack, Ack) and r.faults == 0 and r.fault_code == 0


def test_releasing_a_magnet_while_the_other_foot_holds_is_fine() -> None:
    host = Host()
    replies = host.program(
        [SetMagnet(1, True), JointMove(Q_LAND, 1.0), SetMagnet(0, True), SetMagnet(1, False)]
    )
    assert all(isinstance(r, Ack) for r in replies)
    host.run(2.0)
    assert host.robot.magnets == 0b01 and host.robot.faults == 0


def test_wheels_while_a_foot_is_in_the_air_are_refused() -> None:
    host = Host()
    replies = host.program([SetMagnet(1, True), JointMove(Q_LIFT, 0.5)])
    assert all(isinstance(r, Ack) for r in replies)
    host.run(1.0)
    reply = host.cmd(WheelSpeeds((0.1, 0.1), 1.0))
    assert_fell_back(host, reply, FallRule.WHEELS_FOOT_IN_AIR)
    assert host.robot.odometry.tolist() == [0.0, 0.0]


def test_a_refusal_queued_behind_a_motion_stops_it_at_once() -> None:
    """Refused when it arrives, from the state the queue leads to: the robot stops now."""
    host = Host()
    replies = host.program(
        [SetMagnet(1, True), JointMove(Q_CONV, 2.0), SetMagnet(1, False), JointMove(Q_LAND, 1.0)]
    )
    assert [type(r).__name__ for r in replies] == ["Ack", "Ack", "Nak", "Nak"]
    assert replies[2].reason == NakReason.FALL_RISK and replies[3].reason == NakReason.FAULTED
    assert host.robot.faults == FaultFlag.FALL_RISK and not host.robot.busy


def test_the_start_check_catches_a_state_that_changed_under_the_queue() -> None:
    host = Host()
    assert isinstance(host.cmd(SetMagnet(1, True)), Ack)
    host.run(0.1)
    assert isinstance(host.cmd(JointMove(Q_CONV, 1.0)), Ack)
    host.robot.magnets = 0  # as if restored from a state where foot 2 was released
    host.robot.current = None
    host.robot.buffer.appendleft(JointMove(Q_CONV, 1.0).to_message(host.run_id, 1))
    host.run(0.1)
    r = host.robot
    assert r.faults == FaultFlag.FALL_RISK and r.fault_code == FallRule.JOINTS_WITHOUT_MAGNET
    assert r.counters["fall_risk_at_start"] == 1 and np.allclose(r.q, 0.0)


@pytest.mark.parametrize("phase", ["foot1_in_air", "after_swap", "foot2_in_air"])
def test_estop_mid_jump_stops_the_joints_and_keeps_both_magnets(phase: str) -> None:
    host = Host()
    replies = host.program(jump()[:10])  # up to and with the last magnet release
    assert all(isinstance(r, Ack) for r in replies)
    # When to stop: mid-C (foot 1 flying), right after the swap, mid-E (foot 2 flying).
    until = {"foot1_in_air": 3.0, "after_swap": 4.05, "foot2_in_air": 5.0}[phase]
    host.run(until, step=0.05)
    r = host.robot
    magnets, q_before = r.magnets, r.q.copy()
    executing = r.current.msg.index if r.current is not None else None
    (ack,) = host.send(Estop())
    assert isinstance(ack, Ack) and r.faults & FaultFlag.ESTOP and r.mode == Mode.ESTOP
    assert r.magnets == magnets and r.magnets != 0  # nothing released, nothing grabbed
    assert np.allclose(r.q, q_before)  # joints stop where they are
    assert not r.busy and not r.buffer  # the queued magnet commands are dropped
    host.run(3.0)
    assert r.magnets == magnets and np.allclose(r.q, q_before) and r.feet_held() != 0
    if phase != "after_swap":
        assert executing is not None and r.interrupted is not None
        assert r.interrupted.msg.index == executing
    else:
        assert magnets == 0b11 or magnets == 0b01


def test_base_pose_anchors_and_the_wheels_drive_it() -> None:
    host = Host()
    track = ARA.wheel_track_m
    w = 0.05  # wheel speed of the in-place turn
    replies = host.program(
        [
            BasePose((10.0, 20.0, 1.0), (0.0, 0.0, math.pi / 2)),
            WheelSpeeds((0.1, 0.1), 2.0),  # 0.2 m forward: +y in the world
            WheelSpeeds((-w, w), 1.0),  # turn left by 2w/B rad
            WheelSpeeds((0.1, 0.1), 1.0),
        ]
    )
    assert all(isinstance(r, Ack) for r in replies)
    host.run(4.5, step=0.07)
    dyaw = 2 * w * 1.0 / track
    yaw = math.pi / 2 + dyaw
    want = np.array([10.0, 20.2, 1.0]) + 0.1 * np.array([math.cos(yaw), math.sin(yaw), 0.0])
    T = host.robot.base_pose()
    # Within the wire's quanta (µm, µrad) of the anchor.
    assert np.allclose(T[:3, 3], want, atol=1e-6)
    assert math.atan2(T[1, 0], T[0, 0]) == pytest.approx(yaw, abs=1e-6)
    # Odometry counters go on counting across an anchor.
    assert host.robot.odometry == pytest.approx([0.2 - w + 0.1, 0.2 + w + 0.1])
    # A re-anchor restarts the planar pose there.
    host.cmd(BasePose((0.0, 0.0, 0.0), (0.0, -math.pi / 2, 0.0)))  # on a vertical wall
    host.cmd(WheelSpeeds((0.1, 0.1), 1.0))
    host.run(1.5)
    assert np.allclose(host.robot.base_pose()[:3, 3], [0.0, 0.0, 0.1], atol=1e-6)


def test_feet_base_and_captures_survive_a_restart() -> None:
    host = Host()
    host.program([BasePose((1.0, 2.0, 3.0), (0.1, 0.2, 0.3)), SetMagnet(1, True)])
    host.program([JointMove(Q_CONV, 2.0)])
    host.run(1.0)
    host.robot.captures = 5
    host.robot.link_lost(now=host.t)
    data = json.loads(json.dumps(robot_state(host.robot)))
    assert data["feet_in_air"] == 0b01 and data["magnets"] == 0b10
    again = SimRobot(ARA, clock=lambda: 0.0)
    restore_robot_state(again, data)
    assert again.magnets == 0b10 and again.feet_in_air() == 0b01
    assert np.allclose(again.base_pose(), host.robot.base_pose())
    assert again.captures == 5 and np.allclose(again.q, host.robot.q)
    # Files from before the base pose was kept still load (at the origin).
    for key in ("base_anchor", "base_planar", "captures", "feet_in_air"):
        data.pop(key)
    older = SimRobot(ARA, clock=lambda: 0.0)
    restore_robot_state(older, data)
    assert np.allclose(older.base_pose(), np.eye(4)) and older.captures == 0


def test_robots_without_feet_rules_are_unchanged() -> None:
    generic = resolve_profile("generic")
    assert generic.feet is None
    host = Host(generic)
    (ack,) = host.send(JointMove((0.5,) * 6, 0.5).to_message(host.run_id, 0))
    assert isinstance(ack, Ack)
