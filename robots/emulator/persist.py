"""State that outlives the emulator process: a state file, a port file, an orphan timer.

A real robot keeps its pose, odometry and progress whatever happens to the
server that commands it; an emulator started by that server must too, or a
server crash would "teleport" the robot home and a resume could not be checked
honestly.  Three pieces, used by :class:`robots.emulator.server.Emulator`:

- :class:`StateFile` (``--state-file``): the robot's kept state as JSON —
  pose, odometry, joints, lifting arm, magnets (and, for the record, which
  feet are in the air — derived from magnets and joints on load), plates,
  nozzle, latched faults, the base anchor and planar pose, the capture
  counter, ``run_id``/``last_done`` and the interrupted-command memory
  (:class:`~robots.emulator.robot.Interrupted`).  A snapshot is *captured*
  (in memory, cheap) at each moment the robot comes to rest or changes its
  kept state at rest — halt, completion of a command, pause, clear — and the
  latest one is *written* by a writer thread of its own (an ``fsync`` can
  take long on a busy disk; it must never hold up the emulator's loop, which
  also serves the E-stop) and synchronously on clean exit, atomically (temporary file in the same directory, ``fsync``,
  ``rename``, ``fsync`` of the directory), so a reader sees either the old or
  the new file, never a torn one.  States at rest are exact, so an emulator
  started from the file continues precisely.  Like a real robot whose
  non-volatile memory is written only at rest, a power cut (``kill -9``)
  mid-motion loses the motion since the last rest: the restarted robot stands
  where it last stopped.
- :func:`write_port_file` (``--port-file``): ``{"pid", "url", "robot"}``
  written atomically after binding, so a restarted server finds a running
  emulator and reuses it (:func:`read_port_file` checks the process is alive).
- :class:`OrphanTimer` (``--exit-when-orphaned SECONDS``): true once no
  controller has been connected and nothing has executed for that long, so
  emulators left behind by a killed server do not live forever.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import tempfile
import threading
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from robots.emulator.robot import Interrupted, SimRobot
from robots.protocol.messages import MESSAGE_CLASSES, CommandMessage, MessageError

log = logging.getLogger(__name__)

STATE_FORMAT = "steelpath-emulator-state"
STATE_VERSION = 1


class StateFileError(ValueError):
    """A state or port file that cannot be used (corrupt, another robot, wrong shape)."""


# --- atomic JSON ------------------------------------------------------------------------


def write_json_atomic(path: str | os.PathLike[str], data: Mapping[str, Any]) -> None:
    """Write ``data`` as JSON to ``path`` atomically: tmp + fsync + rename + fsync(dir)."""
    target = Path(path)
    directory = target.parent if str(target.parent) else Path(".")
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=directory)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            # json.dumps without indent runs in C; json.dump to a file (or any
            # indent) runs the pure-Python encoder, which was a quarter of a
            # streaming emulator's time (it writes this at every rest).
            fh.write(json.dumps(data, sort_keys=True))
            fh.write("\n")
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    # The rename itself is durable only once the directory entry is on disk.
    dir_fd = os.open(directory, os.O_RDONLY)
    try:
        os.fsync(dir_fd)
    finally:
        os.close(dir_fd)


def _read_json(path: Path, what: str) -> dict[str, Any] | None:
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        return None
    except OSError as exc:
        raise StateFileError(f"{what} {path}: cannot read: {exc}") from exc
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise StateFileError(f"{what} {path}: not JSON ({exc})") from exc
    if not isinstance(data, dict):
        raise StateFileError(f"{what} {path}: expected a JSON object")
    return data


# --- robot state ------------------------------------------------------------------------


def _encode_command(msg: CommandMessage) -> dict[str, Any]:
    # The wire payload is the command's exact identity (run, index, every field).
    return {"type": int(msg.TYPE), "payload": msg.payload().hex()}


def _decode_command(data: Mapping[str, Any]) -> CommandMessage:
    cls = MESSAGE_CLASSES.get(int(data["type"]))
    if cls is None or not issubclass(cls, CommandMessage):
        raise StateFileError(f"interrupted command of unknown type {data['type']!r}")
    try:
        msg = cls.from_payload(bytes.fromhex(str(data["payload"])))
    except (MessageError, ValueError) as exc:
        raise StateFileError(f"interrupted command does not parse: {exc}") from exc
    assert isinstance(msg, CommandMessage)
    return msg


def robot_state(robot: SimRobot) -> dict[str, Any]:
    """The state a robot keeps across a restart, as JSON-ready data.

    An executing command is saved as interrupted at its current progress (what
    the robot would remember had it stopped now); queued commands are not kept
    (every restart drops the queue; the host sends them again).
    """
    mem = robot.resume_point()
    return {
        "format": STATE_FORMAT,
        "version": STATE_VERSION,
        "robot": robot.profile.name,
        "q_rad": [float(v) for v in robot.q],
        "lift_rad": float(robot.lift),
        "odometry_m": [float(v) for v in robot.odometry],
        "magnets": int(robot.magnets),
        "feet_in_air": int(robot.feet_in_air()),
        "base_anchor": [[float(v) for v in row] for row in robot.base_anchor],
        "base_planar": [float(v) for v in robot.base_planar],
        "captures": int(robot.captures),
        "plates": int(robot.plates),
        "nozzle": bool(robot.nozzle),
        "faults": int(robot.faults),
        "fault_code": int(robot.fault_code),
        "run_id": int(robot.run_id),
        "last_done": int(robot.last_done),
        "sim_t": float(robot.sim_t),
        "interrupted": None
        if mem is None
        else {
            "command": _encode_command(mem.msg),
            "progress": float(mem.progress),
            "done_s": float(mem.done_s),
            "q_start_rad": [float(v) for v in mem.q_start],
            "lift_start_rad": float(mem.lift_start),
        },
    }


def restore_robot_state(robot: SimRobot, state: Mapping[str, Any], source: str = "state") -> None:
    """Apply a :func:`robot_state` snapshot to an idle ``robot``; raises
    :class:`StateFileError` (naming ``source``) if it is not this robot's."""
    p = robot.profile
    if state.get("format") != STATE_FORMAT:
        raise StateFileError(f"{source}: not an emulator state file")
    if state.get("version") != STATE_VERSION:
        raise StateFileError(f"{source}: state version {state.get('version')!r} unsupported")
    if state.get("robot") != p.name:
        raise StateFileError(f"{source}: state of robot {state.get('robot')!r}, not {p.name!r}")
    try:
        q = np.asarray(state["q_rad"], dtype=float)
        odometry = np.asarray(state["odometry_m"], dtype=float)
        if q.shape != (p.n_joints,) or odometry.shape != (p.n_wheels,):
            raise StateFileError(
                f"{source}: {q.size} joints / {odometry.size} wheels, the robot has "
                f"{p.n_joints} / {p.n_wheels}"
            )
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(odometry))):
            raise StateFileError(f"{source}: non-finite pose")
        mem = None
        raw = state.get("interrupted")
        if raw is not None:
            q_start = tuple(float(v) for v in raw["q_start_rad"])
            if len(q_start) != p.n_joints:
                raise StateFileError(
                    f"{source}: interrupted command's start pose has {len(q_start)} joints"
                )
            mem = Interrupted(
                msg=_decode_command(raw["command"]),
                progress=float(raw["progress"]),
                done_s=float(raw["done_s"]),
                q_start=q_start,
                lift_start=float(raw["lift_start_rad"]),
            )
        values: dict[str, Any] = {
            "lift": float(state["lift_rad"]),
            "magnets": int(state["magnets"]),
            "plates": int(state["plates"]),
            "nozzle": bool(state["nozzle"]),
            "faults": int(state["faults"]),
            "fault_code": int(state["fault_code"]),
            "run_id": int(state["run_id"]),
            "last_done": int(state["last_done"]),
            "sim_t": float(state.get("sim_t", 0.0)),
            "captures": int(state.get("captures", 0)),
        }
        # Optional (files written before the base pose was kept: at the origin).
        anchor = np.asarray(state.get("base_anchor", np.eye(4)), dtype=float)
        planar = np.asarray(state.get("base_planar", np.zeros(3)), dtype=float)
        if anchor.shape != (4, 4) or planar.shape != (3,):
            raise StateFileError(f"{source}: base pose of the wrong shape")
        if not (np.all(np.isfinite(anchor)) and np.all(np.isfinite(planar))):
            raise StateFileError(f"{source}: non-finite base pose")
    except (KeyError, TypeError, ValueError) as exc:
        if isinstance(exc, StateFileError):
            raise
        raise StateFileError(f"{source}: missing or bad field ({exc!r})") from exc
    if robot.busy:
        raise StateFileError(f"{source}: cannot restore into a robot that is executing")
    robot.q = q
    robot.odometry = odometry
    robot.wheel_speeds[:] = 0.0
    robot.lift = values["lift"]
    robot.magnets = values["magnets"]
    robot.plates = values["plates"]
    robot.nozzle = values["nozzle"]
    robot.faults = values["faults"]
    robot.fault_code = values["fault_code"]
    robot.run_id = values["run_id"]
    robot.last_done = robot.last_queued = values["last_done"]
    robot.sim_t = values["sim_t"]
    robot.captures = values["captures"]
    robot.base_anchor = anchor
    robot.base_planar = planar
    robot.interrupted = mem
    robot.changed = True


