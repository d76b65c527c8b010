"""Logging of the climber simulator: the per-sample rows, the arrays of
:class:`~planners.sbg.sim_model.SimResult` (world pose, body orientation,
camera weld margin) and per-lane summaries (rib clearance of Table 1, weld
seen, coverage).
"""

from __future__ import annotations

import math

import numpy as np

from planners.sbg import corner as corner_mod
from planners.sbg.camera import weld_margin
from planners.sbg.girder import ROOF
from planners.sbg.sim_model import (
    _NCOL,
    _rot_to_quat,
    _union_length,
    rib_clearance,
)
from planners.sbg.sim_sensors import _Sensors


class _Log(_Sensors):
    """Per-sample log of a run (one row of ``_NCOL`` floats per control
    sample), turned into :class:`SimResult` arrays (world pose, body
    quaternion, camera weld margin) and the per-lane summaries."""

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
