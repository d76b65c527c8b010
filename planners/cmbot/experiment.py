"""The seed's §4 arm experiment (Eq. 21–26) and the resolved-rate tracking loop.

The tool Q starts at (0, 820, −2790 mm, 0°, 0°, −90°) in frame (6) (pose
angles as fixed-axis roll-pitch-yaw) and follows for 20 s the piecewise
velocities of Eq. 21–26, read as the generalised velocity v = [q̇x q̇y q̇z
ωx ωy ωz] of Eq. 13 in (6): a spatial curve for 0 ≤ t < 5 s, then a straight
line along −y.

Units.  Positions are mm/s (their integral ends the first phase at
(−1250, 20, −1565) mm and the straight line is 1170 mm long).  The angular
rows as printed in °/s integrate to exactly 360° about y and about z over the
first 5 s (28.8 = 360/12.5) while ωx integrates to zero: the tool would tumble
through full turns and the pose angles would come back to where they started,
at up to 204 °/s, which does not describe "moving from the start point to the
working position".  The consistent reading is that all six rows are in
milli-units (mm/s and mrad/s): the tool then turns by 0.36 rad about y and z,
ending 20° below the horizontal, pointing away from the base at the line it
follows.  ``angular_unit="deg"`` keeps the printed reading for comparison.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from planners.cmbot.arm import ArmKinematics, rotation_error, rpy_to_matrix
from planners.cmbot.avoidance import AvoidanceParams, combine, escape_velocities
from planners.cmbot.distance import (
    Cuboid,
    boxes_arrays,
    point_box_closed_form,
    sphere_box_exact,
)
from planners.errors import CancelledError, InvalidInputError, UnreachableError

ANGULAR_UNITS = {"mrad": 1e-3, "deg": np.pi / 180.0, "rad": 1.0}


@dataclass(frozen=True)
class Section4Trajectory:
    """Seed §4: start pose (mm, deg) in (6), duration, switch time and unit reading."""

    start_mm_deg: tuple[float, float, float, float, float, float] = (
        0.0,
        820.0,
        -2790.0,
        0.0,
        0.0,
        -90.0,
    )
    duration_s: float = 20.0
    switch_s: float = 5.0
    angular_unit: str = "mrad"
    offset_m: tuple[float, float, float] = (
        0.0,
        0.0,
        0.0,
    )  # whole path shifted in (6), e.g. by a base move

    def __post_init__(self) -> None:
        if self.angular_unit not in ANGULAR_UNITS:
            raise InvalidInputError(
                f"angular_unit must be one of {sorted(ANGULAR_UNITS)}, got {self.angular_unit!r}"
            )
        if not (self.duration_s > 0 and 0 <= self.switch_s <= self.duration_s):
            raise InvalidInputError("need duration_s > 0 and 0 ≤ switch_s ≤ duration_s")

    def velocity(self, t: np.ndarray) -> np.ndarray:
        """Eq. 21–26: v(t) (…,6) in m/s and rad/s."""
        t = np.asarray(t, dtype=float)
        a = t < self.switch_s
        lin = (
            np.stack(
                [
                    np.where(a, 80.0 * t - 450.0, 0.0),
                    np.where(a, -160.0, -78.0),
                    np.where(a, 98.0 * t, 0.0),
                ],
                -1,
            )
            * 1e-3
        )
        ang = (
            np.stack(
                [
                    np.where(a, 7.34 * t - 18.35, 0.0),
                    np.where(a, 28.8 * t, 0.0),
                    np.where(a, 28.8 * t, 0.0),
                ],
                -1,
            )
            * ANGULAR_UNITS[self.angular_unit]
        )
        return np.concatenate([lin, ang], axis=-1)

    def start_pose(self) -> np.ndarray:
        s = self.start_mm_deg
        T = np.eye(4)
        T[:3, :3] = rpy_to_matrix(*np.radians(s[3:]))
        T[:3, 3] = np.array(s[:3]) * 1e-3 + np.asarray(self.offset_m)
        return T

    def poses(self, t: np.ndarray, step_s: float = 1e-3) -> tuple[np.ndarray, np.ndarray]:
        """Desired positions (T,3) and rotations (T,3,3) at times ``t``.

        Positions are the exact integrals of Eq. 21–23; rotations integrate
        Ṙ = [ω]ₓR (ω in (6)) with midpoint rotation-vector steps of ``step_s``
        and are interpolated (slerp) between steps.
        """
        t = np.asarray(t, dtype=float)
        s = np.minimum(t, self.switch_s)
        x = (40.0 * s**2 - 450.0 * s) * 1e-3
        y = (-160.0 * s - 78.0 * (t - s)) * 1e-3
        z = 49.0 * s**2 * 1e-3
        T0 = self.start_pose()
        pos = T0[:3, 3] + np.stack([x, y, z], axis=-1)
        grid, rots = _rotation_track(self, step_s)
        R = Slerp(grid, rots)(np.clip(t, 0.0, grid[-1])).as_matrix()
        return pos, R


@functools.lru_cache(maxsize=16)
def _rotation_track(traj: Section4Trajectory, step_s: float) -> tuple[np.ndarray, Rotation]:
    """Orientation of the tool on a uniform grid over the whole trajectory (cached)."""
    n = max(int(np.ceil(traj.duration_s / step_s)), 1)
    grid = np.linspace(0.0, traj.duration_s, n + 1)
    mids = 0.5 * (grid[1:] + grid[:-1])
    incr = Rotation.from_rotvec(traj.velocity(mids)[:, 3:] * np.diff(grid)[:, None]).as_quat()
    q = np.empty((n + 1, 4))
    q[0] = Rotation.from_matrix(traj.start_pose()[:3, :3]).as_quat()
    # Ṙ = [ω]ₓR with ω in the base frame: R_{k+1} = exp(ω·dt)·R_k (left multiplication).
    for k in range(n):
        x1, y1, z1, w1 = incr[k]
        x2, y2, z2, w2 = q[k]
        q[k + 1] = (
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        )
    return grid, Rotation.from_quat(q)


def _expm(w: np.ndarray) -> np.ndarray:
    """Rotation matrix of the rotation vector ``w`` (Rodrigues)."""
    th = float(np.linalg.norm(w))
    K = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    if th < 1e-12:
        return np.eye(3) + K
    return np.eye(3) + np.sin(th) / th * K + (1.0 - np.cos(th)) / th**2 * (K @ K)


@dataclass(frozen=True)
class ClearanceFilter:
    """Which sphere–box pairs count: spheres of body 0 (the J6/J7 modules bolted
    to the climbing mechanism) ignore the climbing mechanism's own boxes."""

    exclude_body0_groups: tuple[str, ...] = ("climber",)

    def mask(self, spheres_body: np.ndarray, boxes: list[Cuboid]) -> np.ndarray:
        groups = np.array([b.group for b in boxes])
        m = np.ones((len(spheres_body), len(boxes)), dtype=bool)
        for g in self.exclude_body0_groups:
            m[np.ix_(spheres_body == 0, groups == g)] = False
        return m


