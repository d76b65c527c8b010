"""Closed-loop kinematic simulator of the climber over the whole path.

The controllers of seed §3 run against a noisy plant:

- lanes (§3.2): range finders l2–l4 → trilateration (Eq. 5), averaged over
  a short window while driving straight; when the error leaves a dead band
  the robot drives the preview-follow arc (Eq. 6–7) measured by the
  encoders, then turns in place (Eq. 9) until its IMU-propagated yaw is zero
  (the δ2 of Eq. 8 plus whatever slip added).  Between episodes it holds
  its heading on the encoder yaw.  l1 stops it when the front wheel touches
  the crossbeam.
- corners (§3.1): :func:`planners.sbg.corner.cross_corner` (Eq. 1–4) with
  noisy wheels; the lateral position and yaw carry over with a small
  random disturbance.
- U-turns (§3.3): dead reckoning Eq. 10–11 with encoder distances, heading
  from the IMU during the in-place turns (``dr_yaw="imu_turns"``, the
  seed's choice) or from the encoders throughout (``"encoder"``, the
  baseline) or the IMU throughout (``"imu"``); a line follower keeps the
  estimate on S1, S2, S3; S3 ends when l1 sees the roof.

Plant: each wheel's speed is its command times ``1 + gain + σ·N``; an
in-place turn loses a fraction ``slip`` of its yaw and the robot turns about
an instantaneous centre offset from Oc (skid steering); the encoders read
the wheels' travel with a calibration error; the gyro has bias, bias random
walk, angle random walk and scale error.  All random draws come from one
``numpy.random.Generator`` seeded by ``seed``.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field, fields

import numpy as np

from planners.errors import InfeasibleError, InvalidInputError
from planners.sbg import corner as corner_mod
from planners.sbg.camera import footprint, max_yaw_for_margin, weld_margin
from planners.sbg.girder import ROOF, Girder, WallFrame
from planners.sbg.path import (
    CORNER_DOWN,
    CORNER_UP,
    LANE,
    S1,
    S2,
    S3,
    TURN,
    CornerGeom,
    InspectionPath,
)
from planners.sbg.preview import (
    ArcPlan,
    arc_wheel_speeds,
    plan_arc,
    preview_for_arrival,
    rotation_wheel_speeds,
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


class _Sim:
    """One closed-loop run; see the module docstring."""

    def __init__(
        self,
        path: InspectionPath,
        noise: NoiseModel,
        cfg: ControllerConfig,
        seed: int,
        progress: Callable[[float, str], None] | None,
    ) -> None:
        self.path, self.g, self.r = path, path.girder, path.robot
        self.noise, self.cfg, self.seed = noise, cfg, seed
        self.progress = progress
        self.rng = np.random.default_rng(seed)
        self.gauss = _Gauss(self.rng)
        self.dt = cfg.dt_s
        nz = noise
        g = self.gauss
        # Per-run constants.
        self.gain = (nz.wheel_gain_sigma * g(), nz.wheel_gain_sigma * g())
        common, diff = nz.encoder_scale_sigma * g(), nz.encoder_differential_sigma * g()
        self.enc_scale = (common + diff / 2.0, common - diff / 2.0)
        self.slip = min(0.8, max(0.0, nz.turn_slip_mean + nz.turn_slip_sigma * g()))
        self.icr = (nz.turn_centre_sigma_mm * 1e-3 * g(), nz.turn_centre_sigma_mm * 1e-3 * g())
        self.bias = nz.gyro_bias_dps * DEG * g()
        self.gyro_scale = nz.gyro_scale_sigma * g()
        self.wave_phase = [
            2 * math.pi * float(self.rng.random()) for _ in range(2 * self.g.n_lanes)
        ]
        self.init_d = nz.init_d_sigma_mm * 1e-3 * g()
        self.init_delta = nz.init_delta_sigma_deg * DEG * g()
        # Plant state on the current wall.
        self.t = 0.0
        self.wall = ROOF
        self.frame: WallFrame = self.g.wall(ROOF)
        self.x = self.y = self.phi = 0.0
        self.rows: list[tuple[float, ...]] = []
        self.lanes: list[LaneResult] = []
        self.corners: list[CornerResult] = []
        self.uturns: list[UTurnResult] = []
        self.crossings: list[np.ndarray] = []
        self.x2, self.x3, self.x4 = self.r.sensor_x()
        self.fp = footprint(self.r.camera)
        caps = [] if cfg.max_yaw_rad is None else [cfg.max_yaw_rad]
        if cfg.camera_yaw_cap:
            caps.append(max_yaw_for_margin(self.fp, self.g.lane_width_m / 2.0, cfg.camera_safety_m))
        self.yaw_cap: float | None = min(caps) if caps else None
        self.last_est = (0.0, 0.0)
        self.travel = [0.0, 0.0]
        self.counts = [0.0, 0.0]
        self.uturn_t0 = 0.0
        self.lane_limit_s: float | None = None

    # ------------------------------------------------------------------ plant
    def _step(self, vl: float, vr: float) -> tuple[float, float, float]:
        """Advance the plant by dt under wheel commands; return encoder
        travel (left, right) and the gyro's yaw increment (left +)."""
        nz, g, dt, B = self.noise, self.gauss, self.dt, self.r.track_m
        wl = vl * (1.0 + self.gain[0] + nz.wheel_speed_sigma * g())
        wr = vr * (1.0 + self.gain[1] + nz.wheel_speed_sigma * g())
        v = 0.5 * (wl + wr)
        diff = wr - wl
        den = abs(wl) + abs(wr)
        kappa = abs(diff) / den if den > 1e-15 else 0.0
        slip = min(0.95, max(0.0, self.slip + nz.turn_slip_jitter * g()))
        omega = diff / B * (1.0 - slip * kappa)
        # Skid steering turns about a centre offset from Oc by (x_icr, y_icr):
        # Oc then moves with ω × (Oc − ICR) = ω (y_icr, −x_icr) in the body.
        vxb = v + kappa * omega * self.icr[1]
        vyb = -kappa * omega * self.icr[0]
        pm = self.phi + 0.5 * omega * dt
        c, s = math.cos(pm), math.sin(pm)
        self.x += (vxb * c - vyb * s) * dt
        self.y += (vxb * s + vyb * c) * dt
        self.phi += omega * dt
        # Encoders count the wheels' travel (scaled by the radius error); the
        # count is cumulative, so quantisation does not accumulate.
        self.travel[0] += wl * dt * (1.0 + self.enc_scale[0])
        self.travel[1] += wr * dt * (1.0 + self.enc_scale[1])
        res = nz.encoder_resolution_mm * 1e-3
        if res > 0:
            cl, cr = math.floor(self.travel[0] / res) * res, math.floor(self.travel[1] / res) * res
        else:
            cl, cr = self.travel
        enc_l, enc_r = cl - self.counts[0], cr - self.counts[1]
        self.counts = [cl, cr]
        self.bias += nz.gyro_bias_walk_dps_rts * DEG * math.sqrt(dt) * g()
        gyro = (
            omega * (1.0 + self.gyro_scale) + self.bias
        ) * dt + nz.gyro_arw_deg_rts * DEG * math.sqrt(dt) * g()
        self.t += dt
        return enc_l, enc_r, gyro

    def _set_pose_world(self, wall: int, p: np.ndarray, h: np.ndarray) -> None:
        self.wall = wall
        self.frame = self.g.wall(wall)
        x, y = self.frame.to_wall(p)
        self.x, self.y = float(x), float(y)
        self.phi = float(self.frame.heading_angle(h))

    def _pose_world(self) -> tuple[np.ndarray, np.ndarray]:
        return self.frame.to_world(self.x, self.y), self.frame.heading_world(self.phi)

    def _gap_ahead(self, m: tuple[float, float], c0: float, x_s: float) -> tuple[float, float]:
        """Distance along the heading from body x = ``x_s`` to the wall
        ``p·m = c0`` ahead, and the cosine between heading and ``m``."""
        hx, hy = math.cos(self.phi), math.sin(self.phi)
        cos_a = hx * m[0] + hy * m[1]
        if cos_a < 0.2:
            # Turned more than ~78° away from the wall ahead: l1 sees a rib
            # web or nothing, and the front wheel cannot reach that wall.
            return math.inf, cos_a
        px, py = self.x + x_s * hx, self.y + x_s * hy
        return (c0 - (px * m[0] + py * m[1])) / cos_a, cos_a

    def _clip_contact(self, m: tuple[float, float], c0: float) -> None:
        """The front wheel cannot enter the wall ahead."""
        gap, _ = self._gap_ahead(m, c0, self.r.length_m / 2.0)
        if gap < 0:
            self.x += gap * math.cos(self.phi)
            self.y += gap * math.sin(self.phi)

    def _l1(self, m: tuple[float, float], c0: float) -> float:
        gap, _ = self._gap_ahead(m, c0, self.r.l1_x_m)
        return gap + self.noise.range_sigma_mm * 1e-3 * self.gauss()

    def _record(
        self,
        seg: int,
        mode: int,
        kind: int = 0,
        fid: int = 0,
        a: float = 0.0,
        b: float = 0.0,
        c: float = 0.0,
        d: float = math.nan,
        de: float = math.nan,
        de_est: tuple[float, float] = (math.nan, math.nan),
        wheels: tuple[float, float, float, float] = (math.nan, math.nan, math.nan, math.nan),
        arm: float | None = None,
        dr: tuple[float, float, float] = (math.nan, math.nan, math.nan),
        pitch: float = 0.0,
        along: float = math.nan,
    ) -> None:
        self.rows.append(
            (
                self.t,
                seg,
                mode,
                kind,
                fid,
                a,
                b,
                c,
                d,
                de,
                de_est[0],
                de_est[1],
                *wheels,
                self.r.arm_stowed_rad if arm is None else arm,
                *dr,
                pitch,
                along,
            )
        )

    def _tick(self) -> None:
        if self.t - self.seg_t0 > self.cfg.max_segment_s:
            raise InfeasibleError(
                f"segment {self.seg_index} ({self.path.segments[self.seg_index].kind}) did not finish "
                f"within {self.cfg.max_segment_s:.0f} s of simulated time; check the controller settings"
            )

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

    def _run_lane(self, seg_i: int) -> None:
        cfg, r, B = self.cfg, self.r, self.r.track_m
        geo = self._lane_geometry(seg_i)
        m, c0 = (geo["mx"], geo["my"]), geo["c0"]
        vmax = r.max_speed_m_s
        omega_max = 2.0 * r.turn_speed_m_s / B
        window: deque[tuple[float, float]] = deque(maxlen=cfg.window)
        mode = STRAIGHT
        enc_yaw = 0.0
        arc: ArcPlan | None = None
        arc_left = arc_s = arc_psi0 = 0.0
        yaw_est = 0.0
        episodes = 0
        t0 = self.t
        d0, de0 = self._lane_error(geo)
        u0 = self._along(geo)
        touch = r.touch_gap_m + cfg.touch_margin_m
        while True:
            if self.lane_limit_s is not None and self.t - t0 > self.lane_limit_s:
                break  # experiment runs: stop a lane that does not finish
            self._tick()
            d, de = self._lane_error(geo)
            along = self._along(geo)
            l2, l3, l4 = self._ranges(d, de, along, geo["lane"])
            dm, dem = self._trilaterate(l2, l3, l4)
            l1 = self._l1(m, c0)
            est = (math.nan, math.nan)
            if mode in (STRAIGHT, ARC) and l1 <= touch:
                break
            if mode == STRAIGHT:
                window.append((dm, dem))
                if len(window) == cfg.window:
                    n = len(window)
                    de_hat = sum(w[1] for w in window) / n
                    # The window's mean lags by half its length: d' = −v sin δ.
                    d_hat = (
                        sum(w[0] for w in window) / n
                        - vmax * math.sin(de_hat) * (n - 1) * self.dt / 2.0
                    )
                    est = (d_hat, de_hat)
                    self.last_est = est
                    if abs(d_hat) > cfg.d_tol_m or abs(de_hat) > cfg.delta_tol_rad:
                        yaw_est = de_hat
                        episodes += 1
                        window.clear()
                        cap = self.yaw_cap
                        arc, arc_left, mode = None, 0.0, ROTATE
                        if cap is None or abs(de_hat) <= cap:
                            lx = cfg.preview_m
                            if cap is not None:
                                lx = preview_for_arrival(d_hat, de_hat, lx, cap)
                            plan = plan_arc(d_hat, de_hat, lx)
                            # Near the crossbeam an arc that cannot finish
                            # would hand a skewed robot to the corner: only
                            # square up in place there.
                            if (
                                plan.length_m * max(0.0, math.cos(de_hat))
                                < l1 - touch - cfg.end_margin_m
                            ):
                                arc = plan
                                arc_left, arc_s, arc_psi0 = arc.length_m, 0.0, de_hat
                                mode = ARC if arc_left > 0 else ROTATE
                        if mode == ROTATE and abs(yaw_est) <= cfg.rot_tol_rad:
                            mode = STRAIGHT
            if mode == ARC:
                assert arc is not None
                # Done within 10 µm (a few encoder counts): the last steps
                # would otherwise shrink below the encoder resolution.
                if arc_left <= 1e-5:
                    mode = ROTATE
                else:
                    # Drive the arc's curvature and close the loop on the
                    # IMU heading against the planned heading δ + s/Rc, so
                    # wheel errors do not bend a long arc.
                    vl0, vr0 = arc_wheel_speeds(arc.radius_m, vmax, B)
                    v_oc = 0.5 * (vl0 + vr0)
                    psi_plan = arc_psi0 + (
                        arc_s / arc.radius_m if math.isfinite(arc.radius_m) else 0.0
                    )
                    w = (vr0 - vl0) / B + cfg.heading_gain_1_s * _wrap(psi_plan - yaw_est)
                    vl, vr = v_oc - w * B / 2.0, v_oc + w * B / 2.0
                    top = max(abs(vl), abs(vr))
                    if top > vmax:
                        vl, vr, v_oc = vl * vmax / top, vr * vmax / top, v_oc * vmax / top
                    if v_oc * self.dt > arc_left:
                        k = arc_left / (v_oc * self.dt)
                        vl, vr = vl * k, vr * k
            if mode == ROTATE:
                if abs(yaw_est) <= cfg.rot_tol_rad:
                    mode = STRAIGHT
                    enc_yaw = 0.0
                    window.clear()
                else:
                    omega = min(omega_max, abs(yaw_est) / self.dt)
                    vl, vr = rotation_wheel_speeds(yaw_est, omega, B)
            if mode == STRAIGHT:
                # Heading hold on the encoder yaw since the last episode.
                w_cmd = -cfg.heading_gain_1_s * enc_yaw
                vl, vr = vmax - w_cmd * B / 2.0, vmax + w_cmd * B / 2.0
                top = max(abs(vl), abs(vr))
                if top > vmax:
                    vl, vr = vl * vmax / top, vr * vmax / top
            self._record(
                seg_i,
                mode,
                0,
                ROOF,
                self.x,
                self.y,
                self.phi,
                d,
                de,
                est,
                (vl, vr, math.nan, math.nan),
                along=along,
            )
            el, er, gy = self._step(vl, vr)
            self._clip_contact(m, c0)
            enc_yaw += (er - el) / B
            # Between trilateration fixes, carry the estimate forward with the
            # IMU yaw and the encoder distance (used for the U-turn hand-off).
            d_e, de_e = self.last_est
            self.last_est = (d_e - 0.5 * (el + er) * math.sin(de_e + 0.5 * gy), de_e + gy)
            if mode == ARC:
                arc_left -= 0.5 * (el + er)
                arc_s += 0.5 * (el + er)
                yaw_est += gy
            elif mode == ROTATE:
                yaw_est += gy
        # Creep the last fraction of a millimetre to contact (l1 fired early
        # by up to the touch margin plus noise).
        gap, _ = self._gap_ahead(m, c0, r.length_m / 2.0)
        if 0 < gap < 2 * cfg.touch_margin_m + 5 * self.noise.range_sigma_mm * 1e-3:
            self.x += gap * math.cos(self.phi)
            self.y += gap * math.sin(self.phi)
        d, de = self._lane_error(geo)
        along = self._along(geo)
        self._record(seg_i, STRAIGHT, 0, ROOF, self.x, self.y, self.phi, d, de, along=along)
        self.t += self.dt  # the stop takes one sample
        lane_len = self.path.segments[seg_i].length_m
        self.lanes.append(
            LaneResult(
                lane=int(geo["lane"]),
                segment=seg_i,
                length_m=lane_len,
                driven_m=along - u0,
                covered=False,
                final_d_m=d,
                final_delta_rad=de,
                entry_d_m=d0,
                entry_delta_rad=de0,
                max_abs_d_m=math.nan,
                min_rib_clearance_m=math.nan,
                worst_margin_m=math.nan,
                weld_seen_fraction=math.nan,
                episodes=episodes,
                duration_s=self.t - t0,
            )
        )

    # ---------------------------------------------------------------- corners
    def _run_corner(self, seg_i: int) -> None:
        seg = self.path.segments[seg_i]
        geom = seg.corner
        assert geom is not None
        nz, r = self.noise, self.r
        p, h = self._pose_world()
        lateral = float((p - geom.point) @ geom.line_dir)
        a = float(h @ geom.t_old)
        b = float(h @ geom.line_dir)
        skew = math.atan2(b, a)
        rec = corner_mod.cross_corner(
            r,
            profile=self.cfg.corner_profile,
            dt=self.dt,
            rng=self.rng,
            wheel_sigma=nz.wheel_speed_sigma,
            wheel_gain=self.gain,
        )
        t0 = self.t
        for k in range(len(rec.t)):
            self._record(
                seg_i,
                CORNER,
                1,
                seg_i,
                lateral + math.sin(skew) * r.length_m * k / len(rec.t),
                float(rec.theta[k]),
                skew,
                wheels=(math.nan, math.nan, float(rec.v1[k]), float(rec.v2[k])),
                arm=float(rec.arm[k]),
                pitch=float(rec.theta[k]),
            )
            self.t = t0 + float(rec.t[k]) + self.dt
        dur = float(rec.t[-1]) + self.dt
        self.t = t0 + dur
        self.bias += nz.gyro_bias_walk_dps_rts * DEG * math.sqrt(dur) * self.gauss()
        sm = corner_mod.smoothness(rec.theta, self.dt)
        self.corners.append(
            CornerResult(
                segment=seg_i,
                kind=seg.kind,
                delta_theta_rad=rec.delta_theta,
                duration_s=dur,
                max_rate_jump_deg_s=sm["max_rate_jump_deg_s"],
                max_rate_deg_s=sm["max_rate_deg_s"],
                max_accel_deg_s2=sm["max_accel_deg_s2"],
                t_start_s=t0,
            )
        )
        self.crossings.append(rec.theta.copy())
        # Carry the lateral position and the yaw across: the component of the
        # heading along the corner line is kept (it is a concave fold).
        lat_new = (
            lateral + math.sin(skew) * r.length_m + nz.corner_lateral_sigma_mm * 1e-3 * self.gauss()
        )
        skew_new = skew + nz.corner_yaw_sigma_deg * DEG * self.gauss()
        p_new, h_new = _corner_exit(geom, lat_new, skew_new, r.length_m / 2.0)
        self._set_pose_world(geom.to_wall, p_new, h_new)

    # ---------------------------------------------------------------- U-turns
    def _cb_to_eq10(self, x: float, y: float, phi: float) -> tuple[float, float, float]:
        """Crossbeam wall frame → Eq. 10 frame: X = x, Z = y, θ = π/2 − φ."""
        return x, y, math.pi / 2.0 - phi

    def _start_dr(self, lane_seg: int, corner_seg: int) -> tuple[float, float, float]:
        """Initial U-turn estimate: the last trilateration (d̂, δ̂) on the lane,
        placed at the lane end and carried through the same corner geometry
        as the plant (without the random disturbance)."""
        geo = self._lane_geometry(lane_seg)
        seg = self.path.segments[lane_seg]
        d_hat, de_hat = self.last_est
        end = seg.points[-1]
        frame = self.g.wall(ROOF)
        ex, ey = frame.to_wall(end)
        left = (geo["lx"], geo["ly"])
        x = float(ex) - d_hat * left[0]
        y = float(ey) - d_hat * left[1]
        phi = geo["phi"] + de_hat
        p = frame.to_world(x, y)
        h = frame.heading_world(phi)
        geom = self.path.segments[corner_seg].corner
        assert geom is not None
        lateral = float((p - geom.point) @ geom.line_dir)
        skew = math.atan2(float(h @ geom.line_dir), float(h @ geom.t_old))
        p2, h2 = _corner_exit(
            geom, lateral + math.sin(skew) * self.r.length_m, skew, self.r.length_m / 2.0
        )
        cb = self.g.wall(geom.to_wall)
        x2, y2 = cb.to_wall(p2)
        return self._cb_to_eq10(float(x2), float(y2), float(cb.heading_angle(h2)))

    def _run_line(self, seg_i: int, dr: list[float], stop_touch: bool) -> None:
        """Follow S1/S2/S3 on the dead-reckoned pose (Eq. 10–11)."""
        cfg, r, B = self.cfg, self.r, self.r.track_m
        seg = self.path.segments[seg_i]
        cb = self.g.wall(seg.wall)
        sx, sy = cb.to_wall(seg.points[0])
        exx, eyy = cb.to_wall(seg.points[-1])
        sx, sy, exx, eyy = float(sx), float(sy), float(exx), float(eyy)
        length = seg.length_m
        ux, uz = (exx - sx) / length, (eyy - sy) / length
        theta_ref = math.atan2(ux, uz)
        rx, rz = math.cos(theta_ref), -math.sin(theta_ref)  # right of the heading
        vmax = r.max_speed_m_s
        # Wall ahead for S3: the deck, y = 0 in the crossbeam frame.
        m, c0 = (0.0, 1.0), 0.0
        touch = r.touch_gap_m + cfg.touch_margin_m
        omega_max = 2.0 * r.turn_speed_m_s / B
        while True:
            self._tick()
            X, Z, th = dr
            prog = (X - sx) * ux + (Z - sy) * uz
            e_right = (X - sx) * rx + (Z - sy) * rz
            e_th = _wrap(th - theta_ref)
            if stop_touch:
                if self._l1(m, c0) <= touch:
                    break
                v = vmax
            else:
                left = length - prog
                if left <= 1e-5:
                    break
                v = min(vmax, left / self.dt)
            # Turn back toward the line: a positive θ' is a right turn.
            thd = -cfg.line_gain_1_s * (e_th + math.atan2(e_right, cfg.line_lookahead_m))
            thd = max(-omega_max, min(omega_max, thd))
            vl, vr = v + thd * B / 2.0, v - thd * B / 2.0
            top = max(abs(vl), abs(vr))
            if top > vmax:
                vl, vr = vl * vmax / top, vr * vmax / top
            self._record_cb(seg_i, LINE, vl, vr, dr)
            el, er, gy = self._step(vl, vr)
            if stop_touch:
                self._clip_contact(m, c0)
            self._dr_update(dr, el, er, gy, turning=False)
        if stop_touch:
            gap, _ = self._gap_ahead(m, c0, r.length_m / 2.0)
            if gap > 0:
                self.x += gap * math.cos(self.phi)
                self.y += gap * math.sin(self.phi)
        self._record_cb(seg_i, LINE, 0.0, 0.0, dr)
        self.t += self.dt  # the stop takes one sample

    def _run_spin(self, seg_i: int, dr: list[float]) -> None:
        """In-place 90° turn (Eq. 9 wheel speeds) to the next leg's heading,
        measured by the IMU (or the encoders in the baseline)."""
        cfg, r, B = self.cfg, self.r, self.r.track_m
        seg = self.path.segments[seg_i]
        nxt = self.path.segments[seg_i + 1]
        cb = self.g.wall(seg.wall)
        ax, ay = cb.to_wall(nxt.points[0])
        bx, by = cb.to_wall(nxt.points[-1])
        target = math.atan2(float(bx - ax), float(by - ay))
        omega_max = 2.0 * r.turn_speed_m_s / B
        while True:
            self._tick()
            err = _wrap(dr[2] - target)  # > 0: rotated too far right → turn left
            if abs(err) <= cfg.rot_tol_rad:
                break
            omega = min(omega_max, abs(err) / self.dt)
            # Eq. 9 with the Eq. 10 sign (θ grows turning right): reduce err.
            vl, vr = -math.copysign(omega * B / 2.0, err), math.copysign(omega * B / 2.0, err)
            self._record_cb(seg_i, SPIN, vl, vr, dr)
            el, er, gy = self._step(vl, vr)
            self._dr_update(dr, el, er, gy, turning=True)
        self._record_cb(seg_i, SPIN, 0.0, 0.0, dr)
        self.t += self.dt  # the stop takes one sample

    def _dr_update(self, dr: list[float], el: float, er: float, gy: float, turning: bool) -> None:
        """Eq. 10–11 with encoder travel; yaw from the IMU where configured."""
        X, Z, th = dr
        v_dt = 0.5 * (el + er)
        use_imu = self.cfg.dr_yaw == "imu" or (turning and self.cfg.dr_yaw == "imu_turns")
        dth = -gy if use_imu else (el - er) / self.r.track_m
        dr[0] = X + v_dt * math.sin(th)
        dr[1] = Z + v_dt * math.cos(th)
        dr[2] = th + dth

    def _record_cb(self, seg_i: int, mode: int, vl: float, vr: float, dr: list[float]) -> None:
        self._record(
            seg_i,
            mode,
            0,
            self.wall,
            self.x,
            self.y,
            self.phi,
            wheels=(vl, vr, math.nan, math.nan),
            dr=(dr[0], dr[1], dr[2]),
        )

    # ------------------------------------------------------------------ run
    def run(self) -> SimResult:
        segs = self.path.segments
        # Initial pose: first lane start with the initial error.
        first = segs[0]
        geo = self._lane_geometry(0)
        frame = self.g.wall(ROOF)
        x0, y0 = frame.to_wall(first.points[0])
        self.x = float(x0) - self.init_d * geo["lx"]
        self.y = float(y0) - self.init_d * geo["ly"]
        self.phi = geo["phi"] + self.init_delta
        dr: list[float] = [0.0, 0.0, 0.0]
        n = len(segs)
        for i, seg in enumerate(segs):
            self.seg_index, self.seg_t0 = i, self.t
            if self.progress is not None and seg.kind in (LANE, CORNER_UP):
                self.progress(0.05 + 0.9 * i / n, f"simulating segment {i + 1}/{n} ({seg.kind})")
            if seg.kind == LANE:
                self._run_lane(i)
            elif seg.kind == CORNER_DOWN:
                self._run_corner(i)
                dr = list(self._start_dr(i - 1, i))
                self.uturn_t0 = self.t
            elif seg.kind in (S1, S2):
                self._run_line(i, dr, stop_touch=False)
            elif seg.kind == S3:
                self._run_line(i, dr, stop_touch=True)
                s3_err = _wrap(dr[2] - 0.0)
            elif seg.kind == TURN:
                self._run_spin(i, dr)
            elif seg.kind == CORNER_UP:
                self._run_corner(i)
                geo = self._lane_geometry(i + 1)
                d, de = self._lane_error(geo)
                self.uturns.append(
                    UTurnResult(seg.lane, seg.to_lane, de, d, s3_err, self.t - self.uturn_t0)
                )
        arrays = self._arrays()
        self._summaries(arrays)
        return SimResult(
            arrays=arrays,
            lanes=self.lanes,
            corners=self.corners,
            uturns=self.uturns,
            dt_s=self.dt,
            seed=self.seed,
            noise=self.noise,
            config=self.cfg,
            crossing_pitch=self.crossings,
        )

    # ------------------------------------------------------------ arrays
    def _arrays(self) -> dict[str, np.ndarray]:
        A = np.array(self.rows, dtype=float).reshape(-1, _NCOL)
        T = len(A)
        kind = A[:, 3].astype(int)
        fid = A[:, 4].astype(int)
        pos = np.zeros((T, 3))
        xb = np.zeros((T, 3))
        zb = np.zeros((T, 3))
        wall_col = np.where(kind == 0, fid, -1)
        for w in (0, 1, 2):
            mask = (kind == 0) & (fid == w)
            if not mask.any():
                continue
            fr = self.g.wall(w)
            pos[mask] = fr.to_world(A[mask, 5], A[mask, 6])
            xb[mask] = fr.heading_world(A[mask, 7])
            zb[mask] = fr.n
        for ci in np.unique(fid[kind == 1]):
            mask = (kind == 1) & (fid == ci)
            geom = self.path.segments[ci].corner
            assert geom is not None
            theta = A[mask, 6]
            origin, x2, z2 = corner_mod.base_pose(theta, self.r.wheelbase_m, self.r.wheel_radius_m)
            pos[mask] = geom.to_world(origin[:, 0], origin[:, 1], A[mask, 5])
            xw, zw = geom.axes_world(x2, z2)
            xb[mask], zb[mask] = xw, zw
        yb = np.cross(zb, xb)
        Rm = np.stack([xb, yb, zb], axis=-1)
        on_lane = (kind == 0) & (fid == ROOF) & np.isfinite(A[:, 8])
        margin = np.full(T, np.nan)
        seg = A[:, 1].astype(int)
        for ln in self.lanes:
            mask = on_lane & (seg == ln.segment)
            w_deck = self.g.lane_width_m / 2.0
            # Robot-frame x where the deck ends (the crossbeam ahead).
            x_lim = (self.g.length_m - A[mask, 21]) / np.cos(A[mask, 9])
            margin[mask] = weld_margin(A[mask, 8], A[mask, 9], w_deck, -w_deck, self.fp, x_lim)
        return {
            "t_s": A[:, 0],
            "segment": seg,
            "mode": A[:, 2].astype(int),
            "wall": wall_col,
            "pos": pos,
            "quat": _rot_to_quat(Rm),
            "pitch_rad": A[:, 20],
            "d_m": A[:, 8],
            "delta_rad": A[:, 9],
            "d_est_m": A[:, 10],
            "delta_est_rad": A[:, 11],
            "v_left": A[:, 12],
            "v_right": A[:, 13],
            "v_front": A[:, 14],
            "v_rear": A[:, 15],
            "arm_rad": A[:, 16],
            "dr": A[:, 17:20],
            "along_m": A[:, 21],
            "margin_m": margin,
        }

    def _summaries(self, arrays: dict[str, np.ndarray]) -> None:
        seg = arrays["segment"]
        fp = self.fp
        for ln in self.lanes:
            mask = (seg == ln.segment) & np.isfinite(arrays["d_m"])
            d = arrays["d_m"][mask]
            de = arrays["delta_rad"][mask]
            along = arrays["along_m"][mask]
            mg = arrays["margin_m"][mask]
            ln.max_abs_d_m = float(np.max(np.abs(d)))
            ln.min_rib_clearance_m = float(np.min(rib_clearance(d, de, self.g, self.r)))
            ln.worst_margin_m = float(np.nanmin(mg)) if np.isfinite(mg).any() else math.nan
            # Lane covered end to end: Oc went from the start crossbeam's
            # offset to front-wheel contact at the far crossbeam.
            ln.covered = bool(ln.driven_m >= ln.length_m - 2e-3)
            # Weld length seen: union over samples of the footprint's span
            # along the lane (clipped to the deck) while the margin is ≥ 0.
            ok = np.isfinite(mg) & (mg >= 0)
            lo = along[ok] + fp.x_near * np.cos(de[ok])
            hi = np.minimum(along[ok] + fp.x_far * np.cos(de[ok]), self.g.length_m)
            ln.weld_seen_fraction = _union_length(lo, hi) / self.g.length_m


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


