"""The robot-link service: robot links in a process of their own (DESIGN §10)."""

from server.linkservice.client import LinkServiceClient, LinkServiceUnavailable
from server.linkservice.emulators import EmulatorProcess, EmulatorSupervisor
from server.linkservice.service import robot_key_path

__all__ = [
    "EmulatorProcess",
    "EmulatorSupervisor",
    "LinkServiceClient",
    "LinkServiceUnavailable",
    "robot_key_path",
]
