"""Robot descriptions, kinematics loaders, hardware adapters and the emulator.

``load_robot(name)`` returns a :class:`robots.model.RobotModel` for each robot
SteelPath knows (DESIGN §5).  Each robot lives in its own sub-package
``robots/<name>/`` holding ``<name>.urdf``, ``params.toml`` (seed facts and
chosen values, marked) and a ``load()`` function.

The registry itself is :mod:`robots.registry`; this package only re-exports.
"""

from robots.model import DHRobotModel, RobotModel
from robots.registry import ROBOT_NAMES, available_robots, load_robot

__all__ = ["ROBOT_NAMES", "DHRobotModel", "RobotModel", "available_robots", "load_robot"]
