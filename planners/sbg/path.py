"""The whole boustrophedon inspection path (seed §3, Fig. 4 and Fig. 9).

Every lane's centreline is driven once on the roof; at the lane's end the
robot crosses the concave corner down onto the crossbeam, steers into the
next lane with the U-shaped path S1–S2–S3 (two in-place 90° turns) and
crosses the corner back up.  The operator picks the start lane, the sweep
direction across the lanes and the crossbeam the first lane starts from.
When the start lane is not an edge lane the sweep runs to one edge, then a
longer U-turn (S2 spanning several lanes) brings the robot back to the lanes
on the other side of the start.

Points are the robot base origin (on the wall under the robot centre Oc),
in the girder's world frame (:mod:`planners.sbg.girder`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from planners.errors import InfeasibleError, InvalidInputError
from planners.sbg import corner as corner_mod
from planners.sbg.girder import CROSSBEAM0, CROSSBEAM1, ROOF, Girder
from planners.sbg.robot import ClimberParams

LANE, CORNER_DOWN, S1, TURN, S2, S3, CORNER_UP = (
    "lane",
    "corner_down",
    "s1",
    "turn",
    "s2",
    "s3",
    "corner_up",
)
SEGMENT_KINDS = (LANE, CORNER_DOWN, S1, TURN, S2, S3, CORNER_UP)


@dataclass(frozen=True)
class CornerGeom:
    """A concave corner as the robot meets it: ``point`` on the corner line
    (at the lane centre), ``line_dir`` along it, ``t_old`` the direction on
    the old wall toward the corner, ``n_old`` the old wall's normal (= the
    direction away from the corner on the new wall)."""

    point: np.ndarray
    line_dir: np.ndarray
    t_old: np.ndarray
    n_old: np.ndarray
    from_wall: int
    to_wall: int

    def to_world(
        self, s: np.ndarray, h: np.ndarray, lateral: np.ndarray | float = 0.0
    ) -> np.ndarray:
        """Corner-frame (s, h) (see :mod:`planners.sbg.corner`) → world (N,3)."""
        s = np.asarray(s, dtype=float)[..., None]
        h = np.asarray(h, dtype=float)[..., None]
        lat = np.asarray(lateral, dtype=float)[..., None]
        return self.point + s * self.t_old + h * self.n_old + lat * self.line_dir

    def axes_world(self, x2: np.ndarray, z2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Corner-frame 2-D body axes (N,2) → world (N,3) body x and z."""
        x = x2[..., :1] * self.t_old + x2[..., 1:] * self.n_old
        z = z2[..., :1] * self.t_old + z2[..., 1:] * self.n_old
        return x, z


@dataclass(frozen=True)
class PathSegment:
    """One piece of the path.

    ``kind``: one of :data:`SEGMENT_KINDS`; ``lane`` the lane being inspected
    (or left, for U-turn pieces) and ``to_lane`` the lane a U-turn leads to;
    ``wall``: 0 roof, 1/2 crossbeam at X = 0 / X = length (corners: the wall
    being left); ``points`` (K,3) base-origin path; ``length_m`` its length;
    ``turn_rad`` the in-place turn of a ``turn`` (left +); ``heading`` the
    unit travel direction of a straight; ``corner`` the corner of a crossing.
    """

    kind: str
    lane: int
    to_lane: int
    wall: int
    points: np.ndarray
    length_m: float
    turn_rad: float = 0.0
    heading: np.ndarray | None = None
    corner: CornerGeom | None = None

    @property
    def start(self) -> np.ndarray:
        return self.points[0]

    @property
    def end(self) -> np.ndarray:
        return self.points[-1]