@dataclass
class ArmRun:
    """Time series of one tracking run (all SI units)."""

    times: np.ndarray
    q: np.ndarray  # (T,7)
    qdot: np.ndarray  # (T,7) commanded rates
    tool_pos: np.ndarray  # (T,3)
    desired_pos: np.ndarray  # (T,3)
    pos_error: np.ndarray  # (T,) m
    rot_error: np.ndarray  # (T,) rad
    clearance: np.ndarray  # (T,) m, min over counted sphere–box pairs
    closest: list[str] = field(default_factory=list)  # per step "sphere i ↔ box"
    active_pairs: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    avoidance: bool = False


def pair_distances(
    centers: np.ndarray,
    radii: np.ndarray,
    boxes: list[Cuboid],
    arrays: tuple[np.ndarray, np.ndarray, np.ndarray],
    mask: np.ndarray,
    cutoff: float,
) -> tuple[list[tuple[int, int, float, np.ndarray]], tuple[float, int, int]]:
    """Pairs within ``cutoff`` with distance and direction, and the overall minimum.

    The closed-form sphere–box distance (exact for spheres against cuboids)
    gives d_ij and u_ij of every pair at once; Eq. 15 acts on those within
    ``cutoff``.  (It replaced a per-pair GJK, which agreed to 1e-9 and was
    slower.)
    """
    d, _ = sphere_box_exact(centers, radii, arrays, directions=False)
    d = np.where(mask, d, np.inf)
    si, bi = np.nonzero(d <= cutoff)
    near: list[tuple[int, int, float, np.ndarray]] = []
    if len(si):
        # Directions only for the few pairs Eq. 15 acts on.
        bc, bh, bR = arrays
        _, u = point_box_closed_form(centers[si] - bc[bi], bh[bi], bR[bi])
        assert u is not None  # directions=True
        near = [
            (int(i), int(j), float(d[i, j]), u[k])
            for k, (i, j) in enumerate(zip(si, bi, strict=True))
        ]
    flat = int(np.argmin(d))
    i, j = np.unravel_index(flat, d.shape)
    return near, (float(d[i, j]), int(i), int(j))


