"""Steel box girder geometry: roof deck, U-ribs, lanes and the two crossbeams.

World frame (metres): X along the girder from the face of crossbeam 0
(X = 0) to the face of crossbeam 1 (X = ``length_m``); Y across the girder,
rib ``i`` centred at ``Y = i·rib_spacing_m``; Z up, the underside of the roof
deck at Z = 0, the girder's inside below it.  A lane (seed §3, Fig. 7) is the
strip of deck between two adjacent U-ribs; its weld lines are the two
rib-to-deck welds at the rib toes.

Each wall the robot drives on has a 2-D frame ``(origin, ex, ey)`` with the
wall normal ``n = ex × ey`` pointing into the girder's free space, so a
heading angle measured from ``ex`` toward ``ey`` turns counter-clockwise
about ``n`` (a left turn for the robot).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from planners.errors import InvalidInputError

ROOF, CROSSBEAM0, CROSSBEAM1 = 0, 1, 2
WALL_NAMES = ("roof", "crossbeam0", "crossbeam1")


@dataclass(frozen=True)
class WallFrame:
    """2-D chart of one wall: ``p = origin + x·ex + y·ey``, normal ``n``."""

    origin: np.ndarray
    ex: np.ndarray
    ey: np.ndarray

    @property
    def n(self) -> np.ndarray:
        return np.cross(self.ex, self.ey)

    def to_world(self, x: np.ndarray | float, y: np.ndarray | float) -> np.ndarray:
        """(N,) wall coordinates → (N,3) world points (scalars → one (3,) point)."""
        x = np.asarray(x, dtype=float)[..., None]
        y = np.asarray(y, dtype=float)[..., None]
        return self.origin + x * self.ex + y * self.ey

    def to_wall(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N,3) world points → wall coordinates (x, y)."""
        rel = np.asarray(p, dtype=float) - self.origin
        return rel @ self.ex, rel @ self.ey

    def heading_world(self, phi: np.ndarray | float) -> np.ndarray:
        phi = np.asarray(phi, dtype=float)[..., None]
        return np.cos(phi) * self.ex + np.sin(phi) * self.ey

    def heading_angle(self, h: np.ndarray) -> np.ndarray:
        h = np.asarray(h, dtype=float)
        return np.arctan2(h @ self.ey, h @ self.ex)


