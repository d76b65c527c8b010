"""Geometric checks of a navigation plan, independent of the planner that made
it (seed 000 §4.3, Alg. 6 "Point Inside Boundary Check").

Alg. 6 tests sampled footprint points while planning; the checks here test
the *whole* footprint rectangle at every driven pose and the area it sweeps
between consecutive poses against the union of the cluster boundary
polygons, exactly (shapely), via
:func:`planners.navigation.pibc.swept_on_steel`.  They serve both the plan
(``poses_on_steel``) and the replay of the compiled wheel commands.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from planners.navigation.pibc import steel_union, swept_on_steel


@dataclass(frozen=True)
class Footprint:
    """The robot rectangle that must stay on steel, in the base frame (m)."""

    length_m: float
    width_m: float
    center_x_m: float = 0.0
    center_y_m: float = 0.0


def alg6_spacing_m(length_m: float, width_m: float) -> float:
    """Spacing of Alg. 6's projected footprint points: every centimetre, at
    least four across the short side, never coarser than 4 cm (chosen: the
    ARA body's 0.68 × 0.16 m needs no finer than 4 cm)."""
    return float(min(0.04, max(0.01, min(length_m, width_m) / 4.0)))


@dataclass(frozen=True)
class SweptReport:
    """Which poses (and the area swept to them) keep the footprint on steel.

    ``on_steel`` (P,) is over ``poses`` (P,3) = all pose lists stacked; an
    empty report counts as all on steel (nothing is driven).
    """

    poses: np.ndarray
    on_steel: np.ndarray

    @property
    def n_poses(self) -> int:
        return len(self.poses)

    @property
    def fraction(self) -> float:
        return float(self.on_steel.mean()) if len(self.on_steel) else 1.0

    @property
    def first_off(self) -> np.ndarray | None:
        """The first pose (x, y, yaw) that leaves the steel, or None."""
        if self.on_steel.all():
            return None
        return self.poses[int(np.argmin(self.on_steel))]


def poses_on_steel(
    pose_lists: Sequence[np.ndarray], boundaries: Sequence[np.ndarray], footprint: Footprint
) -> SweptReport:
    """The footprint test of every pose list (one per route edge, (P_k,3) in
    plane coordinates) against the union of the boundary polygons (K,2).

    Each list is swept on its own (pose 0 of a list is tested alone: the
    lists are separate drives), so no area is swept between two edges.
    """
    lists = [np.asarray(x, dtype=float).reshape(-1, 3) for x in pose_lists]
    lists = [x for x in lists if len(x)]
    if not lists:
        return SweptReport(np.zeros((0, 3)), np.zeros(0, dtype=bool))
    steel = steel_union([np.asarray(b, dtype=float) for b in boundaries])
    ok = np.concatenate(
        [
            swept_on_steel(
                x,
                steel,
                footprint.length_m,
                footprint.width_m,
                center_x_m=footprint.center_x_m,
                center_y_m=footprint.center_y_m,
            )
            for x in lists
        ]
    )
    return SweptReport(np.vstack(lists), ok)


def to_plane(points: np.ndarray, origin: np.ndarray, e1: np.ndarray, e2: np.ndarray) -> np.ndarray:
    """World points (N,3) → plane coordinates (N,2) in the frame (origin, e1, e2)
    (orthonormal e1, e2: the coordinates are the projections on them)."""
    d = np.asarray(points, dtype=float).reshape(-1, 3) - np.asarray(origin, dtype=float)
    return np.stack([d @ np.asarray(e1, dtype=float), d @ np.asarray(e2, dtype=float)], axis=1)


def bars_covered(bar_ids: Sequence[int], driven_clusters: Sequence[int]) -> int:
    """How many of the bars ``bar_ids`` the route drives on (an edge drives
    on the first cluster it lists)."""
    driven = set(driven_clusters)
    return sum(b in driven for b in bar_ids)