class StateFile:
    """The robot's state file: load at start, capture at rest, write atomically.

    :meth:`capture` only stores a snapshot; it is written by :meth:`flush`, which
    the writer thread (:meth:`start` … :meth:`close`) calls whenever a new
    snapshot is waiting.  Only the latest snapshot is written — an older one
    is superseded — and writes never interleave, so the file always ends up
    holding the last state captured.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self._captured: dict[str, Any] | None = None
        self._cond = threading.Condition()
        self._write_lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._closing = False
        self.writes = 0

    def load_into(self, robot: SimRobot) -> bool:
        """Restore ``robot`` from the file; False when there is no file yet."""
        data = _read_json(self.path, "state file")
        if data is None:
            return False
        restore_robot_state(robot, data, source=f"state file {self.path}")
        return True

    def capture(self, robot: SimRobot) -> None:
        """Remember the robot's state now (called at rest; written by :meth:`flush`)."""
        data = robot_state(robot)
        with self._cond:
            self._captured = data
            self._cond.notify()

    def flush(self) -> bool:
        """Write the latest captured state, if any since the last write."""
        with self._write_lock:
            with self._cond:
                data, self._captured = self._captured, None
            if data is None:
                return False
            write_json_atomic(self.path, data)
            self.writes += 1
            return True

    def save(self, robot: SimRobot) -> None:
        self.capture(robot)
        self.flush()

    def start(self) -> None:
        """Write captured states from a background thread until :meth:`close`."""
        if self._thread is not None:
            return
        self._closing = False
        self._thread = threading.Thread(
            target=self._writer, name=f"state writer {self.path.name}", daemon=True
        )
        self._thread.start()

    def close(self, timeout: float = 5.0) -> None:
        """Stop the writer thread, then write whatever is still waiting."""
        with self._cond:
            self._closing = True
            self._cond.notify()
        if self._thread is not None:
            self._thread.join(timeout)
            self._thread = None
        self.flush()

    def _writer(self) -> None:
        while True:
            with self._cond:
                self._cond.wait_for(lambda: self._captured is not None or self._closing)
                if self._closing:
                    return  # close() writes the rest itself
            try:
                self.flush()
            except OSError:
                log.exception("cannot write the emulator state file %s", self.path)


