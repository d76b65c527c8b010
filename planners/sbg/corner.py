"""Crossing a 90° concave corner (seed §3.1, Fig. 5–6, Eq. 1–4).

Side view of one crossing, in the *corner frame*: ``s`` along the old wall
toward the corner (the new wall is the plane ``s = 0``), ``h`` the height
above the old wall.  The rear-wheel centre B stays on the old wall
(``h = R``) and, once lifted, the front-wheel centre F stays on the new wall
(``s = −R``); with pitch θ between the body and the old wall and wheelbase
``L``::

    F = (−R, R + L sin θ),  B = (−R − L cos θ, R)

so the front wheel rolls along the new wall at ``v1 = L cos θ·θ'`` and the
rear along the old wall at ``v2 = L sin θ·θ'``: ``v2 = v1 tan θ`` (Eq. 3).

Stages: (1) drive until the front wheel touches the new wall; (2) the
lifting arm (pivot A, ``l0`` ahead of B, ``dg`` above the wall) pushes on the
old wall and pitches the body by Eq. 1; (3) the wheels drive with Eq. 4 until
θ = 90° while the arm folds back.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import overload

import numpy as np

from planners.errors import InvalidInputError
from planners.sbg.robot import ClimberParams

PRINTED, SMOOTH = "printed", "smooth"
PROFILES = (PRINTED, SMOOTH)
STAGE_REACH, STAGE_LIFT, STAGE_CLIMB, STAGE_SETTLE = 0, 1, 2, 3


def ab_length(l0: float, dg: float, R: float) -> float:
    """|AB| = sqrt(l0² + (dg − R)²) (Eq. 2)."""
    return math.hypot(l0, dg - R)


def pitch_change(larm: float, l0: float, dg: float, R: float) -> tuple[float, float, float]:
    """Pitch gained by the lifting arm, ``(Δθ, θ1, θ2)`` in rad (Eq. 1).

    θ1 = arctan((dg − R)/l0) is the angle of AB to the wall before lifting,
    θ2 = arcsin((larm − R)/|AB|) once the arm stands perpendicular to it.
    """
    ab = ab_length(l0, dg, R)
    ratio = (larm - R) / ab
    if not -1.0 <= ratio <= 1.0:
        raise InvalidInputError(
            f"(larm − R)/|AB| = {ratio:.4f} is outside [−1, 1]: the arm cannot stand perpendicular"
        )
    theta1 = math.atan((dg - R) / l0)
    theta2 = math.asin(ratio)
    return theta2 - theta1, theta1, theta2


def wheel_speeds(theta: np.ndarray | float, v_max: float = 0.020) -> tuple[np.ndarray, np.ndarray]:
    """Front and rear wheel speeds ``(v1, v2)`` at pitch θ (Eq. 4).

    θ ∈ (0, π/4]: v1 = v_max, v2 = v1 tan θ; θ ∈ [π/4, π/2): v2 = v_max,
    v1 = v2 / tan θ; θ ∈ {0, π/2}: both v_max.  The seed's cap is 20 mm/s.
    """
    th = np.asarray(theta, dtype=float)
    if np.any((th < 0) | (th > math.pi / 2 + 1e-12)):
        raise InvalidInputError("Eq. 4 needs pitch θ in [0, π/2]")
    t = np.tan(np.clip(th, 1e-12, math.pi / 2 - 1e-12))
    low = th <= math.pi / 4
    v1 = np.where(low, v_max, v_max / t)
    v2 = np.where(low, v_max * t, v_max)
    ends = (th <= 0.0) | (th >= math.pi / 2)
    v1 = np.where(ends, v_max, v1)
    v2 = np.where(ends, v_max, v2)
    return v1, v2


def pitch_rate(
    theta: np.ndarray | float, v1: np.ndarray | float, v2: np.ndarray | float, L: float
) -> np.ndarray:
    """θ' from the two wheel speeds: least-squares solution of
    ``v1 = L cos θ θ'`` and ``v2 = L sin θ θ'`` (exact when Eq. 3 holds;
    with noisy wheels it is the motion that slips least)."""
    th = np.asarray(theta, dtype=float)
    return (np.asarray(v1) * np.cos(th) + np.asarray(v2) * np.sin(th)) / L


def wheel_centres(theta: np.ndarray | float, L: float, R: float) -> tuple[np.ndarray, np.ndarray]:
    """Front and rear wheel centres ``(F, B)`` (…,2) in the corner frame."""
    th = np.asarray(theta, dtype=float)
    F = np.stack([np.full_like(th, -R), R + L * np.sin(th)], axis=-1)
    B = np.stack([-R - L * np.cos(th), np.full_like(th, R)], axis=-1)
    return F, B


def base_pose(
    theta: np.ndarray | float, L: float, R: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Robot base frame during the crossing, in the corner frame: origin
    (…,2) = wheel-centre midpoint moved R down the body z axis (on the wall
    when θ is 0 or 90°), body x and body z axes (…,2)."""
    th = np.asarray(theta, dtype=float)
    F, B = wheel_centres(th, L, R)
    x_axis = np.stack([np.cos(th), np.sin(th)], axis=-1)
    z_axis = np.stack([-np.sin(th), np.cos(th)], axis=-1)
    return 0.5 * (F + B) - R * z_axis, x_axis, z_axis


