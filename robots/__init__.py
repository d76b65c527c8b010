"""Robot descriptions, kinematics loaders, hardware adapters and the emulator.

``load_robot(name)`` returns a :class:`robots.model.RobotModel` for each robot
SteelPath knows (DESIGN §5).  Each robot lives in its own sub-package
``robots/<name>/`` holding ``<name>.urdf``, ``params.toml`` (seed facts and
chosen values, marked) and a ``load()`` function.

The registry itself is :mod:`robots.registry`; this package only re-exports,
and lazily (PEP 562): importing ``robots.protocol`` or ``robots.adapters``
must not load the URDF and mesh libraries behind :mod:`robots.model`.  The
robot-link service imports those and nothing heavier, so it starts (and
restarts after a crash, with the E-stop path) in a fraction of the time.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from robots.model import DHRobotModel, RobotModel
    from robots.registry import ROBOT_NAMES, available_robots, load_robot

_FROM = {
    "DHRobotModel": "robots.model",
    "RobotModel": "robots.model",
    "ROBOT_NAMES": "robots.registry",
    "available_robots": "robots.registry",
    "load_robot": "robots.registry",
}

__all__ = ["ROBOT_NAMES", "DHRobotModel", "RobotModel", "available_robots", "load_robot"]


def __getattr__(name: str) -> Any:
    if name in _FROM:
        return getattr(importlib.import_module(_FROM[name]), name)
    raise AttributeError(f"module 'robots' has no attribute {name!r}")