def simulate(
    path: InspectionPath,
    *,
    noise: NoiseModel | None = None,
    config: ControllerConfig | None = None,
    seed: int = 0,
    progress: Callable[[float, str], None] | None = None,
) -> SimResult:
    """Run the closed loop over the whole ``path`` (see the module docstring).

    Deterministic for a given ``seed``.  ``progress(f, stage)`` is called per
    lane and may raise :class:`planners.errors.CancelledError`.
    """
    noise = (noise or NoiseModel()).validate()
    config = (config or ControllerConfig()).validate()
    if not isinstance(seed, int | np.integer) or seed < 0:
        raise InvalidInputError(f"seed must be an integer ≥ 0, got {seed!r}")
    return _Sim(path, noise, config, int(seed), progress).run()


def simulate_lane(
    girder: Girder | None = None,
    robot: ClimberParams | None = None,
    *,
    d0_m: float = 0.010,
    delta0_rad: float = 2.0 * DEG,
    noise: NoiseModel | None = None,
    config: ControllerConfig | None = None,
    seed: int = 0,
    time_limit_s: float | None = 600.0,
) -> SimResult:
    """Centreline tracking on one lane from a given initial error (the
    seed's Fig. 13–14 experiment): a single-lane girder, no corners.  A lane
    still unfinished after ``time_limit_s`` ends there (``covered`` false)."""
    from planners.sbg.path import plan_path

    girder = girder or Girder(length_m=1.5, n_ribs=2)
    path = plan_path(girder, robot)
    path = InspectionPath(
        girder=path.girder,
        robot=path.robot,
        segments=path.segments[:1],
        lane_order=path.lane_order[:1],
        lane_dirs=path.lane_dirs,
        start_lane=path.start_lane,
        direction=path.direction,
        start_end=path.start_end,
        turn_depth_m=path.turn_depth_m,
        total_length_m=path.segments[0].length_m,
    )
    nz = (noise or NoiseModel()).validate()
    sim = _Sim(path, nz, (config or ControllerConfig()).validate(), int(seed), None)
    sim.init_d, sim.init_delta = d0_m, delta0_rad
    sim.lane_limit_s = time_limit_s
    return sim.run()