def pivot_height(theta: np.ndarray | float, robot: ClimberParams) -> np.ndarray:
    """Height of the arm pivot A above the old wall: R + |AB| sin(θ1 + θ)."""
    R, l0, dg = robot.wheel_radius_m, robot.arm_l0_m, robot.arm_dg_m
    theta1 = math.atan((dg - R) / l0)
    return R + ab_length(l0, dg, R) * np.sin(theta1 + np.asarray(theta, dtype=float))


def arm_angle_for_pitch(theta: np.ndarray | float, robot: ClimberParams) -> np.ndarray:
    """Arm angle q (body frame, 0 = pointing at the wall, + folds backward)
    whose tip touches the old wall at pitch θ: ``h_A(θ) = larm cos(q − θ)``.
    At θ = Δθ (Eq. 1) the arm is perpendicular to the wall: q = θ."""
    hA = pivot_height(theta, robot)
    ratio = np.clip(hA / robot.arm_length_m, -1.0, 1.0)
    return np.asarray(theta, dtype=float) + np.arccos(ratio)


class ArmPitchMap:
    """Monotone map between arm angle and pitch over the lift (tabulated)."""

    def __init__(self, robot: ClimberParams, n: int = 2001) -> None:
        dtheta, _, _ = pitch_change(
            robot.arm_length_m, robot.arm_l0_m, robot.arm_dg_m, robot.wheel_radius_m
        )
        self.delta_theta = dtheta
        self.theta = np.linspace(0.0, dtheta, n)
        self.q = arm_angle_for_pitch(self.theta, robot)
        if np.any(np.diff(self.q) >= 0):
            raise InvalidInputError(
                "arm angle must decrease monotonically while lifting; check larm, l0, dg"
            )
        self.q_contact = float(self.q[0])
        self.q_top = float(self.q[-1])
        #: Largest |dθ/dq| over the stroke (the lift's gear ratio to pitch).
        self.max_gain = float(np.max(np.abs(np.diff(self.theta) / np.diff(self.q))))

    @overload
    def pitch(self, q: np.ndarray) -> np.ndarray: ...
    @overload
    def pitch(self, q: float) -> float: ...
    def pitch(self, q: np.ndarray | float) -> np.ndarray | float:
        """Pitch for arm angle q (0 above the contact angle, Δθ at the top)."""
        return np.interp(q, self.q[::-1], self.theta[::-1], left=self.delta_theta, right=0.0)