@dataclass(frozen=True)
class InspectionPath:
    """The planned path: segments in driving order, lane order, each lane's
    travel direction along X (+1/−1), the U-turn depth and the total length."""

    girder: Girder
    robot: ClimberParams
    segments: list[PathSegment]
    lane_order: list[int]
    lane_dirs: dict[int, int]
    start_lane: int
    direction: int
    start_end: int
    turn_depth_m: float
    total_length_m: float = field(default=0.0)

    def polyline(self) -> np.ndarray:
        """All points in order (duplicates at joints removed)."""
        pts = [self.segments[0].points]
        for s in self.segments[1:]:
            pts.append(s.points[1:] if np.allclose(s.points[0], pts[-1][-1]) else s.points)
        return np.concatenate(pts)

    def lengths_by_kind(self) -> dict[str, float]:
        out = dict.fromkeys(SEGMENT_KINDS, 0.0)
        for s in self.segments:
            out[s.kind] += s.length_m
        return out


def lane_order(n_lanes: int, start_lane: int, direction: int) -> list[int]:
    """Boustrophedon lane order: from ``start_lane`` toward ``direction`` to
    the edge, then the lanes on the other side, nearest first."""
    first = list(range(start_lane, n_lanes)) if direction > 0 else list(range(start_lane, -1, -1))
    rest = (
        list(range(start_lane - 1, -1, -1))
        if direction > 0
        else list(range(start_lane + 1, n_lanes))
    )
    return first + rest


def turn_depth(girder: Girder, robot: ClimberParams, clearance_m: float) -> float:
    """Depth below the deck of the U-turn's horizontal leg S2: the robot's
    turning circle (half diagonal) must clear the U-rib cut-outs."""
    return girder.rib_depth_m + girder.cutout_clearance_m + clearance_m + robot.half_diagonal_m


def check_fits(girder: Girder, robot: ClimberParams, clearance_m: float) -> float:
    """Raise :class:`InfeasibleError` when the robot does not fit the lanes
    or the crossbeams; returns the U-turn depth."""
    if girder.lane_width_m < robot.width_m + 2 * 0.005:
        raise InfeasibleError(
            f"lane width {girder.lane_width_m * 1e3:.0f} mm (rib_spacing − rib_top_width) leaves less "
            f"than 5 mm each side of the {robot.width_m * 1e3:.0f} mm robot"
        )
    w_rf = float(girder.lane_half_width(robot.rf_height_m))
    if w_rf - robot.rf_side_m < 0.005:
        raise InfeasibleError(
            f"the side range finders at {robot.rf_height_m * 1e3:.0f} mm would be "
            f"{(w_rf - robot.rf_side_m) * 1e3:.1f} mm from the rib webs (need ≥ 5 mm)"
        )
    depth = turn_depth(girder, robot, clearance_m)
    if girder.crossbeam_depth_m < depth + robot.half_diagonal_m:
        raise InfeasibleError(
            f"crossbeam_depth_m {girder.crossbeam_depth_m} is too shallow for the U-turn at "
            f"{depth:.3f} m below the deck (needs ≥ {depth + robot.half_diagonal_m:.3f} m)"
        )
    usable = girder.length_m - robot.length_m
    if usable <= 0.05:
        raise InfeasibleError(
            f"girder.length_m {girder.length_m} leaves {usable * 1e3:.0f} mm of lane for a "
            f"{robot.length_m * 1e3:.0f} mm robot"
        )
    return depth


def corner_points(geom: CornerGeom, robot: ClimberParams, n: int = 46) -> np.ndarray:
    """Base-origin path through a crossing (noise-free geometry of Eq. 3)."""
    theta = np.linspace(0.0, math.pi / 2, n)
    origin, _, _ = corner_mod.base_pose(theta, robot.wheelbase_m, robot.wheel_radius_m)
    return geom.to_world(origin[:, 0], origin[:, 1])


def _polyline_length(p: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())


