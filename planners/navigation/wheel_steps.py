"""The one wheel-step classifier of a differential drive (seed 000 §4.3: the
ARA drives on two magnetic wheels, so it can turn in place or drive along its
heading, never slide sideways).  Used by the ``wheel_motion`` check of a
navigation plan (:mod:`planners.navigation.navigate_plan`) and by the wheel
compiler (:func:`server.kinds.programs.differential_drive_poses`), so both
judge a step the same way.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class WheelSteps:
    """Consecutive pose pairs (x, y, yaw) split the way a differential drive
    sees them: ``dist`` moved, ``dyaw`` turned (wrapped), ``along`` /
    ``lateral`` the move along / across the start heading; ``turn`` (turn in
    place), ``drive`` (straight along the shared heading) and ``sideways``
    (neither: what the wheels cannot do)."""

    dist: np.ndarray
    dyaw: np.ndarray
    along: np.ndarray
    lateral: np.ndarray
    turn: np.ndarray
    drive: np.ndarray

    @property
    def sideways(self) -> np.ndarray:
        return ~self.turn & ~self.drive


def wheel_steps(
    poses: np.ndarray,
    *,
    position_tol_m: float = 1e-6,
    lateral_tol_m: float = 1e-5,
    yaw_tol_rad: float = 1e-6,
) -> WheelSteps:
    """Classify each step of ``poses`` (K,3) as a turn in place, a straight
    drive, or a sideways move (:class:`WheelSteps`)."""
    q = np.asarray(poses, dtype=float).reshape(-1, 3)
    d = np.diff(q, axis=0)
    dist = np.hypot(d[:, 0], d[:, 1])
    dyaw = (d[:, 2] + np.pi) % (2 * np.pi) - np.pi
    c, s = np.cos(q[:-1, 2]), np.sin(q[:-1, 2])
    along = d[:, 0] * c + d[:, 1] * s
    lateral = np.abs(d[:, 0] * s - d[:, 1] * c)
    turn = dist <= position_tol_m
    drive = ~turn & (np.abs(dyaw) <= yaw_tol_rad) & (lateral <= lateral_tol_m)
    return WheelSteps(dist, dyaw, along, lateral, turn, drive)
