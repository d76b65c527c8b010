"""Robot emulator: a :class:`~robots.emulator.robot.SimRobot` behind TCP and/or a pty.

One daemon thread runs a ``selectors`` loop over the listening socket, the
current TCP connection, the pty master and a wake-up socket; it sleeps until
the next byte or the next timer (state report, end of a motion segment,
watchdog deadline, a delayed frame) — no polling.  Link fault injection
(drop, corrupt, delay) happens here; robot faults (NAK, fault mid-motion)
in the robot.

Authentication and the one-controller rule (docs/protocol.md §12) are
transport work and live here too, not in the simulated robot: every port
runs the challenge–response handshake against :attr:`Emulator.secret`
(random when none is given, so the emulator always enforces it) and every
frame except ``HELLO``/``AUTH``/``ESTOP`` must carry a valid MAC and a fresh
counter, or it is dropped and counted (``stats["frames_unauthenticated"]``)
before the robot sees it.  The authenticated port is the **controller**.  A
new TCP connection is a *candidate*: it may only handshake, and must
authenticate within :data:`AUTH_TIMEOUT_S` or it is closed.  While the
controller is alive (authenticated and heard from within
:data:`LINE_TIMEOUT_S`) a candidate's ``HELLO`` is refused (``CHALLENGE``
``LINE_BUSY``, then closed) unless it asks for a takeover, and even then only
its valid ``AUTH`` drops the old controller.  ``ESTOP`` is honoured without a
MAC from the controller's port, or from any port while no controller is
alive — stopping is always safe, and a stranger cannot reach the robot while
the line is held.

Usage in tests::

    with Emulator("denso_vm6083", time_scale=20) as emu:
        link = RobotLink(emu.url, LinkConfig(secret=emu.secret))  # socket://127.0.0.1:<port>
        ...
        assert not check_exactly_once(emu.execution_log(), run_id, len(program))
"""

from __future__ import annotations

import contextlib
import functools
import heapq
import itertools
import json
import logging
import os
import random
import selectors
import socket
import threading
import time
import tty
from collections.abc import Callable, Sequence
from dataclasses import asdict
from urllib.parse import urlsplit

import numpy as np

from robots.background_io import LineWriter
from robots.emulator.camera import World
from robots.emulator.faults import FaultConfig
from robots.emulator.persist import OrphanTimer, StateFile, remove_port_file, write_port_file
from robots.emulator.profiles import RobotProfile, resolve_profile
from robots.emulator.robot import CaptureInfo, ExecutionRecord, SimRobot, StopEvent
from robots.protocol.auth import (
    AuthError,
    ReplayError,
    SessionMac,
    check_secret,
    generate_secret,
    robot_challenge,
    robot_session,
)
from robots.protocol.framing import PROTOCOL_MAJOR, Frame, FrameDecoder
from robots.protocol.messages import (
    Ack,
    Challenge,
    Hello,
    HelloAck,
    HelloFlag,
    HelloStatus,
    Message,
    MessageError,
    MsgType,
    State,
    decode_message,
    encode_message,
)

log = logging.getLogger(__name__)

#: A connection that has not authenticated within this long is closed (it never holds the line).
AUTH_TIMEOUT_S = 2.0
#: The controller holds the line while its last authentic frame is younger than this.
LINE_TIMEOUT_S = 1.5
#: At most this many connections may be handshaking at once; the oldest goes first.
MAX_CANDIDATES = 4


def parse_listen(url: str) -> tuple[str, int]:
    """``tcp://HOST:PORT`` (or ``socket://``) → (host, port); port 0 picks a free one."""
    parts = urlsplit(url)
    if parts.scheme not in ("tcp", "socket") or not parts.hostname or parts.port is None:
        raise ValueError(f"listen address {url!r}: expected tcp://HOST:PORT")
    return parts.hostname, parts.port


