"""Plain parameters of the box-girder climber that the planners need.

Built from the robot description's ``params.toml`` (``robots.load_robot
("sbg_climber").params``) or used with its defaults, which are the same
numbers.  Everything is in SI units (metres, radians, seconds).  Seed 003
symbols are kept: ``R``, ``B``, ``larm``, ``l0``, ``dg`` (Eq. 1–2, 9, 11) and
``a``, ``b``, ``c``, ``n`` (Eq. 5, Fig. 7).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from typing import Any

from planners.errors import InvalidInputError


@dataclass(frozen=True)
class CameraParams:
    """Pinhole camera on the mast: position in the robot frame (x forward,
    height above the wall), tilt of the optical axis toward the wall, fields
    of view."""

    x_m: float = 0.060
    height_m: float = 0.240
    tilt_rad: float = math.radians(40.0)
    hfov_rad: float = math.radians(70.0)
    vfov_rad: float = math.radians(40.0)


@dataclass(frozen=True)
class ClimberParams:
    """Dimensions and limits of the climber (defaults = ``params.toml``)."""

    length_m: float = 0.230  # seed §2; n of Eq. 5
    width_m: float = 0.210  # seed §2
    height_m: float = 0.256  # seed §2
    wheel_radius_m: float = 0.030  # R
    wheel_width_m: float = 0.025
    track_m: float = 0.180  # B
    wheelbase_m: float = 0.170  # front to rear axle
    max_speed_m_s: float = 0.020  # seed Eq. 4 cap
    accel_m_s2: float = 0.020
    turn_speed_m_s: float = 0.020  # ωB/2 of Eq. 9
    arm_length_m: float = 0.090  # larm
    arm_l0_m: float = 0.100  # l0
    arm_dg_m: float = 0.060  # dg
    arm_stowed_rad: float = math.radians(90.0)
    arm_min_rad: float = 0.0
    arm_max_rad: float = math.radians(100.0)
    servo_speed_rad_s: float = math.radians(30.0)
    lift_time_s: float = 8.0
    rf_a_m: float = 0.115  # a
    rf_b_m: float = 0.150  # b
    rf_c_m: float = 0.190  # c
    rf_height_m: float = 0.070
    rf_side_m: float = 0.105
    l1_x_m: float = 0.095
    touch_gap_m: float = 0.020
    camera: CameraParams = field(default_factory=CameraParams)

    @property
    def rf_n_m(self) -> float:
        """n of Eq. 5: the robot length."""
        return self.length_m

    @property
    def half_diagonal_m(self) -> float:
        """Radius of the circle the footprint sweeps in an in-place turn."""
        return math.hypot(self.length_m / 2.0, self.width_m / 2.0)

    def sensor_x(self) -> tuple[float, float, float]:
        """Body x of l2, l3, l4 (Fig. 7): l3 is c behind the front, l2 is b
        ahead of l3, l4 is a behind the front; the front is at n/2."""
        front = self.length_m / 2.0
        x3 = front - self.rf_c_m
        return x3 + self.rf_b_m, x3, front - self.rf_a_m

    def validate(self) -> ClimberParams:
        """Raise :class:`InvalidInputError` naming the first bad value."""
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, float) and not math.isfinite(v):
                raise InvalidInputError(f"robot.{f.name} must be finite, got {v}")
        positive = [
            "length_m",
            "width_m",
            "wheel_radius_m",
            "track_m",
            "wheelbase_m",
            "max_speed_m_s",
            "accel_m_s2",
            "turn_speed_m_s",
            "arm_length_m",
            "arm_l0_m",
            "arm_dg_m",
            "servo_speed_rad_s",
            "lift_time_s",
            "rf_b_m",
        ]
        for name in positive:
            if getattr(self, name) <= 0:
                raise InvalidInputError(f"robot.{name} must be > 0, got {getattr(self, name)}")
        if self.wheelbase_m + 2 * self.wheel_radius_m > self.length_m + 1e-9:
            raise InvalidInputError(
                f"robot wheelbase_m + 2·wheel_radius_m = "
                f"{self.wheelbase_m + 2 * self.wheel_radius_m:.4f} m exceeds length_m {self.length_m}"
            )
        R, larm, dg, l0 = self.wheel_radius_m, self.arm_length_m, self.arm_dg_m, self.arm_l0_m
        ab = math.hypot(l0, dg - R)
        if not dg < larm <= R + ab:
            raise InvalidInputError(
                f"robot.arm_length_m {larm} must lie in (dg, R + |AB|] = ({dg}, {R + ab:.4f}] "
                "so the arm reaches the wall and Eq. 1's arcsin is defined"
            )
        if larm >= math.hypot(l0, dg):
            raise InvalidInputError(
                f"robot.arm_length_m {larm} must be < sqrt(l0² + dg²) = {math.hypot(l0, dg):.4f} m "
                "so the pitch grows monotonically while the arm lifts"
            )
        return self

    @classmethod
    def from_params(cls, params: dict[str, Any]) -> ClimberParams:
        """From the ``params.toml`` dictionary (mm, degrees)."""
        try:
            body, wh, arm = params["body"], params["wheels"], params["lift_arm"]
            rf, cam = params["rangefinders"], params["camera"]
            mm, deg = 1e-3, math.radians(1.0)
            return cls(
                length_m=body["length_mm"] * mm,
                width_m=body["width_mm"] * mm,
                height_m=body["height_mm"] * mm,
                wheel_radius_m=wh["radius_mm"] * mm,
                wheel_width_m=wh["width_mm"] * mm,
                track_m=wh["track_mm"] * mm,
                wheelbase_m=wh["wheelbase_mm"] * mm,
                max_speed_m_s=wh["max_speed_mm_s"] * mm,
                accel_m_s2=wh["accel_mm_s2"] * mm,
                turn_speed_m_s=wh["turn_speed_mm_s"] * mm,
                arm_length_m=arm["length_mm"] * mm,
                arm_l0_m=arm["pivot_l0_mm"] * mm,
                arm_dg_m=arm["pivot_dg_mm"] * mm,
                arm_stowed_rad=arm["stowed_deg"] * deg,
                arm_min_rad=arm["limit_min_deg"] * deg,
                arm_max_rad=arm["limit_max_deg"] * deg,
                servo_speed_rad_s=arm["servo_speed_deg_s"] * deg,
                lift_time_s=float(arm["lift_time_s"]),
                rf_a_m=rf["a_mm"] * mm,
                rf_b_m=rf["b_mm"] * mm,
                rf_c_m=rf["c_mm"] * mm,
                rf_height_m=rf["height_mm"] * mm,
                rf_side_m=rf["side_offset_mm"] * mm,
                l1_x_m=rf["l1_x_mm"] * mm,
                touch_gap_m=rf["touch_gap_mm"] * mm,
                camera=CameraParams(
                    x_m=cam["x_mm"] * mm,
                    height_m=cam["height_mm"] * mm,
                    tilt_rad=cam["tilt_deg"] * deg,
                    hfov_rad=cam["hfov_deg"] * deg,
                    vfov_rad=cam["vfov_deg"] * deg,
                ),
            ).validate()
        except KeyError as exc:
            raise InvalidInputError(
                f"robot params lack {exc}; see robots/sbg_climber/params.toml"
            ) from exc

    @classmethod
    def coerce(cls, robot: Any) -> ClimberParams:
        """Accept ``None`` (defaults), a :class:`ClimberParams`, a params dict
        or any object with a ``params`` dict (a ``RobotModel``)."""
        if robot is None:
            return cls().validate()
        if isinstance(robot, ClimberParams):
            return robot.validate()
        if isinstance(robot, dict):
            return cls.from_params(robot)
        params = getattr(robot, "params", None)
        if isinstance(params, dict):
            return cls.from_params(params)
        raise InvalidInputError(
            f"robot must be None, ClimberParams, a params dict or a RobotModel, got {type(robot).__name__}"
        )

    def with_(self, **changes: Any) -> ClimberParams:
        """A copy with some fields changed (validated)."""
        return replace(self, **changes).validate()
