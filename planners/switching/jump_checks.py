"""Checks of a planned inch-worm jump recomputed from the returned trajectory
itself (seed 000 §3.2, §5.2.2), so that a planner bug cannot
certify its own output: joint limits and speeds from the timed joint
trajectory, and the foothold footprint against the target plane's concave
hull (the area availability S_am of Eq. 3.1, whose rectangles Alg. 2 finds).
"""

from __future__ import annotations

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

#: A target surface as the jump takes it: (origin (3,), x axis (3,), y axis (3,),
#: concave hull in those plane coordinates).
SurfaceFrame = tuple[np.ndarray, np.ndarray, np.ndarray, BaseGeometry]


def joint_limit_excess(q: np.ndarray, limits: np.ndarray) -> float:
    """Largest excess (rad, ≥ 0) of any sample of the (T,J) trajectory ``q``
    outside the (J,2) ``[lo, hi]`` joint limits; 0 inside them."""
    q = np.asarray(q, dtype=float)
    lo, hi = np.asarray(limits, dtype=float)[:, 0], np.asarray(limits, dtype=float)[:, 1]
    if q.size == 0:
        return 0.0
    return float(np.maximum(0.0, np.maximum(lo - q, q - hi)).max())


def speed_ratio(q: np.ndarray, times: np.ndarray, max_speed: np.ndarray) -> float:
    """Largest finite-difference joint speed |Δq/Δt| over the per-joint
    ``max_speed`` (rad/s); ≤ 1 is within the limits, 0 for a single sample."""
    q = np.asarray(q, dtype=float)
    if len(q) < 2:
        return 0.0
    speed = np.abs(np.diff(q, axis=0)) / np.diff(np.asarray(times, dtype=float))[:, None]
    return float((speed / np.asarray(max_speed, dtype=float)).max())


def foot_inside_surface(
    T: np.ndarray, foot: tuple[float, float], surface: SurfaceFrame, tol_m: float
) -> bool:
    """Whether the foot's (length, width) rectangle at pose ``T`` (4×4; the
    rectangle in its x–y plane, centred) projected on the surface plane lies
    inside the surface hull grown by ``tol_m`` (exact, shapely)."""
    origin, ex, ey, hull = surface
    hl, hw = foot[0] / 2, foot[1] / 2
    local = np.array([[hl, hw, 0], [-hl, hw, 0], [-hl, -hw, 0], [hl, -hw, 0]])
    T = np.asarray(T, dtype=float)
    c = local @ T[:3, :3].T + T[:3, 3] - origin
    return bool(hull.buffer(tol_m).covers(shapely.Polygon(np.column_stack([c @ ex, c @ ey]))))