def track(
    arm: ArmKinematics,
    boxes: list[Cuboid],
    traj: Section4Trajectory,
    q0: np.ndarray,
    *,
    avoidance: AvoidanceParams | None,
    dt: float = 0.01,
    gain: float = 10.0,
    pair_filter: ClearanceFilter | None = None,
    progress: Callable[[float, str], None] | None = None,
) -> ArmRun:
    """Resolved-rate tracking of ``traj`` from ``q0`` (seed Eq. 14 / Eq. 20).

    v = v_d + K·e (closed-loop on the pose error e so integration error does
    not accumulate; K = ``gain`` 1/s); β from Eq. 20 with the escape terms of
    Eq. 15 when ``avoidance`` is given, else the minimum-norm J⁺v.  Joint rates
    are integrated with explicit Euler steps of ``dt``; the null-space term is
    scaled down if it would push a joint past its speed limit.
    """
    if dt <= 0 or gain < 0:
        raise InvalidInputError("dt must be > 0 and gain ≥ 0")
    times = np.arange(0.0, traj.duration_s + dt / 2, dt)
    pos_d, R_d = traj.poses(times)
    v_d = traj.velocity(times)
    flt = pair_filter or ClearanceFilter()
    mask = flt.mask(arm.spheres.body, boxes)
    arrays = boxes_arrays(boxes)
    radii = arm.spheres.radius
    cutoff = avoidance.d_s if avoidance is not None else 0.0
    n = len(times)
    Q = np.empty((n, arm.dof))
    Qd = np.zeros((n, arm.dof))
    tool = np.empty((n, 3))
    perr = np.empty(n)
    rerr = np.empty(n)
    clear = np.empty(n)
    closest: list[str] = []
    active = np.zeros(n, dtype=int)
    q = np.asarray(q0, dtype=float).copy()
    for k in range(n):
        F = arm.frames(q)
        Tt = F[-1]
        e = np.concatenate([pos_d[k] - Tt[:3, 3], rotation_error(R_d[k], Tt[:3, :3])])
        Q[k], tool[k] = q, Tt[:3, 3]
        perr[k], rerr[k] = np.linalg.norm(e[:3]), np.linalg.norm(e[3:])
        centers = arm.sphere_centers(F)
        near, best = pair_distances(centers, radii, boxes, arrays, mask, cutoff)
        clear[k] = best[0]
        closest.append(
            f"sphere {best[1]} (frame {arm.spheres.frame[best[1]]}) ↔ {boxes[best[2]].name}"
            if best[1] >= 0
            else ""
        )
        if k == n - 1:
            break
        J = arm.jacobian_from_frames(F)
        v = v_d[k] + gain * e
        if avoidance is not None and near:
            idx = np.array([p[0] for p in near])
            d = np.array([p[2] for p in near])
            u = np.array([p[3] for p in near])
            s = escape_velocities(d, u, avoidance)
            Jc = arm.sphere_jacobians(F, centers, idx)
            bt, bn = combine(J, v, Jc.reshape(-1, arm.dof), s.reshape(-1), avoidance.damping)
            active[k] = len(near)
        else:
            bt, bn = combine(J, v)
        # Keep 5 % of every joint's speed in reserve for the gate's interpolation.
        beta = bt + _speed_scale(bt, bn, 0.95 * arm.max_speed) * bn
        Qd[k] = beta
        q = q + beta * dt
        if progress is not None and k % 200 == 0:
            progress(k / n, "tracking")
    return ArmRun(
        times, Q, Qd, tool, pos_d, perr, rerr, clear, closest, active, avoidance is not None
    )


