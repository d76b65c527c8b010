"""Plant of the climber simulator: skid-steer kinematics under noisy wheel
commands, encoder travel with calibration error and resolution, a gyro
with bias, bias walk, angle random walk and scale error, wall contact and
the l1 range finder (seed §3, module :mod:`planners.sbg.simulator`).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from planners.errors import InfeasibleError
from planners.sbg.camera import footprint, max_yaw_for_margin
from planners.sbg.girder import ROOF, WallFrame
from planners.sbg.path import (
    InspectionPath,
)
from planners.sbg.sim_model import (
    DEG,
    ControllerConfig,
    CornerResult,
    LaneResult,
    NoiseModel,
    UTurnResult,
    _Gauss,
)


class _Plant:
    """Plant of one closed-loop run: per-run noise draws (wheel gains,
    encoder scale, turn slip and centre, gyro bias/scale, wall waviness
    phases, initial lane error — all from one generator seeded by ``seed``),
    the pose on the current wall, skid-steer kinematics with noisy wheels,
    encoders, gyro and the l1 range finder ahead."""

    # Set per segment by the run loop (read by the segment-time guard).
    seg_index: int
    seg_t0: float

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

    def _tick(self) -> None:
        if self.t - self.seg_t0 > self.cfg.max_segment_s:
            raise InfeasibleError(
                f"segment {self.seg_index} ({self.path.segments[self.seg_index].kind}) did not finish "
                f"within {self.cfg.max_segment_s:.0f} s of simulated time; check the controller settings"
            )
