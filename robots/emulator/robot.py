"""The robot side of the protocol and a kinematic simulation, without any I/O.

:class:`SimRobot` is what firmware on an Arduino or an IPC would implement
(docs/protocol.md §7): session handling, in-order acceptance with remembered
replies, the command buffer, the watchdog, E-stop, latched faults — plus a
simulation that executes commands in simulated time
(``sim seconds = wall seconds × time_scale``).  The caller (the transport in
:mod:`robots.emulator.server`) feeds it decoded messages and the current
monotonic time and sends what it returns; keeping I/O out makes it testable
without sockets.

Every command it starts is recorded in :attr:`SimRobot.log` with its run id and
index, ending ``done`` or ``interrupted`` — the evidence tests use to assert
that nothing was lost or executed twice (:func:`check_exactly_once`).

Continuation (docs/protocol.md §8.2): a command stopped mid-motion (link loss,
watchdog, ``ABORT``, new session, fault, E-stop, power-down) is remembered as
:class:`Interrupted` ``(run_id, index, progress)``.  When the host sends that
same command again — a resume — the robot executes only the remainder:

- ``CMD_WHEELS`` (relative): the same speeds for ``duration − done``, so the
  odometry ends exactly at ``speeds × duration``;
- ``CMD_JOINTS`` / ``CMD_LIFT`` (absolute targets): from where the joints are
  to the same target, in ``duration × f`` where ``f = max_j |target_j − q_j| /
  |target_j − q_start_j|`` over the joints the command moves (``q_start``: the
  pose the command first started from).  Every joint then moves at most at its
  planned speed; a command that moves nothing (a dwell) waits out its
  remaining time;
- magnet, plate, nozzle, stop: absolute states, applied (idempotent).

Any other command or run clears the memory; completed commands stay refused
(``ALREADY_DONE``).  ``CMD_BASE_POSE`` and ``CMD_CAPTURE`` take no time: they
are never interrupted, and a resume does not repeat them.

Feet (two-footed robots, :mod:`robots.emulator.feet`): a command that would
let the robot fall is refused and latches ``FALL_RISK`` (``fault_code`` = the
:class:`~robots.protocol.messages.FallRule`), stopping the robot like any
fault.  It is refused when it arrives (``NAK FALL_RISK``) if the state it
would start from — the current state carried through the queued commands —
breaks a rule, and again at the moment it would start (a safety net: a
restored or continued state).  An E-stop stops the joints where they are
and leaves both magnets as they are.

Base pose and camera: ``CMD_BASE_POSE`` anchors the base in the program's
world frame; wheel motion then moves it in its own x–y plane (differential
drive: even wheels left, odd wheels right, ``profile.wheel_track_m``).
``CMD_CAPTURE`` renders what the camera sees of :attr:`SimRobot.world`
(:mod:`robots.emulator.camera`) and queues a ``CAPTURE`` header and its
``CAPTURE_CHUNK`` messages in :attr:`SimRobot.outbox`, which the transport
sends before the next state report.  The interruption and the continuation are separate
records (``progress``, ``continued_from``), so :func:`check_exactly_once` can
prove that no part of a motion was executed twice or skipped.
"""

from __future__ import annotations

import collections
import logging
import math
import time
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

import numpy as np

from robots.emulator.camera import World, render
from robots.emulator.faults import FaultConfig
from robots.emulator.feet import FEET_MASK
from robots.emulator.profiles import RobotProfile
from robots.protocol.capture import MAX_PENDING_CHUNKS, capture_messages, rpy_to_matrix
from robots.protocol.framing import PROTOCOL_MAJOR
from robots.protocol.messages import (
    ROBOT_FAULTS,
    Abort,
    Ack,
    AckStatus,
    BasePoseCmd,
    CaptureCmd,
    Clear,
    CommandMessage,
    Estop,
    FallRule,
    FaultFlag,
    Feature,
    Heartbeat,
    Hello,
    HelloAck,
    HelloStatus,
    JointsCmd,
    LiftCmd,
    MagnetCmd,
    Message,
    Mode,
    MsgType,
    Nak,
    NakReason,
    NozzleCmd,
    Pause,
    PlateCmd,
    Resume,
    State,
    StopCmd,
    WheelsCmd,
    is_sequenced,
)

log = logging.getLogger(__name__)

REPLY_MEMORY = 64  # replies remembered per session for repeated (retransmitted) seqs
#: Robot → host messages waiting for the transport at most (a few captures' worth).
MAX_OUTBOX = 4 * (1 + MAX_PENDING_CHUNKS)
LIMIT_TOL_URAD = 1  # one quantum of slack at the joint limits


PROGRESS_TOL = 1e-6  # progress fractions equal within this (float round-off)
TRAVEL_MIN_RAD = 1e-6  # a joint whose planned travel is below 1 µrad does not "move"


