"""A sensor frame the robot brings back: what its camera saw at one place.

A ``capture`` command in a program asks the robot for one; the robot sends it
to the host as a header message and point chunks (docs/protocol.md), and the
host's link reassembles them into a :class:`SensorCapture`.

Coordinates: the camera pose is given in the program's ``world`` frame, a
local frame whose origin the plan records (``world_origin_m``, float64, e.g.
a UTM position), so that the numbers stay small enough for float32 and for
the wire's integer micrometres.  Points are in the camera's optical frame
(z along the view, x right, y down), metres.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["SensorCapture"]


@dataclass(frozen=True)
class SensorCapture:
    """One sensor frame, reassembled on the host.

    - ``capture_id``: the robot's number of this capture (unique per run);
    - ``run_id`` / ``command_index``: the program run and the ``capture``
      command that asked for it;
    - ``t_s``: robot clock at the capture, seconds;
    - ``camera_position_m`` (3,) float64 and ``camera_rotation`` (3, 3)
      float64: the camera → world transform (columns: the camera's axes in
      the world frame);
    - ``points_m`` (N, 3) float32 in the camera frame;
    - ``intensity`` (N,) uint8 or ``None``;
    - ``complete``: every point the header announced arrived.
    """

    capture_id: int
    run_id: int
    command_index: int
    t_s: float
    camera_position_m: np.ndarray
    camera_rotation: np.ndarray
    points_m: np.ndarray
    intensity: np.ndarray | None = None
    complete: bool = True
    meta: dict[str, float] = field(default_factory=dict)

    def world_points(self) -> np.ndarray:
        """The points in the world frame, float64 (N, 3)."""
        pts = np.asarray(self.points_m, dtype=np.float64)
        return pts @ np.asarray(self.camera_rotation, dtype=np.float64).T + np.asarray(
            self.camera_position_m, dtype=np.float64
        )