def _speed_scale(bt: np.ndarray, bn: np.ndarray, vmax: np.ndarray) -> float:
    """Largest α ∈ [0, 1] with |bt + α·bn| ≤ vmax wherever bt alone respects it."""
    alpha = 1.0
    for b, n_, m in zip(bt, bn, vmax, strict=True):
        if abs(b + n_) <= m or abs(n_) < 1e-15 or abs(b) > m:
            continue
        lim = (np.sign(n_) * m - b) / n_
        alpha = min(alpha, max(0.0, float(lim)))
    return alpha


def check_cancel(progress: Callable[[float, str], None] | None, f: float, stage: str) -> None:
    """Call ``progress`` if given (it may raise :class:`CancelledError`)."""
    if progress is not None:
        try:
            progress(f, stage)
        except CancelledError:
            raise


@dataclass(frozen=True)
class ExperimentParams:
    """Settings of the §4 arm experiment.

    ``avoidance`` is Eq. 15's threshold d_s (where escaping starts) and
    v_max; ``min_clearance_m`` the clearance the simulation gate requires.
    Eq. 15's escape speed is zero at d_s, so an approaching sphere always
    dips below d_s before it is pushed back: the required clearance must lie
    below d_s, never at it.  ``payload_kg`` is the tool carried in the
    experiment (chosen: nozzle or laser head); the 5 kg design payload is
    checked over the workspace cuboid (:mod:`planners.cmbot.indicators`).
    ``q_ready_deg`` picks the redundant arm's start
    configuration (the seed gives only the tool pose): the IK solution reached
    from this posture (elbow low, below the top bar).
    """

    trajectory: Section4Trajectory = field(default_factory=Section4Trajectory)
    avoidance: AvoidanceParams = field(
        default_factory=lambda: AvoidanceParams(d_s=0.15, v_max=0.3, damping=0.02)
    )
    min_clearance_m: float = 0.05
    dt_s: float = 0.01
    gain: float = 10.0
    payload_kg: float = 2.0
    q_ready_deg: tuple[float, ...] = (90.0, 45.0, 50.0, -85.0, 0.0, -15.0, 180.0)


def start_configuration(
    model: Any, traj: Section4Trajectory, q_ready_deg: tuple[float, ...]
) -> np.ndarray:
    """IK of the start pose from the ready posture (damped least squares, no restarts)."""
    from robots.kinematics import solve_ik_dls

    q = solve_ik_dls(model, traj.start_pose(), np.radians(q_ready_deg), restarts=0, max_iter=400)
    if q is None:
        p = traj.start_pose()[:3, 3]
        raise UnreachableError(
            f"the start pose at {np.round(p * 1e3, 1).tolist()} mm in (6) is out of the arm's reach"
        )
    return q