def min_jerk(tau: np.ndarray | float) -> np.ndarray:
    """Minimum-jerk blend 10τ³ − 15τ⁴ + 6τ⁵ on [0, 1] (zero rate and
    acceleration at both ends)."""
    t = np.clip(np.asarray(tau, dtype=float), 0.0, 1.0)
    return t**3 * (10.0 - 15.0 * t + 6.0 * t * t)


@dataclass
class CrossingRecord:
    """Time series of one crossing (dt spaced): time, pitch θ (rad), commanded
    front/rear wheel speeds v1/v2 (m/s), arm angle q (rad), stage code."""

    t: np.ndarray
    theta: np.ndarray
    v1: np.ndarray
    v2: np.ndarray
    arm: np.ndarray
    stage: np.ndarray
    delta_theta: float

    @property
    def duration_s(self) -> float:
        return float(self.t[-1] - self.t[0])


def smoothness(theta: np.ndarray, dt: float) -> dict[str, float]:
    """Slope-change measures of a pitch history (Fig. 12's "no abrupt
    change"): largest jump of the pitch rate between consecutive samples
    (deg/s), largest pitch rate (deg/s) and largest pitch acceleration
    (deg/s²), all by finite differences of θ sampled every ``dt``."""
    th = np.asarray(theta, dtype=float)
    if th.size < 3:
        return {"max_rate_jump_deg_s": 0.0, "max_rate_deg_s": 0.0, "max_accel_deg_s2": 0.0}
    rate = np.diff(th) / dt
    jump = np.abs(np.diff(rate))
    return {
        "max_rate_jump_deg_s": float(np.degrees(jump.max())),
        "max_rate_deg_s": float(np.degrees(np.abs(rate).max())),
        "max_accel_deg_s2": float(np.degrees(jump.max() / dt)),
    }