@dataclass(frozen=True)
class ExecutionRecord:
    """One command execution: started, then ``done`` or ``interrupted`` (why).

    ``progress``: fraction (0…1) of the *whole* command done when this record
    ended (1.0 for ``done``; ``None`` in logs of emulators that did not report
    it).  ``continued_from``: the progress this execution resumed from, or
    ``None`` when it started the command from its beginning.
    """

    run_id: int
    index: int
    op: str
    outcome: str  # "done" | "interrupted"
    reason: str
    sim_start_s: float
    sim_end_s: float
    wall_start: float  # time.monotonic()
    wall_end: float
    progress: float | None = None
    continued_from: float | None = None


@dataclass(frozen=True)
class Interrupted:
    """A command stopped mid-motion, remembered so that a resume continues it.

    ``done_s``: simulated seconds of the command executed (the remainder of a
    timed command is ``duration − done_s``); ``q_start``/``lift_start``: where
    the joints/lifting arm were when the command first started (the reference
    of the remaining-distance fraction).
    """

    msg: CommandMessage
    progress: float
    done_s: float
    q_start: tuple[float, ...]
    lift_start: float


@dataclass(frozen=True)
class StopEvent:
    """The robot stopped moving (or was told to while idle): when and why."""

    t: float  # time.monotonic() at the moment motion stopped
    reason: (
        str  # "estop" | "watchdog" | "link_lost" | "link_reset" | "abort" | "fault" | "shutdown"
    )
    moving: bool  # a command was executing
    index: int  # the command interrupted, −1 when none


@dataclass(frozen=True)
class CaptureInfo:
    """One capture the robot took: what it sent and how long the rendering took."""

    capture_id: int
    run_id: int
    index: int
    n_points: int
    render_ms: float
    camera_to_world: np.ndarray
    reason: str  # why it is empty ("" when the world was there)


def check_exactly_once(
    log: Iterable[ExecutionRecord], run_id: int, n: int, start: int = 0
) -> list[str]:
    """Problems (empty when none) with run ``run_id`` having executed commands
    ``start … n−1`` each exactly once, in order, with nothing repeated or skipped.

    A command interrupted mid-motion and then *continued* is fine when each
    continuation resumes from exactly the progress its interruption recorded
    (nothing done twice, nothing lost).  Problems: a command completed twice,
    completed out of order, never completed, started again after completing,
    started again from its beginning after part of it was done (the motion
    repeated), or continued from another progress than the one recorded (or
    from a part missing from the log).  Records without ``progress`` (older
    logs) are only checked for completion.
    """
    problems: list[str] = []
    done: list[int] = []
    completed: set[int] = set()
    seen: set[int] = set()
    reached: dict[int, float | None] = {}  # index → progress of its last interruption
    for r in log:
        if r.run_id != run_id:
            continue
        if r.index in completed:
            problems.append(f"command {r.index} started again after completing ({r.outcome})")
        before = reached.get(r.index)
        if r.continued_from is None:
            if before is not None and before > PROGRESS_TOL:
                problems.append(
                    f"command {r.index} started again from its beginning after "
                    f"{before:.1%} of it was done (motion repeated)"
                )
        elif r.index not in seen:
            problems.append(
                f"command {r.index} continued from {r.continued_from:.1%} "
                "but its first part is not in the log"
            )
        elif before is not None and abs(r.continued_from - before) > PROGRESS_TOL:
            what = "repeated" if r.continued_from < before else "skipped"
            problems.append(
                f"command {r.index} continued from {r.continued_from:.4%} after an "
                f"interruption at {before:.4%} (motion {what})"
            )
        seen.add(r.index)
        if r.outcome == "done":
            done.append(r.index)
            completed.add(r.index)
        else:
            reached[r.index] = r.progress
    expected = list(range(start, n))
    if done != expected:
        counts = Counter(done)
        dup = sorted(i for i, c in counts.items() if c > 1)
        missing = sorted(set(expected) - set(done))
        extra = sorted(set(done) - set(expected))
        if dup:
            problems.append(f"completed more than once: {dup}")
        if missing:
            problems.append(f"never completed: {missing[:20]}{'…' if len(missing) > 20 else ''}")
        if extra:
            problems.append(f"completed but not expected: {extra[:20]}")
        if not (dup or missing or extra):
            problems.append("completed out of order")
    return problems


@dataclass
class _Segment:
    """The executing command (or the remainder of an interrupted one)."""

    msg: CommandMessage
    duration: float  # sim seconds of this segment (the remainder when continuing)
    elapsed: float = 0.0
    q_from: np.ndarray | None = None  # joints at the start of this segment
    lift_from: float = 0.0
    fault_at: float | None = None  # sim seconds into the segment
    sim_start: float = 0.0
    wall_start: float = 0.0
    planned: float = 0.0  # the command's full duration, sim seconds
    done_before: float = 0.0  # sim seconds of the command executed before this segment
    q_start: np.ndarray | None = None  # joints when the command first started
    lift_start: float = 0.0
    continued_from: float | None = None  # progress resumed from; None: a fresh start


