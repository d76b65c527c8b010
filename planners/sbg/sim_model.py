"""Types and helpers of the climber simulator (:mod:`planners.sbg.simulator`):
mode codes, the noise model and controller settings, per-lane / corner /
U-turn results, :class:`SimResult`, buffered normal draws, the rib
clearance of Table 1 and the corner-exit geometry (Eq. 1–4).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import numpy as np

from planners.errors import InvalidInputError
from planners.sbg import corner as corner_mod
from planners.sbg.girder import Girder
from planners.sbg.path import (
    CornerGeom,
)
from planners.sbg.robot import ClimberParams

DEG = math.pi / 180.0
# Mode codes recorded per sample.
STRAIGHT, ARC, ROTATE, CORNER, LINE, SPIN = 0, 1, 2, 3, 4, 5
MODE_NAMES = ("straight", "arc", "rotate", "corner", "uturn_line", "uturn_turn")
DR_YAW_MODES = ("imu_turns", "encoder", "imu")


@dataclass(frozen=True)
class NoiseModel:
    """Sensor and plant errors (all chosen; the seed states none).

    Range finders: white noise per reading (laser-triangulation class) and an
    optional sinusoidal waviness of the rib webs.  Wheels: per-wheel constant
    gain error and white speed noise.  Encoders: a common scale
    (wheel-radius) error, a left/right differential scale error as left after
    calibrating the ratio on a straight lane drive (trilateration measures
    the heading drift it causes: 5e-5 of differential scale turns the robot
    0.016°/m), and quantisation of the cumulative count.  Skid steering:
    a fraction ``turn_slip`` of the turning motion is lost (mean, per-run
    spread and per-sample jitter) and the turn centre sits off Oc by a
    per-run offset.  Gyro (an ADIS16470-class MEMS after a standstill bias
    calibration): residual bias, bias random walk, angle random walk, scale
    error.  Corners: lateral shift and yaw kick across each crossing.
    Initial pose error on the first lane.
    """

    range_sigma_mm: float = 0.1
    wall_waviness_mm: float = 0.0
    wall_wavelength_m: float = 0.5
    wheel_gain_sigma: float = 0.002
    wheel_speed_sigma: float = 0.01
    encoder_scale_sigma: float = 1e-3
    encoder_differential_sigma: float = 5e-5
    encoder_resolution_mm: float = 0.001
    turn_slip_mean: float = 0.08
    turn_slip_sigma: float = 0.03
    turn_slip_jitter: float = 0.02
    turn_centre_sigma_mm: float = 2.0
    gyro_bias_dps: float = 0.001
    gyro_bias_walk_dps_rts: float = 1e-4
    gyro_arw_deg_rts: float = 0.0057
    gyro_scale_sigma: float = 2e-4
    corner_lateral_sigma_mm: float = 0.5
    corner_yaw_sigma_deg: float = 0.05
    init_d_sigma_mm: float = 5.0
    init_delta_sigma_deg: float = 1.0

    @classmethod
    def none(cls) -> NoiseModel:
        """Every error zero (for checking the controllers' geometry)."""
        return cls(**{f.name: 0.0 for f in fields(cls) if f.name != "wall_wavelength_m"})

    def validate(self) -> NoiseModel:
        for f in fields(self):
            v = getattr(self, f.name)
            if not isinstance(v, int | float) or not math.isfinite(v) or v < 0:
                raise InvalidInputError(f"noise.{f.name} must be a finite number ≥ 0, got {v!r}")
        if self.wall_wavelength_m <= 0:
            raise InvalidInputError("noise.wall_wavelength_m must be > 0")
        if self.turn_slip_mean >= 0.9:
            raise InvalidInputError("noise.turn_slip_mean must be < 0.9")
        return self


@dataclass(frozen=True)
class ControllerConfig:
    """Controller settings.  ``preview_m`` is Lx (seed: 20 mm); the dead band
    (``d_tol_m``, ``delta_tol_rad``) and the averaging window are chosen.

    Yaw cap (chosen extension): when the Lx arc would arrive at P turned
    more than the cap, the episode uses the smallest longer preview distance
    that does not (and first turns in place to δ = 0 if |δ| already exceeds
    it), so a large entry error is corrected without swinging the camera off
    the welds.  The cap is the smaller of ``max_yaw_rad`` and, with
    ``camera_yaw_cap``, the largest yaw that keeps both welds
    ``camera_safety_m`` inside the view at P
    (:func:`planners.sbg.camera.max_yaw_for_margin`).  ``camera_yaw_cap=False``
    with ``max_yaw_rad=None`` is the seed's law as printed."""

    preview_m: float = 0.020
    dt_s: float = 0.05
    window: int = 10
    d_tol_m: float = 0.15e-3
    delta_tol_rad: float = 0.025 * DEG
    rot_tol_rad: float = 0.005 * DEG
    heading_gain_1_s: float = 1.0
    line_gain_1_s: float = 0.5
    line_lookahead_m: float = 0.05
    touch_margin_m: float = 0.5e-3
    end_margin_m: float = 0.010
    camera_yaw_cap: bool = True
    camera_safety_m: float = 0.005
    max_yaw_rad: float | None = None
    dr_yaw: str = "imu_turns"
    corner_profile: str = corner_mod.SMOOTH
    max_segment_s: float = 3000.0

    def validate(self) -> ControllerConfig:
        if not math.isfinite(self.preview_m) or self.preview_m < 0:
            raise InvalidInputError(f"preview_m (Lx) must be ≥ 0, got {self.preview_m}")
        if not 0 < self.dt_s <= 0.5:
            raise InvalidInputError(f"dt_s must be in (0, 0.5], got {self.dt_s}")
        if int(self.window) != self.window or self.window < 1:
            raise InvalidInputError(f"window must be an integer ≥ 1, got {self.window}")
        for name in (
            "d_tol_m",
            "delta_tol_rad",
            "rot_tol_rad",
            "heading_gain_1_s",
            "line_gain_1_s",
            "line_lookahead_m",
        ):
            v = getattr(self, name)
            if not math.isfinite(v) or v <= 0:
                raise InvalidInputError(f"{name} must be > 0, got {v}")
        if self.camera_safety_m < 0 or not math.isfinite(self.camera_safety_m):
            raise InvalidInputError(f"camera_safety_m must be ≥ 0, got {self.camera_safety_m}")
        if self.max_yaw_rad is not None and not 0 < self.max_yaw_rad < math.pi / 2:
            raise InvalidInputError(
                f"max_yaw_rad must be in (0, π/2) or None, got {self.max_yaw_rad}"
            )
        if self.dr_yaw not in DR_YAW_MODES:
            raise InvalidInputError(f"dr_yaw must be one of {DR_YAW_MODES}, got {self.dr_yaw!r}")
        if self.corner_profile not in corner_mod.PROFILES:
            raise InvalidInputError(
                f"corner_profile must be one of {corner_mod.PROFILES}, got {self.corner_profile!r}"
            )
        return self


@dataclass
class LaneResult:
    """One lane: final true errors at the crossbeam, worst camera margin,
    fraction of each weld line seen, largest |d|, smallest clearance between
    a wheel and a rib web, covered end to end."""

    lane: int
    segment: int
    length_m: float
    driven_m: float
    covered: bool
    final_d_m: float
    final_delta_rad: float
    entry_d_m: float
    entry_delta_rad: float
    max_abs_d_m: float
    min_rib_clearance_m: float
    worst_margin_m: float
    weld_seen_fraction: float
    episodes: int
    duration_s: float


@dataclass
class CornerResult:
    """One crossing: direction, Eq. 1's Δθ, duration and pitch smoothness."""

    segment: int
    kind: str
    delta_theta_rad: float
    duration_s: float
    max_rate_jump_deg_s: float
    max_rate_deg_s: float
    max_accel_deg_s2: float
    t_start_s: float


@dataclass
class UTurnResult:
    """One U-turn: true yaw deviation and offset on reaching the roof, the
    dead-reckoned heading error at the end of S3 and the duration."""

    from_lane: int
    to_lane: int
    roof_yaw_rad: float
    roof_d_m: float
    s3_heading_error_rad: float
    duration_s: float


@dataclass
class SimResult:
    """Time series (one row per control sample ``dt_s``) and summaries.

    Arrays: ``t_s``, ``segment`` (index into ``path.segments``), ``mode``
    (:data:`MODE_NAMES`), ``wall`` (0 roof, 1/2 crossbeams, −1 in a corner),
    ``pos`` (T,3) base origin (m), ``quat`` (T,4) body orientation wxyz,
    ``pitch_rad`` (crossing pitch, 0 on a wall), ``d_m``/``delta_rad`` (true
    lane error, NaN off the lanes), ``d_est_m``/``delta_est_rad`` (trilateration,
    NaN when none), ``v_left``/``v_right`` (wheel commands on a wall, m/s),
    ``v_front``/``v_rear`` (corner commands), ``arm_rad``, ``dr`` (T,3) the
    U-turn estimate (X, Z, θ of Eq. 10; NaN elsewhere), ``margin_m`` (camera
    margin on the lanes, NaN elsewhere).
    """

    arrays: dict[str, np.ndarray]
    lanes: list[LaneResult]
    corners: list[CornerResult]
    uturns: list[UTurnResult]
    dt_s: float
    seed: int
    noise: NoiseModel
    config: ControllerConfig
    crossing_pitch: list[np.ndarray] = field(default_factory=list)

    @property
    def duration_s(self) -> float:
        return (
            float(self.arrays["t_s"][-1] - self.arrays["t_s"][0])
            if len(self.arrays["t_s"])
            else 0.0
        )


class _Gauss:
    """Buffered standard normals (scalar draws are slow one by one)."""

    def __init__(self, rng: np.random.Generator, size: int = 8192) -> None:
        self.rng, self.size = rng, size
        self.buf = rng.standard_normal(size).tolist()
        self.i = 0

    def __call__(self) -> float:
        if self.i >= self.size:
            self.buf = self.rng.standard_normal(self.size).tolist()
            self.i = 0
        v = self.buf[self.i]
        self.i += 1
        return v


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


_NCOL = 22


def rib_clearance(
    d: np.ndarray, delta: np.ndarray, girder: Girder, robot: ClimberParams
) -> np.ndarray:
    """Smallest lateral gap (m) between the wheels' outer extremes (front and
    back of each wheel, at wheel-centre height R) and the rib webs at that
    height, for robots at ``(d, δ)`` on a lane; negative means contact."""
    d = np.asarray(d, dtype=float)[..., None]
    de = np.asarray(delta, dtype=float)[..., None]
    xs = np.array([1.0, 1.0, -1.0, -1.0]) * (robot.wheelbase_m / 2.0 + robot.wheel_radius_m)
    ys = np.array([1.0, -1.0, 1.0, -1.0]) * (robot.track_m / 2.0 + robot.wheel_width_m / 2.0)
    lateral = -d + xs * np.sin(de) + ys * np.cos(de)
    hw = float(girder.lane_half_width(robot.wheel_radius_m))
    return hw - np.max(np.abs(lateral), axis=-1)


def _corner_exit(
    geom: CornerGeom, lateral: float, skew: float, half: float
) -> tuple[np.ndarray, np.ndarray]:
    """Pose on the new wall after a crossing: base origin ``half`` from the
    corner, heading away from it turned by ``skew`` toward the corner line."""
    p = geom.point + lateral * geom.line_dir + half * geom.n_old
    h = math.cos(skew) * geom.n_old + math.sin(skew) * geom.line_dir
    return p, h


def _union_length(lo: np.ndarray, hi: np.ndarray) -> float:
    """Total length of the union of intervals [lo, hi] (vectorised)."""
    keep = hi > lo
    lo, hi = lo[keep], hi[keep]
    if lo.size == 0:
        return 0.0
    order = np.argsort(lo)
    lo, hi = lo[order], hi[order]
    reach = np.maximum.accumulate(hi)
    starts = np.r_[True, lo[1:] > reach[:-1]]
    seg_id = np.cumsum(starts) - 1
    seg_lo = lo[starts]
    seg_hi = np.zeros(seg_lo.size)
    np.maximum.at(seg_hi, seg_id, hi)
    return float(np.sum(seg_hi - seg_lo))


def _rot_to_quat(R: np.ndarray) -> np.ndarray:
    """(T,3,3) rotation matrices → (T,4) quaternions wxyz (w ≥ 0)."""
    m = R
    tr = m[:, 0, 0] + m[:, 1, 1] + m[:, 2, 2]
    cand = np.stack(
        [
            1.0 + tr,
            1.0 + m[:, 0, 0] - m[:, 1, 1] - m[:, 2, 2],
            1.0 - m[:, 0, 0] + m[:, 1, 1] - m[:, 2, 2],
            1.0 - m[:, 0, 0] - m[:, 1, 1] + m[:, 2, 2],
        ],
        axis=1,
    )
    k = np.argmax(cand, axis=1)
    q = np.zeros((len(m), 4))
    s = np.sqrt(np.maximum(cand[np.arange(len(m)), k], 1e-300)) * 2.0
    i = k == 0
    q[i] = np.stack(
        [
            s[i] / 4,
            (m[i, 2, 1] - m[i, 1, 2]) / s[i],
            (m[i, 0, 2] - m[i, 2, 0]) / s[i],
            (m[i, 1, 0] - m[i, 0, 1]) / s[i],
        ],
        1,
    )
    i = k == 1
    q[i] = np.stack(
        [
            (m[i, 2, 1] - m[i, 1, 2]) / s[i],
            s[i] / 4,
            (m[i, 0, 1] + m[i, 1, 0]) / s[i],
            (m[i, 0, 2] + m[i, 2, 0]) / s[i],
        ],
        1,
    )
    i = k == 2
    q[i] = np.stack(
        [
            (m[i, 0, 2] - m[i, 2, 0]) / s[i],
            (m[i, 0, 1] + m[i, 1, 0]) / s[i],
            s[i] / 4,
            (m[i, 1, 2] + m[i, 2, 1]) / s[i],
        ],
        1,
    )
    i = k == 3
    q[i] = np.stack(
        [
            (m[i, 1, 0] - m[i, 0, 1]) / s[i],
            (m[i, 0, 2] + m[i, 2, 0]) / s[i],
            (m[i, 1, 2] + m[i, 2, 1]) / s[i],
            s[i] / 4,
        ],
        1,
    )
    q *= np.where(q[:, :1] < 0, -1.0, 1.0)
    return q / np.linalg.norm(q, axis=1, keepdims=True)
