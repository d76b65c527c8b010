"""Lane controller of the climber simulator (seed §3.2): trilateration
(Eq. 5) averaged over a window while driving straight; outside the dead
band the preview-follow arc (Eq. 6–7) on the encoders, then the in-place
turn (Eq. 8–9) on the IMU yaw; l1 stops the robot at the crossbeam.
"""

from __future__ import annotations

import math
from collections import deque

from planners.sbg.girder import ROOF
from planners.sbg.preview import (
    ArcPlan,
    arc_wheel_speeds,
    plan_arc,
    preview_for_arrival,
    rotation_wheel_speeds,
)
from planners.sbg.sim_log import _Log
from planners.sbg.sim_model import (
    ARC,
    ROTATE,
    STRAIGHT,
    LaneResult,
    _wrap,
)


class _LaneControl(_Log):
    """Lane tracking (seed §3.2): windowed trilateration (Eq. 5), the
    preview-follow arc (Eq. 6–7) when the error leaves the dead band, the
    in-place turn (Eq. 8–9) and heading hold on the encoder yaw."""

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
            # geo holds the lane index among its floats (as at the lane end below)
            l2, l3, l4 = self._ranges(d, de, along, int(geo["lane"]))
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
