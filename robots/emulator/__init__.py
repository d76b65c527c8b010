"""Robot emulator speaking the SteelPath protocol over TCP and a pty (DESIGN §7).

- :class:`Emulator` — transport + :class:`SimRobot`, with link fault injection.
- :class:`SimRobot` — protocol state machine and simulation, no I/O.
- :class:`FaultConfig` — what to inject; :func:`resolve_profile` — the robot's hardware.
- :func:`check_exactly_once` — assert nothing lost or duplicated from the execution log
  (an interrupted command must be *continued*, never repeated: docs/protocol.md §8.2).
- :class:`StateFile`, :func:`read_port_file` — state and endpoint that outlive the
  emulator process (``--state-file``, ``--port-file``; :mod:`robots.emulator.persist`).
- :class:`FeetSpec` — the feet rules of a two-footed robot (:mod:`robots.emulator.feet`);
  :class:`CameraSpec`, :class:`World` — its camera and what it sees
  (``--world``; :mod:`robots.emulator.camera`).
- :func:`main` — ``steelpath emulate`` entry point.
"""

from robots.emulator.camera import CameraSpec, World, WorldError
from robots.emulator.cli import main
from robots.emulator.faults import FaultConfig
from robots.emulator.feet import FeetSpec
from robots.emulator.persist import PortInfo, StateFile, StateFileError, read_port_file
from robots.emulator.profiles import FALLBACK_PROFILES, RobotProfile, resolve_profile
from robots.emulator.robot import (
    CaptureInfo,
    ExecutionRecord,
    Interrupted,
    SimRobot,
    StopEvent,
    check_exactly_once,
)
from robots.emulator.server import Emulator

__all__ = [
    "FALLBACK_PROFILES",
    "CameraSpec",
    "CaptureInfo",
    "Emulator",
    "ExecutionRecord",
    "FaultConfig",
    "FeetSpec",
    "Interrupted",
    "PortInfo",
    "RobotProfile",
    "SimRobot",
    "StateFile",
    "StateFileError",
    "StopEvent",
    "World",
    "WorldError",
    "check_exactly_once",
    "main",
    "read_port_file",
    "resolve_profile",
]