@dataclass
class SimRobot:
    """Protocol state machine and kinematic simulation of one robot."""

    profile: RobotProfile
    buffer_capacity: int = 16
    time_scale: float = 1.0
    state_period_s: float = 0.1
    #: Progress (a command queued, started or done) is reported at most this
    #: often; a halt, an E-stop, a fault, a new session or an operator command
    #: (pause, resume, abort, clear) at once.  Firmware reports at a bounded rate
    #: too: at a time scale of 10 a report per change was ~300 frames a second
    #: for the host to verify and decode, none of them telling it anything the
    #: next one does not (``last_done`` is cumulative).
    min_report_gap_s: float = 0.02
    max_watchdog_s: float = 2.0
    faults_injected: FaultConfig = field(default_factory=FaultConfig)
    clock: Callable[[], float] = time.monotonic
    on_record: Callable[[ExecutionRecord], None] | None = None
    on_stop: Callable[[StopEvent], None] | None = None  # each StopEvent, as it happens
    # Called whenever the robot comes to rest or its kept state changes at rest
    # (halt, completion of a command, pause, clear): where a robot saves to NV memory.
    on_rest: Callable[[], None] | None = None
    #: What the camera sees (``--world``); ``None``: captures are empty (and say why).
    world: World | None = None
    camera_seed: int = 0  # seeds the range noise (with the capture id)

    def __post_init__(self) -> None:
        lim = self.profile.joint_limits
        self.q = np.clip(np.zeros(self.profile.n_joints), lim[:, 0], lim[:, 1])
        self.lift = self.profile.lift_limits[0] if self.profile.lift_limits else 0.0
        self.wheel_speeds = np.zeros(self.profile.n_wheels)
        self.odometry = np.zeros(self.profile.n_wheels)  # metres
        self.magnets = 0
        self.plates = 0
        self.nozzle = False
        # Base pose: the last CMD_BASE_POSE (world ← anchor) and the planar pose
        # (x, y, yaw) the wheels drove since, in the anchor's x–y plane.
        self.base_anchor = np.eye(4)
        self.base_planar = np.zeros(3)
        self.captures = 0  # captures taken so far (the last capture id)
        self.capture_log: collections.deque[CaptureInfo] = collections.deque(maxlen=256)
        self.outbox: collections.deque[Message] = collections.deque()
        self.faults = 0
        self.fault_code = 0
        self.paused = False
        self.run_id = 0
        self.last_done = -1
        self.last_queued = -1
        self.buffer: collections.deque[CommandMessage] = collections.deque()
        self.current: _Segment | None = None
        self.interrupted: Interrupted | None = None  # command to continue on resume
        self.session = False
        self.expected_seq = 1
        self.replies: collections.OrderedDict[int, Message] = collections.OrderedDict()
        self.watchdog_s = 0.5
        self.last_host_rx = self.clock()
        self.sim_t = 0.0
        self._wall_t = self.clock()
        self.log: list[ExecutionRecord] = []
        self.stops: list[StopEvent] = []
        self.changed = False  # a state report is owed
        self.urgent = False  # … and must go out at once, not at the next report slot
        self._last_report = -float("inf")
        # Evidence for tests: retransmissions seen, gaps, commands answered ALREADY_DONE.
        self.counters: collections.Counter[str] = collections.Counter()
        self._nak_left = self.faults_injected.nak_times
        self._fault_left = self.faults_injected.fault_times

    # --- derived ---------------------------------------------------------------------

    @property
    def busy(self) -> bool:
        """Executing or holding queued commands (what the watchdog protects)."""
        return self.current is not None or bool(self.buffer)

    @property
    def mode(self) -> Mode:
        if self.faults & FaultFlag.ESTOP:
            return Mode.ESTOP
        if self.faults:
            return Mode.FAULT
        if self.paused:
            return Mode.PAUSED
        if self.current is not None:
            return Mode.MOVING
        return Mode.IDLE

    def report(self) -> State:
        lim32 = 2**31
        odo = [int((round(v * 1e6) + lim32) % 2**32 - lim32) for v in self.odometry]
        return State(
            mode=self.mode,
            faults=self.faults,
            fault_code=self.fault_code,
            run_id=self.run_id,
            last_done=self.last_done,
            executing=self.current.msg.index if self.current else -1,
            buffer_level=len(self.buffer) + (1 if self.current else 0),
            t_ms=int(self.sim_t * 1000) & 0xFFFFFFFF,
            magnets=self.magnets,
            plates=self.plates,
            nozzle=self.nozzle,
            lift_urad=round(self.lift * 1e6),
            q_urad=tuple(round(v * 1e6) for v in self.q),
            odometry_um=tuple(odo),
        )

    def hello_ack(self, status: int = HelloStatus.OK) -> HelloAck:
        p = self.profile
        return HelloAck(
            status=status,
            watchdog_ms=round(self.watchdog_s * 1000),
            state_period_ms=round(self.state_period_s * 1000),
            buffer_capacity=self.buffer_capacity,
            n_joints=p.n_joints,
            n_wheels=p.n_wheels,
            n_magnets=p.n_magnets,
            n_plates=p.n_plates,
            features=(Feature.LIFT_ARM if p.lift_limits else 0)
            | (Feature.NOZZLE if p.nozzle else 0)
            | (Feature.CAMERA if p.camera is not None else 0),
            run_id=self.run_id,
            last_done=self.last_done,
            name=p.name[:32],
        )

    # --- time --------------------------------------------------------------------------

    def next_deadline(self) -> float | None:
        """Monotonic time of the next internal event (segment end, fault, watchdog)."""
        deadlines = []
        if self.current is not None and not self.paused and not self.faults:
            seg = self.current
            end = seg.duration if seg.fault_at is None else min(seg.duration, seg.fault_at)
            deadlines.append(self._wall_t + max(0.0, end - seg.elapsed) / self.time_scale)
        if self.busy and self.session:
            deadlines.append(self.last_host_rx + self.watchdog_s)
        return min(deadlines) if deadlines else None

    def advance(self, now: float | None = None) -> None:
        """Run the simulation up to ``now`` and check the watchdog."""
        now = self.clock() if now is None else now
        dt = max(0.0, now - self._wall_t) * self.time_scale
        self._wall_t = now
        late = now - self.last_host_rx - self.watchdog_s
        if self.busy and self.session and late > 0:
            # The watchdog stops motion at its deadline, not at this (late) call.
            before = max(0.0, dt - late * self.time_scale)
            self._run(before, now)
            if self.busy:
                self._halt("watchdog", now, latch=FaultFlag.WATCHDOG)
            self.sim_t += dt - before
            return
        self._run(dt, now)

    def _run(self, dt: float, now: float) -> None:
        remaining = dt
        while True:
            if self.faults or self.paused:
                break
            if self.current is None:
                if not self.buffer:
                    break
                self._start(self.buffer.popleft(), now)
                continue
            seg = self.current
            stop_at = seg.duration if seg.fault_at is None else min(seg.duration, seg.fault_at)
            step = min(max(0.0, stop_at - seg.elapsed), remaining)
            self._move(seg, step)
            seg.elapsed += step
            remaining -= step
            self.sim_t += step
            if seg.fault_at is not None and seg.elapsed >= seg.fault_at - 1e-12:
                self._halt(
                    "fault", now, latch=FaultFlag.DRIVE, code=self.faults_injected.fault_code
                )
                break
            if seg.elapsed >= seg.duration - 1e-12:
                self._complete(seg, now)
                continue
            break
        self.sim_t += max(0.0, remaining)

    def _start(self, msg: CommandMessage, now: float) -> None:
        rule = self._fall_rule(msg, self.magnets, self.q)
        if rule is not None:
            # The queue-time check let it through, so the state changed under it
            # (a restored state, a continued command): refuse it here, unstarted.
            self.counters["fall_risk_at_start"] += 1
            self._fall(rule, msg, now)
            return
        planned = getattr(msg, "duration_ms", 0) / 1000.0
        seg = _Segment(msg, planned, sim_start=self.sim_t, wall_start=now, planned=planned)
        seg.q_from = self.q.copy()
        seg.lift_from = self.lift
        seg.q_start = self.q.copy()
        seg.lift_start = self.lift
        mem, self.interrupted = self.interrupted, None  # any other command forgets it
        if mem is not None and (mem.msg.run_id, mem.msg.index) == (msg.run_id, msg.index):
            if mem.msg == msg:
                self._continue(seg, mem)
            else:
                # Same slot, other content: not a resume of what was interrupted.
                self.counters["continuation_mismatch"] += 1
        inj = self.faults_injected
        if (
            inj.fault_at_index is not None
            and msg.index == inj.fault_at_index
            and self._fault_left > 0
        ):
            self._fault_left -= 1
            seg.fault_at = seg.duration / 2
        if isinstance(msg, WheelsCmd):
            self.wheel_speeds = np.asarray(msg.speeds_um_s, dtype=float) / 1e6
        else:
            # Commands run one at a time: wheels turn only during a wheels command.
            self.wheel_speeds[:] = 0.0
        self.current = seg
        self.changed = True

    def _continue(self, seg: _Segment, mem: Interrupted) -> None:
        """Turn ``seg`` into the remainder of the interrupted command ``mem``."""
        msg = seg.msg
        seg.continued_from = mem.progress
        seg.q_start = np.asarray(mem.q_start, dtype=float)
        seg.lift_start = mem.lift_start
        self.counters["continuations"] += 1
        if isinstance(msg, JointsCmd | LiftCmd):
            # Absolute target: continue to it at no more than the planned joint speed.
            frac = self._remaining_fraction(seg)
            if frac is None:  # a dwell: wait out the remaining time
                seg.done_before = min(seg.planned, mem.done_s)
                seg.duration = seg.planned - seg.done_before
            else:
                seg.duration = seg.planned * frac
                seg.done_before = max(0.0, seg.planned - seg.duration)
        else:
            # Wheels are relative: only the time not yet driven, at the same speeds.
            seg.done_before = min(seg.planned, mem.done_s)
            seg.duration = seg.planned - seg.done_before

    def _remaining_fraction(self, seg: _Segment) -> float | None:
        """max_j |target − now| / |target − start| over the joints the command moves;
        ``None`` when it moves none (or is no joint/lift command)."""
        msg = seg.msg
        if isinstance(msg, JointsCmd) and seg.q_start is not None:
            target = np.asarray(msg.q_urad, dtype=float) / 1e6
            travel = np.abs(target - seg.q_start)
            left = np.abs(target - self.q)
        elif isinstance(msg, LiftCmd):
            target_l = msg.angle_urad / 1e6
            travel = np.array([abs(target_l - seg.lift_start)])
            left = np.array([abs(target_l - self.lift)])
        else:
            return None
        moves = travel > TRAVEL_MIN_RAD
        if not moves.any():
            return None
        return float(max(0.0, np.max(left[moves] / travel[moves])))

    def _progress(self, seg: _Segment) -> float:
        """Fraction of the whole command done now (distance for joints/lift, else time)."""
        frac = self._remaining_fraction(seg)
        if frac is not None:
            return min(1.0, max(0.0, 1.0 - frac))
        if seg.planned <= 0:
            return 0.0  # an instantaneous command that did not complete did nothing
        return min(1.0, (seg.done_before + seg.elapsed) / seg.planned)

    def resume_point(self) -> Interrupted | None:
        """What the robot would continue on a resume if it stopped now: the
        executing command at its progress, else the remembered interruption."""
        seg = self.current
        if seg is None:
            return self.interrupted
        assert seg.q_start is not None
        return Interrupted(
            msg=seg.msg,
            progress=self._progress(seg),
            done_s=min(seg.planned, seg.done_before + seg.elapsed),
            q_start=tuple(float(v) for v in seg.q_start),
            lift_start=float(seg.lift_start),
        )

    def _move(self, seg: _Segment, step: float) -> None:
        msg = seg.msg
        frac = 1.0 if seg.duration <= 0 else min(1.0, (seg.elapsed + step) / seg.duration)
        if isinstance(msg, JointsCmd) and seg.q_from is not None:
            target = np.asarray(msg.q_urad, dtype=float) / 1e6
            self.q = seg.q_from + (target - seg.q_from) * frac
        elif isinstance(msg, LiftCmd):
            self.lift = seg.lift_from + (msg.angle_urad / 1e6 - seg.lift_from) * frac
        elif isinstance(msg, WheelsCmd):
            self.odometry += self.wheel_speeds * step
            self._drive_base(step)

    def _drive_base(self, step: float) -> None:
        """Integrate the planar base pose over ``step`` s at the current wheel speeds
        (differential drive, exact for constant speeds: an arc)."""
        sp = self.wheel_speeds
        if len(sp) < 2 or step <= 0:
            return
        left, right = float(np.mean(sp[0::2])), float(np.mean(sp[1::2]))
        v = 0.5 * (left + right)
        w = (right - left) / self.profile.wheel_track_m
        x, y, th = self.base_planar
        dth = w * step
        if abs(dth) < 1e-12:
            x += v * step * math.cos(th)
            y += v * step * math.sin(th)
        else:
            x += v / w * (math.sin(th + dth) - math.sin(th))
            y -= v / w * (math.cos(th + dth) - math.cos(th))
        self.base_planar = np.array([x, y, math.remainder(th + dth, math.tau)])

    def base_pose(self) -> np.ndarray:
        """Base → world (4, 4): the last anchor, then the planar motion since."""
        x, y, th = self.base_planar
        c, s = math.cos(th), math.sin(th)
        planar = np.array([[c, -s, 0.0, x], [s, c, 0.0, y], [0.0, 0.0, 1.0, 0.0], [0, 0, 0, 1.0]])
        return self.base_anchor @ planar

    def camera_pose(self) -> np.ndarray | None:
        """Camera → world (4, 4), ``None`` without a camera."""
        cam = self.profile.camera
        return None if cam is None else self.base_pose() @ cam.camera_to_base

    def feet_in_air(self) -> int:
        """Bits of the feet in the air now (0 for robots without feet rules)."""
        feet = self.profile.feet
        return 0 if feet is None else feet.in_air(self.magnets, self.q)

    def feet_held(self) -> int:
        """Bits of the feet held now (by magnets, or by the wheels in mobile mode)."""
        feet = self.profile.feet
        return FEET_MASK if feet is None else feet.held(self.magnets, self.q)

    def _fall_rule(self, msg: CommandMessage, magnets: int, q: np.ndarray) -> FallRule | None:
        feet = self.profile.feet
        return None if feet is None else feet.refusal(msg, magnets, q)

    def _projected(self) -> tuple[int, np.ndarray]:
        """Magnets and joints once the executing and queued commands are done."""
        magnets, q = self.magnets, self.q
        cmds = ([self.current.msg] if self.current is not None else []) + list(self.buffer)
        for m in cmds:
            if isinstance(m, MagnetCmd):
                magnets = _set_bit(magnets, m.magnet, m.touched)
            elif isinstance(m, JointsCmd):
                q = np.asarray(m.q_urad, dtype=float) / 1e6
        return magnets, q

    def _fall(self, rule: FallRule, msg: CommandMessage, now: float) -> None:
        """Refuse ``msg``: the robot would fall.  Latch FALL_RISK and stop."""
        log.warning(
            "robot %s: refused run %d command %d (%s): %s; FALL_RISK latched",
            self.profile.name,
            msg.run_id,
            msg.index,
            MsgType(msg.TYPE).name,
            rule.name,
        )
        self.counters["fall_risk"] += 1
        self._halt("fall_risk", now, latch=FaultFlag.FALL_RISK, code=int(rule))

    def _capture(self, msg: CaptureCmd) -> None:
        """Take one frame and queue its header and chunks for the host."""
        cam = self.profile.camera
        assert cam is not None  # refused in _validate otherwise
        self.captures += 1
        cid = self.captures
        T_wc = self.base_pose() @ cam.camera_to_base
        t0 = time.perf_counter()
        pts = np.zeros((0, 3), dtype=np.float32)
        inten = None
        if self.world is None:
            reason = "no world loaded (start the emulator with --world PATH)"
        else:
            cloud, reason = self.world.current()
            if cloud is not None:
                rng = np.random.default_rng([self.camera_seed, cid])
                pts, inten = render(cam, cloud, None, T_wc, rng)
        spent = time.perf_counter() - t0
        ms = spent * 1000.0
        # The camera is not the link: time spent rendering (or loading a new
        # world) is not time the host was silent.
        self.last_host_rx += spent
        if reason:
            log.warning(
                "robot %s: capture %d (run %d command %d) has no points: %s",
                self.profile.name,
                cid,
                msg.run_id,
                msg.index,
                reason,
            )
        self.capture_log.append(
            CaptureInfo(cid, msg.run_id, msg.index, len(pts), ms, T_wc.copy(), reason)
        )
        self.counters["captures"] += 1
        for m in capture_messages(
            capture_id=cid,
            run_id=msg.run_id,
            index=msg.index,
            t_s=self.sim_t,
            camera_to_world=T_wc,
            points_m=pts,
            intensity=inten,
        ):
            self.outbox.append(m)
        while len(self.outbox) > MAX_OUTBOX:
            self.outbox.popleft()
            self.counters["outbox_dropped"] += 1

    def take_outbox(self) -> list[Message]:
        """Robot → host messages waiting to go (captures), oldest first; empties it."""
        out = list(self.outbox)
        self.outbox.clear()
        return out

    def _complete(self, seg: _Segment, now: float) -> None:
        msg = seg.msg
        if isinstance(msg, MagnetCmd):
            self.magnets = _set_bit(self.magnets, msg.magnet, msg.touched)
        elif isinstance(msg, PlateCmd):
            self.plates = _set_bit(self.plates, msg.plate, msg.engaged)
        elif isinstance(msg, NozzleCmd):
            self.nozzle = msg.on
        elif isinstance(msg, StopCmd | WheelsCmd):
            self.wheel_speeds[:] = 0.0
        elif isinstance(msg, BasePoseCmd):
            T = np.eye(4)
            T[:3, :3] = rpy_to_matrix(
                [msg.roll_urad / 1e6, msg.pitch_urad / 1e6, msg.yaw_urad / 1e6]
            )
            T[:3, 3] = np.array([msg.x_um, msg.y_um, msg.z_um], dtype=float) / 1e6
            self.base_anchor = T
            self.base_planar = np.zeros(3)
        elif isinstance(msg, CaptureCmd):
            self._capture(msg)
        self.current = None
        self.last_done = msg.index
        self._record(seg, "done", "", now, progress=1.0)
        self.changed = True
        self._rested()

    def _rested(self) -> None:
        if self.on_rest is not None:
            self.on_rest()

    def _record(
        self, seg: _Segment, outcome: str, reason: str, now: float, *, progress: float
    ) -> None:
        rec = ExecutionRecord(
            run_id=seg.msg.run_id,
            index=seg.msg.index,
            op=MsgType(seg.msg.TYPE).name.removeprefix("CMD_").lower(),
            outcome=outcome,
            reason=reason,
            sim_start_s=seg.sim_start,
            sim_end_s=self.sim_t,
            wall_start=seg.wall_start,
            wall_end=now,
            progress=progress,
            continued_from=seg.continued_from,
        )
        self.log.append(rec)
        if self.on_record is not None:
            self.on_record(rec)

    def _halt(self, reason: str, now: float, latch: int = 0, code: int = 0) -> None:
        """Stop all motion now and drop the queue; latch ``latch`` fault bits."""
        moving = self.current is not None
        index = self.current.msg.index if self.current else -1
        if self.current is not None:
            # Remembered so that a resume of this command continues it (docs §8.2).
            self.interrupted = self.resume_point()
            assert self.interrupted is not None
            self._record(
                self.current, "interrupted", reason, now, progress=self.interrupted.progress
            )
            self.current = None
        self.buffer.clear()
        self.last_queued = self.last_done
        self.wheel_speeds[:] = 0.0
        self.paused = False
        self.faults |= latch
        if code:
            self.fault_code = code
        stop = StopEvent(now, reason, moving, index)
        self.stops.append(stop)
        if self.on_stop is not None:
            self.on_stop(stop)
        self.changed = self.urgent = True
        self._rested()

    # --- report pacing -----------------------------------------------------------------

    def report_due(self, now: float) -> bool:
        """A state report is owed and may go out at ``now`` (see ``min_report_gap_s``)."""
        return self.changed and (self.urgent or now - self._last_report >= self.min_report_gap_s)

    def report_at(self) -> float | None:
        """When an owed progress report may go out; ``None`` when none is owed."""
        return self._last_report + self.min_report_gap_s if self.changed else None

    def reported(self, now: float) -> None:
        """A state report (:meth:`report`) went out at ``now``."""
        self.changed = self.urgent = False
        self._last_report = now

    # --- messages ----------------------------------------------------------------------

    def power_down(self, now: float | None = None) -> None:
        """The robot is switched off cleanly (emulator exit): stop first, so that
        what it keeps is a state at rest; latches ``LINK_RESET`` if it was busy."""
        now = self.clock() if now is None else now
        self.advance(now)
        if self.busy or self.paused:
            self._halt("shutdown", now, latch=FaultFlag.LINK_RESET)
        self.session = False

    def link_lost(self, now: float | None = None) -> None:
        """The transport knows the connection dropped (TCP): stop at once if busy."""
        now = self.clock() if now is None else now
        self.advance(now)
        if self.busy or self.paused:
            self._halt("link_lost", now, latch=FaultFlag.LINK_RESET)
        self.session = False

    def receive(self, msg: Message, seq: int, now: float | None = None) -> list[Message]:
        """Handle one message from the host; returns the replies to send, in order."""
        now = self.clock() if now is None else now
        self.advance(now)
        self.last_host_rx = now  # any valid frame feeds the watchdog
        if isinstance(msg, Estop):
            if not self.faults & FaultFlag.ESTOP or self.busy:
                self._halt("estop", now, latch=FaultFlag.ESTOP)
            return [Ack(ref_type=MsgType.ESTOP, ref_seq=seq, buffer_free=self._free())]
        if isinstance(msg, Hello):
            return self._hello(msg, seq, now)
        if isinstance(msg, Heartbeat) or not is_sequenced(msg.TYPE):
            return []
        if not self.session:
            return [Nak(ref_type=msg.TYPE, ref_seq=seq, reason=NakReason.NOT_READY)]
        diff = (seq - self.expected_seq) & 0xFFFF
        if diff >= 0x8000:
            self.counters["duplicates"] += 1
            old = self.replies.get(seq)  # a retransmission: repeat the first answer
            return [old] if old is not None else []
        if diff != 0:
            self.counters["gaps"] += 1
            return [
                Nak(
                    ref_type=msg.TYPE,
                    ref_seq=seq,
                    reason=NakReason.SEQ_GAP,
                    expected_seq=self.expected_seq,
                )
            ]
        reply = self._apply(msg, seq, now)
        if isinstance(reply, Nak) and reply.transient:
            return [reply]  # not consumed: the host sends this seq again
        self.expected_seq = (self.expected_seq + 1) & 0xFFFF
        self.replies[seq] = reply
        while len(self.replies) > REPLY_MEMORY:
            self.replies.popitem(last=False)
        return [reply]

    def receive_invalid(self, msg_type: int, seq: int, now: float | None = None) -> list[Message]:
        """A frame with a valid CRC whose type is unknown or whose payload does not parse.

        A sequenced one is refused ``INVALID`` (consuming its seq, so the host's
        later frames still get through); anything else is ignored.
        """
        now = self.clock() if now is None else now
        self.advance(now)
        self.last_host_rx = now
        if not is_sequenced(msg_type) or not self.session:
            return []
        diff = (seq - self.expected_seq) & 0xFFFF
        if diff >= 0x8000:
            old = self.replies.get(seq)
            return [old] if old is not None else []
        if diff != 0:
            return [
                Nak(
                    ref_type=msg_type,
                    ref_seq=seq,
                    reason=NakReason.SEQ_GAP,
                    expected_seq=self.expected_seq,
                )
            ]
        self.expected_seq = (self.expected_seq + 1) & 0xFFFF
        reply = Nak(
            ref_type=msg_type,
            ref_seq=seq,
            reason=NakReason.INVALID,
            expected_seq=self.expected_seq,
            detail=-1,
        )
        self.replies[seq] = reply
        return [reply]

    def _hello(self, msg: Hello, seq: int, now: float) -> list[Message]:
        if msg.major != PROTOCOL_MAJOR:
            self.session = False
            return [self.hello_ack(HelloStatus.VERSION_UNSUPPORTED)]
        # A new session means the host lost track of us: whatever was running stops.
        if self.busy or self.paused:
            self._halt("link_reset", now, latch=FaultFlag.LINK_RESET)
        self.session = True
        self.expected_seq = (seq + 1) & 0xFFFF
        self.replies.clear()
        self.watchdog_s = min(max(msg.watchdog_ms / 1000.0, 0.1), self.max_watchdog_s)
        self.changed = self.urgent = True
        return [self.hello_ack(), self.report()]

    def _free(self) -> int:
        return max(0, self.buffer_capacity - len(self.buffer) - (1 if self.current else 0))

    def _ack(self, msg: Message, seq: int, status: int = AckStatus.OK) -> Ack:
        return Ack(ref_type=msg.TYPE, ref_seq=seq, status=status, buffer_free=self._free())

    def _nak(self, msg: Message, seq: int, reason: int, detail: int = 0) -> Nak:
        return Nak(
            ref_type=msg.TYPE,
            ref_seq=seq,
            reason=reason,
            expected_seq=self.expected_seq,
            detail=max(-32768, min(32767, detail)),
        )

    def _apply(self, msg: Message, seq: int, now: float) -> Message:
        if isinstance(msg, Pause):
            self.paused = True
            self._rested()
        elif isinstance(msg, Resume):
            self.paused = False
        elif isinstance(msg, Abort):
            if self.busy or self.paused:
                self._halt("abort", now)
        elif isinstance(msg, Clear):
            self.faults &= ~msg.faults
            if msg.faults & ROBOT_FAULTS and not self.faults & ROBOT_FAULTS:
                self.fault_code = 0
            if not self.busy:
                self._rested()
        elif isinstance(msg, CommandMessage):
            return self._accept(msg, seq, now)
        self.changed = self.urgent = True
        return self._ack(msg, seq)

    def _accept(self, msg: CommandMessage, seq: int, now: float) -> Message:
        inj = self.faults_injected
        if inj.nak_index is not None and msg.index == inj.nak_index and self._nak_left > 0:
            self._nak_left -= 1
            self.counters["injected_naks"] += 1
            return self._nak(
                msg, seq, NakReason.INVALID if inj.nak_permanent else NakReason.BUSY, 0
            )
        if self.faults:
            return self._nak(msg, seq, NakReason.FAULTED, self.faults)
        problem = self._validate(msg)
        if problem is not None:
            return self._nak(msg, seq, *problem)
        if msg.run_id != self.run_id:
            if self.busy:
                return self._nak(msg, seq, NakReason.RUN_ACTIVE)
            self.run_id = msg.run_id
            self.last_done = self.last_queued = msg.index - 1
            self.interrupted = None  # another run: nothing of the old one to continue
        if msg.index <= self.last_done:
            self.counters["already_done"] += 1
            return self._ack(msg, seq, AckStatus.ALREADY_DONE)
        if msg.index <= self.last_queued:
            return self._ack(msg, seq)  # already queued in this session
        if msg.index != self.last_queued + 1:
            return self._nak(msg, seq, NakReason.INDEX, (self.last_queued + 1) & 0x7FFF)
        if self._free() == 0:
            return self._nak(msg, seq, NakReason.BUSY)
        rule = self._fall_rule(msg, *self._projected())
        if rule is not None:
            # Refused now rather than when its turn comes: the robot stops at once.
            self._fall(rule, msg, now)
            return self._nak(msg, seq, NakReason.FALL_RISK, int(rule))
        self.buffer.append(msg)
        self.last_queued = msg.index
        self.changed = True
        return self._ack(msg, seq)

    def _validate(self, msg: CommandMessage) -> tuple[int, int] | None:
        """``(reason, detail)`` when the robot cannot execute ``msg``."""
        p = self.profile
        if isinstance(msg, JointsCmd):
            if len(msg.q_urad) != p.n_joints:
                return NakReason.INVALID, len(msg.q_urad)
            lim = np.round(p.joint_limits * 1e6)
            for j, v in enumerate(msg.q_urad):
                if not lim[j, 0] - LIMIT_TOL_URAD <= v <= lim[j, 1] + LIMIT_TOL_URAD:
                    return NakReason.LIMIT, j
        elif isinstance(msg, WheelsCmd):
            if len(msg.speeds_um_s) != p.n_wheels:
                return NakReason.INVALID, len(msg.speeds_um_s)
        elif isinstance(msg, MagnetCmd):
            if msg.magnet >= p.n_magnets:
                return NakReason.INVALID, msg.magnet
        elif isinstance(msg, PlateCmd):
            if msg.plate >= p.n_plates:
                return NakReason.INVALID, msg.plate
        elif isinstance(msg, LiftCmd):
            if p.lift_limits is None:
                return NakReason.INVALID, 0
            lo, hi = (round(v * 1e6) for v in p.lift_limits)
            if not lo - LIMIT_TOL_URAD <= msg.angle_urad <= hi + LIMIT_TOL_URAD:
                return NakReason.LIMIT, 0
        elif (isinstance(msg, NozzleCmd) and not p.nozzle) or (
            isinstance(msg, CaptureCmd) and p.camera is None
        ):
            return NakReason.INVALID, 0
        return None


def _set_bit(mask: int, bit: int, on: bool) -> int:
    return mask | (1 << bit) if on else mask & ~(1 << bit)


__all__ = [
    "CaptureInfo",
    "ExecutionRecord",
    "Interrupted",
    "SimRobot",
    "StopEvent",
    "check_exactly_once",
]
