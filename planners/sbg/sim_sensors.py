"""Lane sensing of the climber simulator: lane geometry in the roof frame,
true lane error (d, δ) of Table 1, noisy side ranges l2–l4 (forward model
of Eq. 5 with wall waviness) and their trilateration (Eq. 5).
"""

from __future__ import annotations

import math

from planners.sbg.sim_model import (
    _wrap,
)
from planners.sbg.sim_plant import _Plant


class _Sensors(_Plant):
    """Lane geometry and the side range finders l2–l4 with their
    trilateration (Eq. 5) on top of the plant."""

    # ------------------------------------------------------------------ lanes
    def _lane_geometry(self, seg_i: int) -> dict[str, float]:
        seg = self.path.segments[seg_i]
        lane = seg.lane
        sx = self.path.lane_dirs[lane]
        yc = float(self.g.lane_centre_y(lane))
        # Roof frame: x = X, y = −Y.  Lane heading 0 (+X) or π (−X); its left
        # is the robot's left, +90° in the wall frame.
        phi_lane = 0.0 if sx > 0 else math.pi
        left = (-math.sin(phi_lane), math.cos(phi_lane))
        # Wall ahead: X = length (sx > 0) or X = 0.
        m = (1.0, 0.0) if sx > 0 else (-1.0, 0.0)
        c0 = self.g.length_m if sx > 0 else 0.0
        return {
            "lane": lane,
            "sx": sx,
            "yc": -yc,
            "phi": phi_lane,
            "lx": left[0],
            "ly": left[1],
            "mx": m[0],
            "my": m[1],
            "c0": c0,
        }

    def _lane_error(self, geo: dict[str, float]) -> tuple[float, float]:
        """True (d, δ) of Table 1 on the current lane."""
        # The lane line runs along the wall x axis at y = yc; its left unit
        # vector is (0, ±1), so the offset to the left is (y − yc)·ly.
        w = (self.y - geo["yc"]) * geo["ly"]
        return -w, _wrap(self.phi - geo["phi"])

    def _along(self, geo: dict[str, float]) -> float:
        """Distance of Oc from the lane's starting crossbeam."""
        return self.x if geo["sx"] > 0 else self.g.length_m - self.x

    def _ranges(
        self, d: float, delta: float, along: float, lane: int
    ) -> tuple[float, float, float]:
        """Noisy l2, l3, l4 (the forward model of Eq. 5, see
        :func:`planners.sbg.trilateration.side_ranges`)."""
        nz, g = self.noise, self.gauss
        w0 = float(self.g.lane_half_width(self.r.rf_height_m))
        s, c = math.sin(delta), math.cos(delta)
        side = self.r.rf_side_m
        amp = nz.wall_waviness_mm * 1e-3
        k = 2 * math.pi / nz.wall_wavelength_m

        def wave(x_s: float, j: int) -> float:
            if amp == 0.0:
                return 0.0
            return amp * math.sin(k * (along + x_s * c) + self.wave_phase[2 * lane + j])

        sig = nz.range_sigma_mm * 1e-3
        l2 = (w0 + wave(self.x2, 0) - d + self.x2 * s - side * c) / c + sig * g()
        l3 = (w0 + wave(self.x3, 0) - d + self.x3 * s - side * c) / c + sig * g()
        l4 = (w0 + wave(self.x4, 1) + d - self.x4 * s - side * c) / c + sig * g()
        return l2, l3, l4

    def _trilaterate(self, l2: float, l3: float, l4: float) -> tuple[float, float]:
        """Eq. 5 (scalar copy of :func:`planners.sbg.trilateration.trilaterate`)."""
        r = self.r
        delta = math.atan((l2 - l3) / r.rf_b_m)
        d = ((l4 - l3) * math.cos(delta) + (r.rf_n_m - r.rf_a_m - r.rf_c_m) * math.sin(delta)) / 2.0
        return d, delta
