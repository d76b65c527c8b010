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

from collections.abc import Callable

import numpy as np

from planners.errors import InvalidInputError
from planners.sbg.girder import ROOF, Girder
from planners.sbg.path import (
    CORNER_DOWN,
    CORNER_UP,
    LANE,
    S1,
    S2,
    S3,
    TURN,
    InspectionPath,
)
from planners.sbg.robot import ClimberParams
from planners.sbg.sim_model import (
    DEG,
    DR_YAW_MODES,
    MODE_NAMES,
    ControllerConfig,
    CornerResult,
    LaneResult,
    NoiseModel,
    SimResult,
    UTurnResult,
    _wrap,
    rib_clearance,
)
from planners.sbg.sim_uturn import _CornerUTurnControl

__all__ = [
    "DR_YAW_MODES",
    "MODE_NAMES",
    "ControllerConfig",
    "CornerResult",
    "LaneResult",
    "NoiseModel",
    "SimResult",
    "UTurnResult",
    "rib_clearance",
    "simulate",
    "simulate_lane",
]


class _Sim(_CornerUTurnControl):
    """One closed-loop run; see the module docstring.  Its parts, each a
    layer on the one before: :class:`~planners.sbg.sim_plant._Plant` (state,
    noisy plant, l1) → :class:`~planners.sbg.sim_sensors._Sensors` (l2–l4,
    Eq. 5) → :class:`~planners.sbg.sim_log._Log` (samples, arrays,
    summaries) → :class:`~planners.sbg.sim_lane._LaneControl` (Eq. 5–9) →
    :class:`~planners.sbg.sim_uturn._CornerUTurnControl` (Eq. 1–4, 10–11);
    this class only runs the segments in order."""

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