@dataclass(frozen=True)
class Girder:
    """Inside of one steel-box-girder bay, all dimensions in metres.

    ``n_ribs`` U-ribs (trapezoids: ``rib_top_width_m`` at the deck,
    ``rib_bottom_width_m`` at ``rib_depth_m`` below it) spaced
    ``rib_spacing_m`` apart give ``n_ribs − 1`` lanes.  Crossbeams
    (diaphragms) close the bay at both ends; the U-ribs pass through them in
    cut-outs ``cutout_clearance_m`` wider than the rib.
    """

    length_m: float = 2.0
    n_ribs: int = 4
    rib_spacing_m: float = 0.600
    rib_top_width_m: float = 0.300
    rib_bottom_width_m: float = 0.180
    rib_depth_m: float = 0.280
    deck_thickness_m: float = 0.016
    crossbeam_depth_m: float = 0.800
    crossbeam_thickness_m: float = 0.012
    cutout_clearance_m: float = 0.010
    edge_width_m: float = 0.300

    @property
    def n_lanes(self) -> int:
        return self.n_ribs - 1

    @property
    def lane_width_m(self) -> float:
        """Lane width at the deck (weld toe to weld toe)."""
        return self.rib_spacing_m - self.rib_top_width_m

    def rib_centres_y(self) -> np.ndarray:
        return np.arange(self.n_ribs, dtype=float) * self.rib_spacing_m

    def lane_centre_y(self, lane: int | np.ndarray) -> np.ndarray | float:
        return (np.asarray(lane, dtype=float) + 0.5) * self.rib_spacing_m

    def weld_y(self, lane: int) -> tuple[float, float]:
        """Y of the lane's two rib-to-deck welds (low Y, high Y)."""
        y0 = lane * self.rib_spacing_m
        return y0 + self.rib_top_width_m / 2.0, y0 + self.rib_spacing_m - self.rib_top_width_m / 2.0

    def rib_half_width(self, depth_m: float | np.ndarray) -> np.ndarray:
        """Half width of a U-rib at ``depth_m`` below the deck (webs are straight)."""
        z = np.clip(np.asarray(depth_m, dtype=float), 0.0, self.rib_depth_m)
        top, bot = self.rib_top_width_m / 2.0, self.rib_bottom_width_m / 2.0
        return top + (bot - top) * z / self.rib_depth_m

    def lane_half_width(self, depth_m: float | np.ndarray) -> np.ndarray:
        """Half the clear width between the two rib webs at ``depth_m``."""
        return self.rib_spacing_m / 2.0 - self.rib_half_width(depth_m)

    @property
    def y_extent(self) -> tuple[float, float]:
        return -self.edge_width_m, (self.n_ribs - 1) * self.rib_spacing_m + self.edge_width_m

    def wall(self, wall: int) -> WallFrame:
        """2-D frame of the roof or a crossbeam face (see the module docstring)."""
        X, Y, Z = np.eye(3)
        if wall == ROOF:
            return WallFrame(np.zeros(3), X, -Y)  # n = -Z: the robot hangs under the deck
        if wall == CROSSBEAM0:
            return WallFrame(np.zeros(3), Y, Z)  # n = +X
        if wall == CROSSBEAM1:
            return WallFrame(np.array([self.length_m, 0.0, 0.0]), -Y, Z)  # n = -X
        raise InvalidInputError(f"wall must be 0 (roof), 1 or 2 (crossbeams), got {wall}")

    def validate(self) -> Girder:
        """Raise :class:`InvalidInputError` naming the first bad dimension."""
        for f in fields(self):
            v = getattr(self, f.name)
            if not isinstance(v, int | float) or not math.isfinite(v):
                raise InvalidInputError(f"girder.{f.name} must be a finite number, got {v!r}")
        if int(self.n_ribs) != self.n_ribs or self.n_ribs < 2:
            raise InvalidInputError(
                f"girder.n_ribs must be an integer ≥ 2 (one lane), got {self.n_ribs}"
            )
        for name in [
            "length_m",
            "rib_spacing_m",
            "rib_top_width_m",
            "rib_bottom_width_m",
            "rib_depth_m",
            "deck_thickness_m",
            "crossbeam_depth_m",
            "crossbeam_thickness_m",
        ]:
            if getattr(self, name) <= 0:
                raise InvalidInputError(f"girder.{name} must be > 0, got {getattr(self, name)}")
        if self.rib_top_width_m >= self.rib_spacing_m:
            raise InvalidInputError(
                f"girder.rib_top_width_m {self.rib_top_width_m} must be < rib_spacing_m {self.rib_spacing_m}"
            )
        if self.cutout_clearance_m < 0 or self.edge_width_m < 0:
            raise InvalidInputError("girder.cutout_clearance_m and edge_width_m must be ≥ 0")
        return self


def sample_girders() -> dict[str, Girder]:
    """Sample bays.  U-rib 300/180/280 mm at 600 mm is a common orthotropic
    deck; the seed gives no girder dimensions, so all of these are chosen.

    - ``seed_lab``: a 2 m mock-up with 3 lanes (two U-turns, one at each
      crossbeam) — the default of the ``sbg.inspect`` plan kind.
    - ``deck_bay``: a 3.2 m bay between diaphragms with 5 lanes.
    - ``single_lane``: one long lane for centreline-tracking runs (Fig. 14).
    """
    return {
        "seed_lab": Girder(),
        "deck_bay": Girder(length_m=3.2, n_ribs=6),
        "single_lane": Girder(length_m=2.5, n_ribs=2),
    }
