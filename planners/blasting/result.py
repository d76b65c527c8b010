"""Result contract of the sand-blasting planner: :class:`BlastPlan` and its
plan checks (DESIGN §4: coverage Eq. 3.2 raster, overspray, joint limits,
joint speed Eq. 3.12–3.13, ellipsoid clearance §3.4.2, IK residual).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from planners.blasting.constants import OVERSPRAY_TARGET


@dataclass(frozen=True)
class RobotMotion:
    """The with-robot fields of a :class:`BlastPlan`, none of them optional
    (see :meth:`BlastPlan.robot_motion`)."""

    joint_trajectory: np.ndarray
    times: np.ndarray
    clearance: np.ndarray
    waypoint_spot: np.ndarray
    segment: np.ndarray
    ik_residual_mm: np.ndarray
    ik_residual_deg: np.ndarray
    joint_limits: np.ndarray
    speed_limit_rad_s: float


@dataclass
class BlastPlan:
    """Result of :func:`plan_blasting`.

    Discs (index = disc id): ``centers`` (N,3) world, ``centers_2d`` (N,2)
    plane, ``radii`` (N,), ``classes`` (N,) — Eq. 3.2 class of the lattice
    disc it came from (1 inside, 3 boundary; 4 = added by our cover step),
    ``stream_mm`` (N,), ``tilt_deg`` (N,).  ``order`` visits disc ids;
    ``skipped`` are disc ids no collision-free configuration reaches (not in
    ``order``).  Coverage/overspray are rasterised over the visited discs.
    With a robot: ``joint_trajectory`` (T,6) rad, ``times`` (T,) s,
    ``clearance`` (T,) m (signed; ``inf`` without obstacles),
    ``waypoint_spot`` (T,) disc id at a spot or −1, ``segment`` (T,) 0 start
    pose, 1 approach, 2 blasting move, 3 reconfiguration; per disc
    ``ik_residual_mm`` and ``ik_residual_deg`` (0 for closed-form solutions).

    Footprints (exact cone–plane sections, :mod:`planners.blasting.footprint`):
    ``centers`` are their centres; the nozzle axis meets the surface at
    ``aim_points`` (N,3) / ``aim_points_2d``; ``semi_axes`` (N,2) = (a along
    ``major_dir_2d``, b) in metres.  ``coverage_reach``: share of the surface
    discs of the smallest admissible footprint reach without overspray;
    ``coverage_bound``: certified upper bound on coverage within the 0.5 %
    overspray target (computed when coverage < 99 %, see
    :mod:`planners.blasting.bound`).  ``unreached``: disc ids whose pose is
    free but that no certified joint-space path reaches (also in
    ``skipped``); ``motion``: joint planner statistics.
    """

    radius: float
    centers: np.ndarray
    centers_2d: np.ndarray
    radii: np.ndarray
    classes: np.ndarray
    stream_mm: np.ndarray
    tilt_deg: np.ndarray
    order: np.ndarray
    skipped: np.ndarray
    distance_m: float
    turns: int
    objective: float
    lower_bound_m: float
    mst_m: float
    coverage: float
    overspray: float
    coverage_planned: float
    overspray_planned: float
    lattice_centers_2d: np.ndarray
    lattice_classes: np.ndarray
    spacing_m: float
    params: dict[str, Any] = field(default_factory=dict)
    timings_s: dict[str, float] = field(default_factory=dict)
    joint_trajectory: np.ndarray | None = None
    times: np.ndarray | None = None
    clearance: np.ndarray | None = None
    waypoint_spot: np.ndarray | None = None
    segment: np.ndarray | None = None
    ik_residual_mm: np.ndarray | None = None
    ik_residual_deg: np.ndarray | None = None
    joint_limits: np.ndarray | None = None
    speed_limit_rad_s: float | None = None
    aim_points: np.ndarray | None = None
    aim_points_2d: np.ndarray | None = None
    semi_axes: np.ndarray | None = None
    major_dir_2d: np.ndarray | None = None
    coverage_reach: float | None = None
    coverage_bound: float | None = None
    min_radius_m: float | None = None
    unreached: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    motion: dict[str, int] = field(default_factory=dict)

    def robot_motion(self) -> RobotMotion | None:
        """The trajectory fields narrowed to arrays, or ``None`` without a robot.

        ``_attach_trajectory`` sets them all together, so ``joint_trajectory``
        being set implies every other one is; a partial set is a bug."""
        if self.joint_trajectory is None:
            return None
        assert (
            self.times is not None
            and self.clearance is not None
            and self.waypoint_spot is not None
            and self.segment is not None
            and self.ik_residual_mm is not None
            and self.ik_residual_deg is not None
            and self.joint_limits is not None
            and self.speed_limit_rad_s is not None
        ), "BlastPlan: joint_trajectory set without the other trajectory fields"
        return RobotMotion(
            joint_trajectory=self.joint_trajectory,
            times=self.times,
            clearance=self.clearance,
            waypoint_spot=self.waypoint_spot,
            segment=self.segment,
            ik_residual_mm=self.ik_residual_mm,
            ik_residual_deg=self.ik_residual_deg,
            joint_limits=self.joint_limits,
            speed_limit_rad_s=self.speed_limit_rad_s,
        )

    def _coverage_message(self, coverage_min: float) -> str:
        msg = f"coverage {self.coverage:.2%} (min {coverage_min:.0%})"
        if self.coverage < coverage_min:
            extra = _coverage_limit_text(self)
            if extra:
                msg += ": " + extra
        return msg

    @property
    def ratio_to_lower_bound(self) -> float:
        return self.distance_m / self.lower_bound_m if self.lower_bound_m > 0 else 1.0

    @property
    def max_joint_speed_rad_s(self) -> float:
        m = self.robot_motion()
        if m is None or len(m.times) < 2:
            return 0.0
        dt = np.diff(m.times)
        dq = np.abs(np.diff(m.joint_trajectory, axis=0)).max(axis=1)
        v = np.where(dt > 0, dq / np.where(dt > 0, dt, 1.0), np.where(dq > 0, np.inf, 0.0))
        return float(v.max())

    @property
    def min_clearance_m(self) -> float:
        return (
            float(np.min(self.clearance))
            if self.clearance is not None and len(self.clearance)
            else np.inf
        )

    @property
    def within_joint_limits(self) -> bool:
        m = self.robot_motion()
        if m is None:
            return True
        lo, hi = m.joint_limits[:, 0], m.joint_limits[:, 1]
        q = m.joint_trajectory
        return bool(np.all(q >= lo - 1e-9) and np.all(q <= hi + 1e-9))

    def checks(
        self,
        *,
        coverage_min: float = 0.99,
        overspray_max: float = 0.005,
        residual_max_mm: float = 0.1,
    ) -> list[dict[str, Any]]:
        """Plan checks (DESIGN §4) as dicts: name, passed, value, limit, message."""
        out = [
            _check("coverage", self.coverage >= coverage_min, self.coverage, coverage_min,
                   self._coverage_message(coverage_min)),
            _check("overspray", self.overspray <= overspray_max, self.overspray, overspray_max,
                   f"overspray {self.overspray:.3%} of the surface (max {overspray_max:.1%})"),
        ]  # fmt: skip
        m = self.robot_motion()
        if m is not None:
            v = self.max_joint_speed_rad_s
            vmax = m.speed_limit_rad_s
            res = float(np.max(m.ik_residual_mm)) if len(m.ik_residual_mm) else 0.0
            out += [
                _check("joint_limits", self.within_joint_limits, self.within_joint_limits, True,
                       "all way-points inside the joint limits" if self.within_joint_limits
                       else "a way-point leaves the joint limits"),
                _check("joint_speed", v <= vmax * (1 + 1e-9), np.degrees(v), np.degrees(vmax),
                       f"max joint speed {np.degrees(v):.2f}°/s (limit {np.degrees(vmax):.0f}°/s)"),
                _check("clearance", self.min_clearance_m > 0, self.min_clearance_m, 0.0,
                       f"min ellipsoid clearance {self.min_clearance_m * 1000:.1f} mm"),
                _check("ik_residual", res <= residual_max_mm, res, residual_max_mm,
                       f"max IK position residual {res:.4f} mm"),
                _check("skipped_spots", len(self.skipped) == 0, len(self.skipped), 0,
                       f"{len(self.skipped)} discs unreachable without collision"),
            ]  # fmt: skip
        return out


def _coverage_limit_text(plan: BlastPlan) -> str:
    parts = []
    if plan.min_radius_m is not None and plan.coverage_reach is not None:
        parts.append(
            f"without overspray footprints ≥ Ø{2000 * plan.min_radius_m:.1f} mm (shortest stream) "
            f"reach {plan.coverage_reach:.2%} of the surface"
        )
    if plan.coverage_bound is not None:
        parts.append(
            f"certified: at most {plan.coverage_bound:.2%} is reachable within "
            f"{OVERSPRAY_TARGET:.1%} overspray (pointwise bound)"
        )
    if len(plan.skipped):
        parts.append(f"{len(plan.skipped)} discs skipped (no collision-free pose or path)")
    return "; ".join(parts)


def _check(name: str, passed: bool, value: Any, limit: Any, message: str) -> dict[str, Any]:
    v = (
        float(value)
        if isinstance(value, (int, float, np.floating, np.integer)) and not isinstance(value, bool)
        else value
    )
    return {"name": name, "passed": bool(passed), "value": v, "limit": limit, "message": message}
