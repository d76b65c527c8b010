"""Camera field of view on the deck and the weld lines inside it.

The inspection camera (seed §2: it "takes photos of the lane") is a pinhole
on the mast, tilted toward the wall.  Without roll its image rectangle maps
onto the deck as an isosceles trapezoid in the robot frame: a near edge at
``x_near`` (half width ``w_near``) and a far edge at ``x_far``
(``w_far``).  A lane's two weld lines are inside the view when both lie
between the trapezoid's side edges over its whole length; the *margin* is
the smallest lateral distance from a weld to a side edge (negative: a weld
leaves the picture).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from planners.errors import InvalidInputError
from planners.sbg.robot import CameraParams


@dataclass(frozen=True)
class Footprint:
    """Trapezoid seen on the wall, robot frame (m)."""

    x_near: float
    w_near: float
    x_far: float
    w_far: float

    def half_width(self, x: np.ndarray | float) -> np.ndarray:
        """Half width at robot-frame x (linear between the edges)."""
        f = (np.asarray(x, dtype=float) - self.x_near) / (self.x_far - self.x_near)
        return self.w_near + f * (self.w_far - self.w_near)

    def corners(self) -> np.ndarray:
        """(4,2) near-left, near-right, far-right, far-left."""
        return np.array(
            [
                [self.x_near, self.w_near],
                [self.x_near, -self.w_near],
                [self.x_far, -self.w_far],
                [self.x_far, self.w_far],
            ]
        )


def footprint(cam: CameraParams) -> Footprint:
    """Intersect the four corner rays with the wall plane z = 0.

    Camera frame: x optical axis, y left, z up; it is turned by ``tilt``
    about the body y axis, so a ray ``(1, u·tan(hfov/2), v·tan(vfov/2))``
    becomes ``(cos t + v' sin t, u', −sin t + v' cos t)`` in the body frame.
    """
    t, th, tv = cam.tilt_rad, math.tan(cam.hfov_rad / 2), math.tan(cam.vfov_rad / 2)
    edges = []
    for v in (-1.0, 1.0):  # near edge (toward the wall), far edge
        rz = -math.sin(t) + v * tv * math.cos(t)
        if rz >= -1e-9:
            raise InvalidInputError(
                "camera sees above the horizon (tilt_deg − vfov_deg/2 ≤ 0): its view of the deck is unbounded"
            )
        s = cam.height_m / -rz
        x = cam.x_m + s * (math.cos(t) + v * tv * math.sin(t))
        edges.append((x, s * th))
    (xn, wn), (xf, wf) = edges
    return Footprint(xn, wn, xf, wf)


def weld_margin(
    d: np.ndarray | float,
    delta: np.ndarray | float,
    weld_left: float,
    weld_right: float,
    fp: Footprint,
    x_limit: np.ndarray | float | None = None,
) -> np.ndarray:
    """Margin (m) of both weld lines inside the footprint, vectorised.

    ``weld_left``/``weld_right`` are the welds' lateral offsets from the
    centreline (left positive, so typically ``+w/2`` and ``−w/2``); ``(d, δ)``
    follow Table 1.  A weld at lateral ``y_w`` crosses robot-frame ``x`` at
    ``y_r(x) = (y_w + d − x sin δ)/cos δ``.  ``x_limit`` (robot-frame x where
    the deck ends, e.g. at the crossbeam ahead) clips the far edge; where it
    is nearer than the near edge the result is NaN (the camera sees no deck).
    """
    d = np.asarray(d, dtype=float)
    delta = np.asarray(delta, dtype=float)
    x_far = np.full(np.broadcast(d, delta).shape, fp.x_far)
    if x_limit is not None:
        x_far = np.minimum(x_far, np.asarray(x_limit, dtype=float))
    s, c = np.sin(delta), np.cos(delta)
    out = np.full(x_far.shape, np.inf)
    for x in (np.full_like(x_far, fp.x_near), x_far):
        hw = fp.half_width(x)
        yl = (weld_left + d - x * s) / c
        yr = (weld_right + d - x * s) / c
        out = np.minimum(out, np.minimum(hw - np.abs(yl), hw - np.abs(yr)))
    return np.where(x_far >= fp.x_near, out, np.nan)


def max_yaw_for_margin(fp: Footprint, weld_half_m: float, safety_m: float) -> float:
    """Largest yaw ψ (rad) that keeps both welds ``safety_m`` inside the view
    of a robot on the centreline (d = 0) — where a preview-follow arc ends
    with its largest yaw.  Bisection on the monotone ``weld_margin(0, ψ)``."""
    if float(weld_margin(0.0, 0.0, weld_half_m, -weld_half_m, fp)) < safety_m:
        return 0.0
    lo, hi = 0.0, math.pi / 2 - 1e-6
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if float(weld_margin(0.0, mid, weld_half_m, -weld_half_m, fp)) >= safety_m:
            lo = mid
        else:
            hi = mid
    return lo