# --- port file ---------------------------------------------------------------------------


@dataclass(frozen=True)
class PortInfo:
    """A running emulator as announced in its port file."""

    pid: int
    url: str | None  # socket://127.0.0.1:PORT, None without a TCP endpoint
    robot: str
    pty: str | None = None


def write_port_file(
    path: str | os.PathLike[str], *, url: str | None, robot: str, pty: str | None = None
) -> None:
    """Announce this process's endpoint(s) atomically."""
    data: dict[str, Any] = {"pid": os.getpid(), "url": url, "robot": robot}
    if pty is not None:
        data["pty"] = pty
    write_json_atomic(path, data)


def pid_alive(pid: int) -> bool:
    """Whether process ``pid`` runs (a zombie — exited, not yet reaped — does not)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # exists, owned by someone else
    with contextlib.suppress(OSError, IndexError):
        stat = Path(f"/proc/{pid}/stat").read_text()
        if stat.rsplit(")", 1)[1].split()[0] == "Z":
            return False
    return True


def read_port_file(path: str | os.PathLike[str], *, check_alive: bool = True) -> PortInfo | None:
    """The emulator a port file announces; ``None`` if there is no file or (with
    ``check_alive``) its process is gone.  Raises :class:`StateFileError` if corrupt."""
    p = Path(path)
    data = _read_json(p, "port file")
    if data is None:
        return None
    try:
        info = PortInfo(
            pid=int(data["pid"]),
            url=None if data.get("url") is None else str(data["url"]),
            robot=str(data["robot"]),
            pty=None if data.get("pty") is None else str(data["pty"]),
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise StateFileError(f"port file {p}: missing or bad field ({exc!r})") from exc
    if check_alive and not pid_alive(info.pid):
        return None
    return info


def remove_port_file(path: str | os.PathLike[str]) -> None:
    """Remove the port file if it still announces this process (a newer one may own it)."""
    try:
        info = read_port_file(path, check_alive=False)
    except StateFileError:
        return
    if info is not None and info.pid == os.getpid():
        with contextlib.suppress(FileNotFoundError):
            os.unlink(path)


# --- orphan timer -------------------------------------------------------------------------


class OrphanTimer:
    """Expires ``seconds`` after the robot last had a controller or work.

    "Contact" is a TCP connection being open, a valid host frame (any port), or
    the robot being busy or paused; an orphaned emulator saves its state and exits.
    """

    def __init__(self, seconds: float, now: float) -> None:
        if not seconds > 0:
            raise ValueError(f"exit_when_orphaned={seconds}: must be > 0 seconds")
        self.seconds = seconds
        self.last_contact = now

    def expired(self, now: float, *, connected: bool, active: bool, last_rx: float) -> bool:
        if connected or active:
            self.last_contact = now
        self.last_contact = max(self.last_contact, last_rx)
        return now - self.last_contact >= self.seconds


__all__ = [
    "OrphanTimer",
    "PortInfo",
    "StateFile",
    "StateFileError",
    "read_port_file",
    "remove_port_file",
    "restore_robot_state",
    "robot_state",
    "write_json_atomic",
    "write_port_file",
]