def plan_path(
    girder: Girder,
    robot: ClimberParams | None = None,
    *,
    start_lane: int = 0,
    direction: int = 1,
    start_end: int = 0,
    turn_clearance_m: float = 0.030,
) -> InspectionPath:
    """Plan the full inspection path (Fig. 4a: lane centrelines joined by
    corner crossings and Fig. 9 U-turns).

    ``start_lane`` in ``[0, n_lanes)``; ``direction`` +1 sweeps toward higher
    lane numbers (larger Y) first, −1 toward lower; ``start_end`` 0 starts
    the first lane at crossbeam 0 (X = 0) driving +X, 1 at crossbeam 1.
    """
    girder = girder.validate()
    robot = ClimberParams.coerce(robot)
    if not isinstance(start_lane, int | np.integer) or not 0 <= start_lane < girder.n_lanes:
        raise InvalidInputError(
            f"start_lane must be an integer in [0, {girder.n_lanes - 1}], got {start_lane!r}"
        )
    if direction not in (1, -1):
        raise InvalidInputError(f"direction must be +1 or -1, got {direction!r}")
    if start_end not in (0, 1):
        raise InvalidInputError(f"start_end must be 0 (crossbeam at X=0) or 1, got {start_end!r}")
    if not math.isfinite(turn_clearance_m) or turn_clearance_m < 0:
        raise InvalidInputError(f"turn_clearance_m must be ≥ 0, got {turn_clearance_m}")
    depth = check_fits(girder, robot, turn_clearance_m)
    order = lane_order(girder.n_lanes, int(start_lane), int(direction))
    half = robot.length_m / 2.0
    Lg = girder.length_m
    X, Y, Z = np.eye(3)
    segments: list[PathSegment] = []
    dirs: dict[int, int] = {}
    sx = 1 if start_end == 0 else -1
    for i, lane in enumerate(order):
        yc = float(girder.lane_centre_y(lane))
        dirs[lane] = sx
        x0, x1 = (half, Lg - half) if sx > 0 else (Lg - half, half)
        pts = np.array([[x0, yc, 0.0], [x1, yc, 0.0]])
        segments.append(PathSegment(LANE, lane, lane, ROOF, pts, abs(x1 - x0), heading=sx * X))
        if i == len(order) - 1:
            break
        nxt = order[i + 1]
        yn = float(girder.lane_centre_y(nxt))
        cb = CROSSBEAM1 if sx > 0 else CROSSBEAM0
        xc = Lg if sx > 0 else 0.0
        n_cb = -X if sx > 0 else X
        down = CornerGeom(np.array([xc, yc, 0.0]), Y.copy(), sx * X, -Z, ROOF, cb)
        cp = corner_points(down, robot)
        segments.append(
            PathSegment(CORNER_DOWN, lane, nxt, ROOF, cp, _polyline_length(cp), corner=down)
        )
        a1 = np.array([xc, yc, -half])
        a2 = np.array([xc, yc, -depth])
        a3 = np.array([xc, yn, -depth])
        a4 = np.array([xc, yn, -half])
        side = math.copysign(1.0, yn - yc)
        h1, h2, h3 = -Z, side * Y, Z
        t1 = math.copysign(math.pi / 2, float(np.dot(n_cb, np.cross(h1, h2))))
        t2 = math.copysign(math.pi / 2, float(np.dot(n_cb, np.cross(h2, h3))))
        segments.append(
            PathSegment(S1, lane, nxt, cb, np.array([a1, a2]), depth - half, heading=h1)
        )
        segments.append(PathSegment(TURN, lane, nxt, cb, np.array([a2, a2]), 0.0, turn_rad=t1))
        segments.append(
            PathSegment(S2, lane, nxt, cb, np.array([a2, a3]), abs(yn - yc), heading=h2)
        )
        segments.append(PathSegment(TURN, lane, nxt, cb, np.array([a3, a3]), 0.0, turn_rad=t2))
        segments.append(
            PathSegment(S3, lane, nxt, cb, np.array([a3, a4]), depth - half, heading=h3)
        )
        up = CornerGeom(np.array([xc, yn, 0.0]), Y.copy(), Z.copy(), n_cb, cb, ROOF)
        cp = corner_points(up, robot)
        segments.append(PathSegment(CORNER_UP, lane, nxt, cb, cp, _polyline_length(cp), corner=up))
        sx = -sx
    total = float(sum(s.length_m for s in segments))
    return InspectionPath(
        girder=girder,
        robot=robot,
        segments=segments,
        lane_order=order,
        lane_dirs=dirs,
        start_lane=int(start_lane),
        direction=int(direction),
        start_end=int(start_end),
        turn_depth_m=depth,
        total_length_m=total,
    )