class _Port:
    """One byte channel to the host (a TCP connection or the pty master)."""

    kind = "port"

    def __init__(self) -> None:
        self.decoder = FrameDecoder(accept_any_version=True)
        self.frames_rx = 0
        self.silent_until = 0.0
        self.closed = False
        self.opened_at = time.monotonic()
        # Handshake in progress: the HELLO, our CHALLENGE, the session it offers.
        self.hello: Hello | None = None
        self.challenge: Challenge | None = None
        self.pending: SessionMac | None = None
        # Set once the AUTH verified: only the controller's port has one.
        self.session: SessionMac | None = None
        self.last_auth_rx = 0.0

    def fileno(self) -> int:
        raise NotImplementedError

    def read(self) -> bytes | None:
        """Bytes available, b"" when none, None when the channel is gone."""
        raise NotImplementedError

    def write(self, data: bytes) -> bool:
        raise NotImplementedError

    def close(self) -> None:
        self.closed = True


class _TcpPort(_Port):
    kind = "tcp"

    def __init__(self, sock: socket.socket, peer: str) -> None:
        super().__init__()
        sock.setblocking(False)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.sock = sock
        self.peer = peer

    def fileno(self) -> int:
        return self.sock.fileno()

    def read(self) -> bytes | None:
        try:
            data = self.sock.recv(4096)
        except BlockingIOError:
            return b""
        except OSError:
            return None
        return data or None

    def write(self, data: bytes) -> bool:
        try:
            self.sock.send(data)  # a short write is line noise; the host recovers
            return True
        except BlockingIOError:
            return True
        except OSError:
            return False

    def close(self) -> None:
        super().close()
        with contextlib.suppress(OSError):
            self.sock.close()


class _PtyPort(_Port):
    kind = "pty"

    def __init__(self) -> None:
        super().__init__()
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        os.set_blocking(self.master, False)
        self.path = os.ttyname(self.slave)
        # Keeping our own slave fd open means the master never sees EIO when the
        # host closes and reopens the device (a reconnect).

    def fileno(self) -> int:
        return self.master

    def read(self) -> bytes | None:
        try:
            return os.read(self.master, 4096)
        except BlockingIOError:
            return b""
        except OSError:
            return b""  # EIO while no reader: nothing to read, not a failure

    def write(self, data: bytes) -> bool:
        # Nobody reading: like a UART with no cable attached, the bytes are lost.
        with contextlib.suppress(OSError):
            os.write(self.master, data)
        return True

    def close(self) -> None:
        super().close()
        for fd in (self.master, self.slave):
            with contextlib.suppress(OSError):
                os.close(fd)