def cross_corner(
    robot: ClimberParams,
    *,
    profile: str = SMOOTH,
    dt: float = 0.05,
    rng: np.random.Generator | None = None,
    wheel_sigma: float = 0.0,
    wheel_gain: tuple[float, float] = (0.0, 0.0),
    taper_rad: float = math.radians(10.0),
    taper_floor: float = 0.1,
    max_time_s: float = 600.0,
    settle_ticks: int = 4,
) -> CrossingRecord:
    """Simulate stages 2–3 of one crossing (Eq. 1–4), from front-wheel touch
    to the whole robot on the new wall.

    ``profile="printed"``: the arm turns at the servo's full speed and the
    wheels follow Eq. 4 as printed (speeds step to the caps).
    ``profile="smooth"`` (chosen extension): a minimum-jerk arm stroke over
    ``robot.lift_time_s``, the Eq. 4 speeds scaled by a common factor that
    ramps up at ``robot.accel_m_s2`` and tapers linearly to ``taper_floor``
    over the last ``taper_rad`` before 90°.  Scaling both wheels by one
    factor keeps the Eq. 3 ratio and stays under the 20 mm/s caps.

    Wheel noise: each wheel's actual speed is the command times
    ``1 + gain + wheel_sigma·N(0,1)``; the pitch follows the actual speeds
    via :func:`pitch_rate`.
    """
    if profile not in PROFILES:
        raise InvalidInputError(f"corner profile must be one of {PROFILES}, got {profile!r}")
    if dt <= 0:
        raise InvalidInputError(f"dt must be > 0, got {dt}")
    amap = ArmPitchMap(robot)
    L, vmax = robot.wheelbase_m, robot.max_speed_m_s
    servo = robot.servo_speed_rad_s
    rows: list[tuple[float, float, float, float, float, int]] = []
    t = 0.0
    q = robot.arm_stowed_rad
    theta = 0.0

    def noisy(v: float, k: int) -> float:
        if rng is None or (wheel_sigma == 0.0 and wheel_gain[k] == 0.0):
            return v
        return v * (1.0 + wheel_gain[k] + wheel_sigma * float(rng.standard_normal()))

    # Stage 2a: swing the arm from stowed down to wall contact (no pitch change).
    rows.append((t, theta, 0.0, 0.0, q, STAGE_REACH))
    while q > amap.q_contact + 1e-12:
        q = max(amap.q_contact, q - servo * dt)
        t += dt
        rows.append((t, theta, 0.0, 0.0, q, STAGE_REACH))
    # Stage 2b: lift.  Pitch follows the arm through the contact geometry; the
    # wheels roll per Eq. 3 so both stay on their walls.
    q0, q1 = amap.q_contact, amap.q_top
    if profile == PRINTED:
        # Constant servo rate, as fast as the servo goes but no faster than
        # keeps the wheels dragged along by the lift (Eq. 3) under the cap.
        rate = min(servo, vmax / (L * amap.max_gain))
        n_lift = max(1, math.ceil((q0 - q1) / (rate * dt)))
        qs = np.maximum(q1, q0 - rate * dt * np.arange(1, n_lift + 1))
    else:
        # Minimum-jerk stroke; stretched if the wheels would exceed the cap.
        T = robot.lift_time_s
        for _ in range(20):
            n_lift = max(1, math.ceil(T / dt))
            qs = q0 + (q1 - q0) * min_jerk(np.arange(1, n_lift + 1) / n_lift)
            th = amap.pitch(np.r_[q0, qs])
            peak = L * float(np.max(np.abs(np.diff(th)))) / dt
            if peak <= vmax:
                break
            T *= 1.02 * peak / vmax
    thetas = amap.pitch(qs)
    prev = theta
    for qk, thk in zip(qs, thetas, strict=True):
        rate = (float(thk) - prev) / dt
        v1, v2 = L * math.cos(thk) * rate, L * math.sin(thk) * rate
        prev = float(thk)
        t += dt
        rows.append((t, prev, v1, v2, float(qk), STAGE_LIFT))
    theta, q = prev, q1
    # Stage 3: Eq. 4 wheel law until the rear wheel reaches the corner (θ = 90°);
    # the arm folds back meanwhile (its tip leaves the wall as θ grows).
    scale = 0.0 if profile == SMOOTH else 1.0
    ramp = robot.accel_m_s2 / vmax * dt
    half_pi = math.pi / 2
    while theta < half_pi - 1e-9:
        if t > max_time_s:
            raise InvalidInputError("corner crossing did not finish; check the robot parameters")
        v1s, v2s = wheel_speeds(theta, vmax)
        v1c, v2c = float(v1s), float(v2s)
        if profile == SMOOTH:
            scale = min(1.0, scale + ramp)
            taper = min(1.0, max(taper_floor, (half_pi - theta) / taper_rad))
            v1c, v2c = v1c * scale * taper, v2c * scale * taper
        v1a, v2a = noisy(v1c, 0), noisy(v2c, 1)
        theta = min(half_pi, theta + float(pitch_rate(theta, v1a, v2a, L)) * dt)
        q = min(robot.arm_stowed_rad, q + servo * dt)
        t += dt
        rows.append((t, theta, v1c, v2c, q, STAGE_CLIMB))
    # A few samples flat on the new wall, so the landing's change of pitch
    # rate (to zero) shows in the record.
    v_land = rows[-1][3]
    for _ in range(settle_ticks):
        q = min(robot.arm_stowed_rad, q + servo * dt)
        t += dt
        rows.append((t, half_pi, v_land, v_land, q, STAGE_SETTLE))
    arr = np.array(rows, dtype=float)
    return CrossingRecord(
        t=arr[:, 0],
        theta=arr[:, 1],
        v1=arr[:, 2],
        v2=arr[:, 3],
        arm=arr[:, 4],
        stage=arr[:, 5].astype(np.int8),
        delta_theta=amap.delta_theta,
    )
