"""Robot emulator: a :class:`~robots.emulator.robot.SimRobot` behind TCP and/or a pty.

One daemon thread runs a ``selectors`` loop over the listening socket, the
current TCP connection, the pty master and a wake-up socket; it sleeps until
the next byte or the next timer (state report, end of a motion segment,
watchdog deadline, a delayed frame) — no polling.  Link fault injection
(drop, corrupt, delay) happens here; robot faults (NAK, fault mid-motion)
in the robot.

Usage in tests::

    with Emulator("denso_vm6083", time_scale=20) as emu:
        link = RobotLink(emu.url)                # socket://127.0.0.1:<port>
        ...
        assert not check_exactly_once(emu.execution_log(), run_id, len(program))
"""

from __future__ import annotations

import contextlib
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
from typing import IO
from urllib.parse import urlsplit

import numpy as np

from robots.emulator.faults import FaultConfig
from robots.emulator.persist import OrphanTimer, StateFile, remove_port_file, write_port_file
from robots.emulator.profiles import RobotProfile, resolve_profile
from robots.emulator.robot import ExecutionRecord, SimRobot, StopEvent
from robots.protocol.framing import PROTOCOL_MAJOR, Frame, FrameDecoder
from robots.protocol.messages import (
    HelloStatus,
    Message,
    MessageError,
    MsgType,
    State,
    decode_message,
    encode_message,
)

log = logging.getLogger(__name__)


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
        state_file: str | os.PathLike[str] | None = None,
        port_file: str | os.PathLike[str] | None = None,
        exit_when_orphaned_s: float | None = None,
        on_orphaned: Callable[[], None] | None = None,
    ) -> None:
        if exit_when_orphaned_s is not None and not exit_when_orphaned_s > 0:
            raise ValueError(f"exit_when_orphaned_s={exit_when_orphaned_s}: must be > 0")
        if listen is None and not pty:
            raise ValueError("the emulator needs a TCP listen address, a pty, or both")
        if time_scale <= 0:
            raise ValueError(f"time_scale={time_scale}: must be > 0")
        self.profile = profile or resolve_profile(robot, joint_limits)
        self.faults = faults or FaultConfig()
        self._listen = listen
        self._want_pty = pty
        self._log_file: IO[str] | None = (
            open(log_path, "a", encoding="utf-8") if log_path is not None else None  # noqa: SIM115
        )
        self.robot = SimRobot(
            self.profile,
            buffer_capacity=buffer_capacity,
            time_scale=time_scale,
            state_period_s=state_period_s,
            faults_injected=self.faults,
            on_record=self._write_record if self._log_file else None,
        )
        self._state_file = StateFile(state_file) if state_file is not None else None
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
        self._rng = random.Random(self.faults.seed)
        self._lock = threading.RLock()
        self._cond = threading.Condition(self._lock)
        self._sel = selectors.DefaultSelector()
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._listener: socket.socket | None = None
        self._tcp: _TcpPort | None = None
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
                try:
                    self._state_file.save(self.robot)
                except OSError:
                    log.exception("emulator %s: cannot save its state", self.profile.name)
        if self._port_file is not None:
            remove_port_file(self._port_file)
        for port in (self._tcp, self._pty):
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
                    for key, _ in events:
                        handler = key.data
                        if isinstance(handler, _Port):
                            self._on_readable(handler, now)
                        else:
                            handler(now)
                    actions, self._actions = self._actions, []
                    for action in actions:
                        action(now)
                    self._tick(now)
                    self._cond.notify_all()
        except Exception:  # pragma: no cover - keep the reason visible
            log.exception("emulator %s crashed", self.profile.name)

    def _timeout(self, now: float) -> float:
        period = self.robot.state_period_s
        deadlines = [self._next_state]
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
        if self.robot.changed or now >= self._next_state:
            self.robot.changed = False
            self._next_state = now + self.robot.state_period_s
            report = self.robot.report()
            for port in (self._tcp, self._pty):
                if port is not None:
                    self._send(port, report, now)
        self._persist_tick(now)

    def _capture_state(self) -> None:
        if self._state_file is not None:
            self._state_file.capture(self.robot)

    def _persist_tick(self, now: float) -> None:
        """Write the state captured at the last rest; end the loop when orphaned."""
        if self._state_file is not None:
            try:
                self._state_file.flush()
            except OSError:
                log.exception("emulator %s: cannot save its state", self.profile.name)
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
        if self._tcp is not None:
            # One host at a time, like a serial line: the newcomer wins.
            self._close_tcp(now)
        self._tcp = _TcpPort(sock, f"{peer[0]}:{peer[1]}")
        self._sel.register(self._tcp, selectors.EVENT_READ, self._tcp)
        self.stats["connections"] += 1

    def _close_tcp(self, now: float) -> None:
        port, self._tcp = self._tcp, None
        if port is None:
            return
        with contextlib.suppress(KeyError, ValueError):
            self._sel.unregister(port)
        port.close()
        # A TCP robot knows its link is gone: stop now, do not wait for the watchdog.
        self.robot.link_lost(now)

    def _on_readable(self, port: _Port, now: float) -> None:
        data = port.read()
        if data is None:
            if port is self._tcp:
                self._close_tcp(now)
            return
        if not data or now < port.silent_until:
            return  # silenced: the bytes vanish on the "cable"
        f = self.faults
        if f.corrupt_rate and f.corrupt_direction in ("rx", "both"):
            data = self._corrupt(data)
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
                self._later(now + f.delay_s, lambda t, p=port, fr=frame: self._handle(p, fr, t))
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
        try:
            msg = decode_message(frame)
            replies = self.robot.receive(msg, frame.seq, now)
        except MessageError:
            self.stats["frames_rejected"] += 1
            replies = self.robot.receive_invalid(frame.type, frame.seq, now)
        for reply in replies:
            self._send(port, reply, now)
        if self.robot.changed:
            # Report immediately after anything that changed (E-stop, completion…).
            self.robot.changed = False
            self._next_state = now + self.robot.state_period_s
            self._send(port, self.robot.report(), now)

    def _send(self, port: _Port, msg: Message, now: float) -> None:
        if port.closed or now < port.silent_until:
            return
        self._tx_seq = (self._tx_seq + 1) & 0xFFFF
        wire = encode_message(msg, self._tx_seq)
        f = self.faults
        if f.corrupt_rate and f.corrupt_direction in ("tx", "both"):
            wire = self._corrupt(wire)
        self.stats["frames_tx"] += 1
        if f.delay_s and f.delay_direction in ("tx", "both"):
            self._later(now + f.delay_s, lambda t, p=port, w=wire: self._write(p, w, t))
        else:
            self._write(port, wire, now)

    def _write(self, port: _Port, wire: bytes, now: float) -> None:
        if port.closed or now < port.silent_until:
            return
        if not port.write(wire) and port is self._tcp:
            self._close_tcp(now)

    def _later(self, when: float, action: Callable[[float], None]) -> None:
        heapq.heappush(self._delayed, (when, next(self._counter), action))

    def _corrupt(self, data: bytes) -> bytes:
        rate = self.faults.corrupt_rate
        out = bytearray(data)
        for i in range(len(out)):
            if self._rng.random() < rate:
                out[i] = self._rng.randrange(256)
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
        if self._log_file is not None:
            self._log_file.write(json.dumps(asdict(rec)) + "\n")
            self._log_file.flush()