class Emulator:
    """A protocol-speaking robot emulator on TCP and/or a pty; see the module docstring.

    ``robot`` names the robot (its limits come from ``joint_limits``, the
    robot's description, or a fallback — :func:`resolve_profile`).
    ``listen`` is ``tcp://HOST:PORT`` (port 0: any free port) or ``None``;
    ``pty=True`` adds a pseudo-terminal whose path (:attr:`pty_path`) a host
    opens like a serial device.  ``time_scale`` > 1 runs motions faster than
    real time (watchdog and link timing stay in real time).

    Surviving the server (:mod:`robots.emulator.persist`): ``state_file``
    loads the robot's kept state at construction if the file exists and writes
    it atomically whenever the robot comes to rest and on :meth:`close`;
    ``port_file`` announces ``{"pid", "url", "robot"}`` after binding;
    ``exit_when_orphaned_s`` ends the loop (state saved, ``on_orphaned``
    called, :attr:`orphaned` set) after that long with no controller and
    nothing executing.

    The camera (robots with one, e.g. the ARA): ``world`` is an ``.npz``
    point cloud in the program's world frame (:mod:`robots.emulator.camera`),
    reloaded whenever it changes; a file that exists but cannot be used
    raises :class:`~robots.emulator.camera.WorldError` here, a missing one
    only makes captures empty (it may appear later).  ``camera_seed`` seeds
    the range noise.  Captures go to the controller as ``CAPTURE`` +
    ``CAPTURE_CHUNK`` frames, before the state report that shows them done.
    """

    def __init__(
        self,
        robot: str = "generic",
        *,
        joint_limits: np.ndarray | Sequence | None = None,
        profile: RobotProfile | None = None,
        faults: FaultConfig | None = None,
        listen: str | None = "tcp://127.0.0.1:0",
        pty: bool = False,
        time_scale: float = 1.0,
        state_period_s: float = 0.1,
        buffer_capacity: int = 16,
        log_path: str | os.PathLike[str] | None = None,
        secret: bytes | None = None,
        state_file: str | os.PathLike[str] | None = None,
        port_file: str | os.PathLike[str] | None = None,
        exit_when_orphaned_s: float | None = None,
        on_orphaned: Callable[[], None] | None = None,
        world: str | os.PathLike[str] | None = None,
        camera_seed: int = 0,
    ) -> None:
        if exit_when_orphaned_s is not None and not exit_when_orphaned_s > 0:
            raise ValueError(f"exit_when_orphaned_s={exit_when_orphaned_s}: must be > 0")
        if listen is None and not pty:
            raise ValueError("the emulator needs a TCP listen address, a pty, or both")
        if time_scale <= 0:
            raise ValueError(f"time_scale={time_scale}: must be > 0")
        # No secret given: a random one, so the emulator still refuses everyone
        # who was not handed ``emu.secret``.
        self.secret: bytes = generate_secret() if secret is None else check_secret(secret)
        self.profile = profile or resolve_profile(robot, joint_limits)
        self.faults = faults or FaultConfig()
        self._listen = listen
        self._want_pty = pty
        # Records go through a writer thread: a write() throttled by the
        # kernel's dirty-page flushing must not stall the loop (its watchdog).
        self.world = World(world) if world is not None else None
        if self.world is not None:
            # A broken world is the caller's mistake: say so now, not at the first capture.
            self.world.load()
        self._log_file: LineWriter | None = LineWriter(log_path) if log_path is not None else None
        self.robot = SimRobot(
            self.profile,
            buffer_capacity=buffer_capacity,
            time_scale=time_scale,
            state_period_s=state_period_s,
            faults_injected=self.faults,
            on_record=self._write_record if self._log_file else None,
            on_stop=self._write_stop if self._log_file else None,
            world=self.world,
            camera_seed=camera_seed,
        )
        self._state_file = StateFile(state_file) if state_file is not None else None
        self._loop_prev = time.monotonic()
        self.loop_late_s = 0.0
        self.state_loaded = False  # the robot's state came from ``state_file``
        if self._state_file is not None:
            try:
                self.state_loaded = self._state_file.load_into(self.robot)
            except ValueError:
                if self._log_file is not None:
                    self._log_file.close()
                raise
            self.robot.on_rest = self._capture_state
        self._port_file = port_file
        self._orphan_after = exit_when_orphaned_s
        self._orphan: OrphanTimer | None = None
        self._on_orphaned = on_orphaned
        self.orphaned = False
        # One stream a direction: which received byte is corrupted then depends
        # on the received bytes alone, not on how reads and writes interleave,
        # so a seed corrupts the same bytes of the host's frames every run.
        self._rng = {d: random.Random(f"{self.faults.seed}/{d}") for d in ("rx", "tx")}
        self._lock = threading.RLock()
        self._cond = threading.Condition(self._lock)
        self._sel = selectors.DefaultSelector()
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._listener: socket.socket | None = None
        self._tcp: _TcpPort | None = None  # the controller's TCP connection (authenticated)
        self._candidates: list[_TcpPort] = []  # connections still handshaking
        self._controller: _Port | None = None  # the port whose session the robot obeys
        self._pty: _PtyPort | None = None
        self._thread: threading.Thread | None = None
        self._stop = False
        self._actions: list[Callable[[float], None]] = []
        self._delayed: list[tuple[float, int, Callable[[float], None]]] = []
        self._counter = itertools.count()
        self._tx_seq = 0
        self._next_state = 0.0
        self._drops_left = self.faults.drop_times if self.faults.drop_after_frames else 0
        self.address: tuple[str, int] | None = None
        self.stats: dict[str, int] = {
            "connections": 0,
            "frames_rx": 0,
            "frames_tx": 0,
            "frames_rejected": 0,
            "frames_corrupt": 0,
            "drops": 0,
            "bytes_corrupted": 0,
            "frames_unauthenticated": 0,  # dropped: no session, bad MAC, or replayed
            "frames_replayed": 0,  # of those: authentic but an old counter
            "auth_failures": 0,
            "connections_refused": 0,
            "sessions": 0,
            "takeovers": 0,
        }

    # --- lifecycle -----------------------------------------------------------------

    def start(self) -> Emulator:
        if self._thread is not None:
            return self
        self._sel.register(self._wake_r, selectors.EVENT_READ, self._on_wake)
        if self._listen is not None:
            host, port = parse_listen(self._listen)
            lst = socket.create_server((host, port), reuse_port=False)
            lst.setblocking(False)
            self._listener = lst
            self.address = lst.getsockname()[:2]
            self._sel.register(lst, selectors.EVENT_READ, self._on_accept)
        if self._want_pty:
            self._pty = _PtyPort()
            self._sel.register(self._pty, selectors.EVENT_READ, self._pty)
        if self._state_file is not None:
            self._state_file.start()
        if self._orphan_after is not None:
            self._orphan = OrphanTimer(self._orphan_after, time.monotonic())
        if self._port_file is not None:
            write_port_file(
                self._port_file,
                url=self.url if self.address is not None else None,
                robot=self.profile.name,
                pty=self._pty.path if self._pty is not None else None,
            )
        self._thread = threading.Thread(
            target=self._loop, name=f"emulator {self.profile.name}", daemon=True
        )
        self._thread.start()
        return self

    def close(self, timeout: float = 5.0) -> None:
        with self._lock:
            self._stop = True
        self._wake()
        if self._thread is not None:
            self._thread.join(timeout)
        with self._lock:
            # Come to rest, then keep that state: what a robot does when switched off.
            self.robot.power_down(time.monotonic())
            if self._state_file is not None:
                self._state_file.capture(self.robot)
        if self._state_file is not None:
            try:
                self._state_file.close()  # joins the writer, then writes the last state
            except OSError:
                log.exception("emulator %s: cannot save its state", self.profile.name)
        if self._port_file is not None:
            remove_port_file(self._port_file)
        for port in (self._tcp, self._pty, *self._candidates):
            if port is not None:
                port.close()
        if self._listener is not None:
            self._listener.close()
        self._wake_r.close()
        self._wake_w.close()
        self._sel.close()
        if self._log_file is not None:
            self._log_file.close()
            self._log_file = None

    def __enter__(self) -> Emulator:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def url(self) -> str:
        """pyserial URL of the TCP endpoint (``socket://host:port``)."""
        if self.address is None:
            raise RuntimeError("the emulator has no TCP endpoint (started with listen=None?)")
        return f"socket://{self.address[0]}:{self.address[1]}"

    @property
    def pty_path(self) -> str:
        if self._pty is None:
            raise RuntimeError("the emulator has no pty (start it with pty=True)")
        return self._pty.path

    # --- observation (thread-safe) -------------------------------------------------

    def execution_log(self) -> list[ExecutionRecord]:
        with self._lock:
            return list(self.robot.log)

    def stop_events(self) -> list[StopEvent]:
        with self._lock:
            return list(self.robot.stops)

    def capture_log(self) -> list[CaptureInfo]:
        """The captures taken so far (the last 256): id, point count, render time, pose."""
        with self._lock:
            return list(self.robot.capture_log)

    def snapshot(self) -> State:
        """The state report the robot would send now."""
        with self._lock:
            self.robot.advance()
            return self.robot.report()

    def wait_for(self, predicate: Callable[[Emulator], bool], timeout: float) -> bool:
        """Block until ``predicate(self)`` is true; re-checked after every loop turn.

        The predicate runs with the emulator locked: read ``self.robot`` freely.
        """
        with self._cond:
            return self._cond.wait_for(lambda: predicate(self), timeout)

    # --- manual fault triggers (tests, console) ----------------------------------------

    def drop_link(self, silence_s: float | None = None) -> None:
        """Drop the current link now (close TCP; or silence for ``silence_s``)."""
        self._do(lambda now: self._drop_all(now, silence_s))

    def raise_fault(self, code: int = 1) -> None:
        """Latch a DRIVE fault now (stops motion)."""
        from robots.protocol.messages import FaultFlag

        self._do(lambda now: self.robot._halt("fault", now, latch=FaultFlag.DRIVE, code=code))

    # --- loop ------------------------------------------------------------------------

    def _do(self, action: Callable[[float], None]) -> None:
        with self._lock:
            self._actions.append(action)
        self._wake()

    def _wake(self) -> None:
        with contextlib.suppress(OSError):
            self._wake_w.send(b"\x00")

    def _on_wake(self, now: float) -> None:
        try:
            while self._wake_r.recv(4096):
                pass
        except (BlockingIOError, OSError):
            pass

    def _loop(self) -> None:
        try:
            while True:
                with self._lock:
                    if self._stop:
                        return
                    timeout = self._timeout(time.monotonic())
                events = self._sel.select(timeout)
                with self._lock:
                    now = time.monotonic()
                    # How late this wake-up is: a watchdog stop is only evidence
                    # of a silent host when the loop itself was on time.
                    self.loop_late_s = max(0.0, now - self._loop_prev - timeout)
                    self._loop_prev = now
                    for key, _ in events:
                        handler = key.data
                        if isinstance(handler, _Port):
                            self._on_readable(handler, now)
                        else:
                            handler(now)
                    actions, self._actions = self._actions, []
                    for action in actions:
                        action(now)
                    self._expire_candidates(now)
                    self._tick(now)
                    self._cond.notify_all()
        except Exception:  # pragma: no cover - keep the reason visible
            log.exception("emulator %s crashed", self.profile.name)

    def _timeout(self, now: float) -> float:
        period = self.robot.state_period_s
        deadlines = [self._next_state]
        report_at = self.robot.report_at()
        if report_at is not None:
            deadlines.append(report_at)
        robot_deadline = self.robot.next_deadline()
        if robot_deadline is not None:
            deadlines.append(robot_deadline)
        if self._delayed:
            deadlines.append(self._delayed[0][0])
        return min(max(0.0, min(deadlines) - now), period)

    def _tick(self, now: float) -> None:
        while self._delayed and self._delayed[0][0] <= now:
            _, _, action = heapq.heappop(self._delayed)
            action(now)
        self.robot.advance(now)
        self._send_outbox(now)
        if self.robot.report_due(now) or now >= self._next_state:
            self.robot.reported(now)
            self._next_state = now + self.robot.state_period_s
            report = self.robot.report()
            for port in (self._tcp, self._pty):
                if port is not None:
                    self._send(port, report, now)
        self._persist_tick(now)

    def _send_outbox(self, now: float) -> None:
        """Captures the robot took: to the host, before the report that shows them done."""
        if not self.robot.outbox:
            return
        for msg in self.robot.take_outbox():
            for port in (self._tcp, self._pty):
                if port is not None:
                    self._send(port, msg, now)

    def _capture_state(self) -> None:
        if self._state_file is not None:
            self._state_file.capture(self.robot)

    def _persist_tick(self, now: float) -> None:
        """End the loop when orphaned (the state file's own thread writes the state)."""
        if self._orphan is not None and not self.orphaned:
            robot = self.robot
            if self._orphan.expired(
                now,
                connected=self._tcp is not None,
                active=robot.busy or robot.paused,
                last_rx=robot.last_host_rx,
            ):
                log.info(
                    "emulator %s: no controller for %.0f s, exiting",
                    self.profile.name,
                    self._orphan.seconds,
                )
                self.orphaned = True
                self._stop = True
                if self._on_orphaned is not None:
                    self._on_orphaned()

    def _on_accept(self, now: float) -> None:
        assert self._listener is not None
        try:
            sock, peer = self._listener.accept()
        except (BlockingIOError, OSError):
            return
        # A newcomer never takes the line: it is a candidate that may only
        # handshake (see the module docstring).
        port = _TcpPort(sock, f"{peer[0]}:{peer[1]}")
        self._candidates.append(port)
        self._sel.register(port, selectors.EVENT_READ, port)
        self.stats["connections"] += 1
        while len(self._candidates) > MAX_CANDIDATES:
            self.stats["connections_refused"] += 1
            self._close_candidate(self._candidates[0])

    def _close_tcp(self, now: float) -> None:
        port, self._tcp = self._tcp, None
        if port is None:
            return
        if self._controller is port:
            self._controller = None
        port.session = None
        with contextlib.suppress(KeyError, ValueError):
            self._sel.unregister(port)
        port.close()
        # A TCP robot knows its link is gone: stop now, do not wait for the watchdog.
        self.robot.link_lost(now)

    def _close_candidate(self, port: _TcpPort) -> None:
        if port in self._candidates:
            self._candidates.remove(port)
        with contextlib.suppress(KeyError, ValueError):
            self._sel.unregister(port)
        port.close()

    def _close_port(self, port: _Port, now: float) -> None:
        if port is self._tcp:
            self._close_tcp(now)
        elif isinstance(port, _TcpPort):
            self._close_candidate(port)

    def _expire_candidates(self, now: float) -> None:
        """Close connections that did not authenticate in time: nobody squats on the line."""
        for port in list(self._candidates):
            if now - port.opened_at > AUTH_TIMEOUT_S:
                log.info("emulator %s: %s did not authenticate", self.profile.name, port.peer)
                self.stats["connections_refused"] += 1
                self._close_candidate(port)

    def _line_held_by_other(self, port: _Port, now: float) -> bool:
        """Another port is the controller and is alive (authentic frame within LINE_TIMEOUT_S)."""
        c = self._controller
        return (
            c is not None
            and c is not port
            and not c.closed
            and c.session is not None
            and now - c.last_auth_rx <= LINE_TIMEOUT_S
        )

    @property
    def has_controller(self) -> bool:
        """A port is authenticated as the controller (alive or not)."""
        with self._lock:
            return self._controller is not None and self._controller.session is not None

    def _on_readable(self, port: _Port, now: float) -> None:
        data = port.read()
        if data is None:
            self._close_port(port, now)
            return
        if not data or now < port.silent_until:
            return  # silenced: the bytes vanish on the "cable"
        f = self.faults
        if f.corrupt_rate and f.corrupt_direction in ("rx", "both"):
            data = self._corrupt(data, "rx")
        errors = port.decoder.errors
        frames = port.decoder.feed(data)
        self.stats["frames_corrupt"] += port.decoder.errors - errors
        for frame in frames:
            port.frames_rx += 1
            self.stats["frames_rx"] += 1
            if (
                self._drops_left > 0
                and f.drop_after_frames is not None
                and port.frames_rx >= f.drop_after_frames
            ):
                self._drops_left -= 1
                self._drop(port, now, None)
                return
            if f.delay_s and f.delay_direction in ("rx", "both"):
                self._later(now + f.delay_s, functools.partial(self._handle, port, frame))
            else:
                self._handle(port, frame, now)

    def _handle(self, port: _Port, frame: Frame, now: float) -> None:
        if port.closed:
            return
        if frame.ver != PROTOCOL_MAJOR:
            self.stats["frames_rejected"] += 1
            if frame.type == MsgType.HELLO:
                self._send(port, self.robot.hello_ack(HelloStatus.VERSION_UNSUPPORTED), now)
            return
        if frame.type == MsgType.HELLO:
            self._on_hello(port, frame, now)
            return
        if frame.type == MsgType.AUTH:
            self._on_auth(port, frame, now)
            return
        if frame.type == MsgType.ESTOP:
            # Fail-safe: no MAC needed, but only from the controller or while
            # nobody holds the line (a candidate cannot disturb the controller).
            if self._line_held_by_other(port, now):
                self.stats["frames_unauthenticated"] += 1
                return
            inner = frame.payload
        elif port.session is None:
            self.stats["frames_unauthenticated"] += 1
            return
        else:
            try:
                inner = port.session.open(frame)
            except AuthError as exc:
                self.stats["frames_unauthenticated"] += 1
                if isinstance(exc, ReplayError):
                    self.stats["frames_replayed"] += 1
                return
            port.last_auth_rx = now
        self._deliver(port, Frame(frame.type, frame.seq, inner, frame.ver), now)

    def _deliver(self, port: _Port, frame: Frame, now: float) -> None:
        """Hand an authenticated (or fail-safe) frame to the robot and send its replies."""
        try:
            msg = decode_message(frame)
            replies = self.robot.receive(msg, frame.seq, now)
        except MessageError:
            self.stats["frames_rejected"] += 1
            replies = self.robot.receive_invalid(frame.type, frame.seq, now)
        for reply in replies:
            self._send(port, reply, now)
        self._send_outbox(now)
        if self.robot.report_due(now):
            # Report at once after an E-stop, a halt or an operator command; progress
            # waits for its slot (SimRobot.min_report_gap_s; _tick sends it then).
            self.robot.reported(now)
            self._next_state = now + self.robot.state_period_s
            self._send(port, self.robot.report(), now)

    def _on_hello(self, port: _Port, frame: Frame, now: float) -> None:
        try:
            hello = decode_message(frame)
        except MessageError:
            self.stats["frames_rejected"] += 1
            return
        assert isinstance(hello, Hello)
        if port.hello == hello and port.challenge is not None:
            # The host repeats its HELLO until answered: the same answer again,
            # so an AUTH computed from either one verifies.
            self._send(port, port.challenge, now)
            return
        if self._line_held_by_other(port, now) and not hello.flags & HelloFlag.TAKEOVER:
            self._refuse(port, now)
            return
        challenge = robot_challenge(self.secret, hello)
        port.hello, port.challenge = hello, challenge
        port.pending = robot_session(self.secret, hello, challenge)
        self._send(port, challenge, now)

    def _refuse(self, port: _Port, now: float) -> None:
        """Another controller holds the line: say so once and hang up (a TCP candidate)."""
        log.info("emulator %s: refused a second controller", self.profile.name)
        self.stats["connections_refused"] += 1
        self._send(port, Challenge(status=HelloStatus.LINE_BUSY), now)
        if isinstance(port, _TcpPort) and port is not self._tcp:
            self._close_candidate(port)

    def _on_auth(self, port: _Port, frame: Frame, now: float) -> None:
        session = port.pending
        if session is None or port.hello is None:
            self.stats["frames_unauthenticated"] += 1
            return
        try:
            inner = session.open(frame)
        except AuthError as exc:
            self.stats["frames_unauthenticated"] += 1
            if not isinstance(exc, ReplayError):
                # A wrong key: this is not our server; a TCP candidate goes at once.
                self.stats["auth_failures"] += 1
                if isinstance(port, _TcpPort) and port is not self._tcp:
                    self._close_candidate(port)
            return
        if inner:
            self.stats["frames_rejected"] += 1
            return
        if port.session is session:
            # A repeated AUTH (our HELLO_ACK was lost): answer again, restart nothing.
            port.last_auth_rx = now
            self._send(port, self.robot.hello_ack(), now)
            self._send(port, self.robot.report(), now)
            return
        if self._line_held_by_other(port, now):
            if not port.hello.flags & HelloFlag.TAKEOVER:
                self._refuse(port, now)
                return
            log.info("emulator %s: controller taken over", self.profile.name)
            self.stats["takeovers"] += 1
        self._make_controller(port, session, now)
        self.stats["sessions"] += 1
        # The robot sees an ordinary new session: motion stops, LINK_RESET if busy.
        self._deliver(port, Frame(MsgType.HELLO, frame.seq, port.hello.payload()), now)

    def _make_controller(self, port: _Port, session: SessionMac, now: float) -> None:
        old = self._controller
        if old is not None and old is not port:
            old.session = None
            if old is self._tcp:
                self._close_tcp(now)  # stops the robot at once (LINK_RESET if busy)
            self._controller = None
        if isinstance(port, _TcpPort) and port is not self._tcp:
            if self._tcp is not None:
                self._close_tcp(now)
            if port in self._candidates:
                self._candidates.remove(port)
            self._tcp = port
        port.session = session
        port.last_auth_rx = now
        self._controller = port

    def _send(self, port: _Port, msg: Message, now: float) -> None:
        if port.closed or now < port.silent_until:
            return
        # Handshake answers are always plain (the host has no key for them yet,
        # even when this port still has the session of an earlier handshake).
        session = None if _handshake_answer(msg) else port.session
        if session is None and not _plain_ok(msg):
            return  # nothing but handshake answers goes to a port without a session
        self._tx_seq = (self._tx_seq + 1) & 0xFFFF
        if session is not None:
            try:
                wire = session.seal_message(msg, self._tx_seq)
            except AuthError:  # counter exhausted: the host must handshake again
                port.session = None
                return
        else:
            wire = encode_message(msg, self._tx_seq)
        f = self.faults
        if f.corrupt_rate and f.corrupt_direction in ("tx", "both"):
            wire = self._corrupt(wire, "tx")
        self.stats["frames_tx"] += 1
        if f.delay_s and f.delay_direction in ("tx", "both"):
            self._later(now + f.delay_s, functools.partial(self._write, port, wire))
        else:
            self._write(port, wire, now)

    def _write(self, port: _Port, wire: bytes, now: float) -> None:
        if port.closed or now < port.silent_until:
            return
        if not port.write(wire):
            self._close_port(port, now)

    def _later(self, when: float, action: Callable[[float], None]) -> None:
        heapq.heappush(self._delayed, (when, next(self._counter), action))

    def _corrupt(self, data: bytes, direction: str) -> bytes:
        rate = self.faults.corrupt_rate
        rng = self._rng[direction]
        out = bytearray(data)
        for i in range(len(out)):
            if rng.random() < rate:
                out[i] = rng.randrange(256)
                self.stats["bytes_corrupted"] += 1
        return bytes(out)

    def _drop(self, port: _Port, now: float, silence_s: float | None) -> None:
        self.stats["drops"] += 1
        mode = self.faults.drop_mode
        if port is self._tcp and silence_s is None and mode in ("auto", "close"):
            log.info("emulator %s: dropping TCP connection", self.profile.name)
            self._close_tcp(now)
            return
        length = self.faults.drop_for_s if silence_s is None else silence_s
        log.info("emulator %s: link silent for %.2f s", self.profile.name, length)
        port.silent_until = now + length
        port.decoder.reset()
        port.frames_rx = 0  # what follows the silence counts as a new connection

    def _drop_all(self, now: float, silence_s: float | None) -> None:
        for port in (self._tcp, self._pty):
            if port is not None:
                self._drop(port, now, silence_s)

    def _write_record(self, rec: ExecutionRecord) -> None:
        # One JSON object a line: "command" records (ExecutionRecord) and "stop"
        # records (StopEvent; ``t`` is this process's time.monotonic(), which on
        # Linux is system-wide, so other processes can time a stop against it).
        if self._log_file is not None:
            self._log_file.write(json.dumps({"record": "command", **asdict(rec)}))

    def _write_stop(self, stop: StopEvent) -> None:
        if stop.reason == "watchdog":
            log.warning(
                "emulator %s: watchdog stop; last host frame %.3f s before it, loop %.3f s late",
                self.profile.name,
                stop.t - self.robot.last_host_rx,
                self.loop_late_s,
            )
        if self._log_file is not None:
            self._log_file.write(json.dumps({"record": "stop", **asdict(stop)}))


def _handshake_answer(msg: Message) -> bool:
    """CHALLENGE, or a HELLO_ACK refusing the version: sent before any session key."""
    return isinstance(msg, Challenge) or (
        isinstance(msg, HelloAck) and msg.status != HelloStatus.OK
    )


def _plain_ok(msg: Message) -> bool:
    """Robot → host messages that may go without a MAC: handshake answers, ESTOP's ACK."""
    return _handshake_answer(msg) or (isinstance(msg, Ack) and msg.ref_type == MsgType.ESTOP)
