"""Corner and U-turn controllers of the climber simulator: the 90° concave
corner (seed §3.1, :func:`planners.sbg.corner.cross_corner`, Eq. 1–4) with
noisy wheels, and the U-turn (§3.3) on dead reckoning Eq. 10–11 (encoder
distances; heading from the IMU in turns, the encoders or the IMU) with a
line follower on S1, S2, S3.
"""

from __future__ import annotations

import math

from planners.sbg import corner as corner_mod
from planners.sbg.girder import ROOF
from planners.sbg.sim_lane import _LaneControl
from planners.sbg.sim_model import (
    CORNER,
    DEG,
    LINE,
    SPIN,
    CornerResult,
    _corner_exit,
    _wrap,
)


class _CornerUTurnControl(_LaneControl):
    """Corner crossing (§3.1, Eq. 1–4) and the U-turn on the crossbeam
    (§3.3): dead reckoning Eq. 10–11 and the S1/S2/S3 line follower."""

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
        w0, w1 = cb.to_wall(seg.points[0]), cb.to_wall(seg.points[-1])
        sx, sy, exx, eyy = float(w0[0]), float(w0[1]), float(w1[0]), float(w1[1])
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
