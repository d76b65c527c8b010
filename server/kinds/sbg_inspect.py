"""``sbg.inspect``: full-lane inspection of a steel box girder by the
magnetic-wheel wall climber (seed 003, Song et al. 2022).

Plans the boustrophedon path over every lane (lane centrelines on the roof,
90° concave corners, S1–S2–S3 U-turns on the crossbeams) and drives it in the
closed-loop simulator (trilateration Eq. 5, preview-follow Eq. 6–9, corner law
Eq. 1–4, dead reckoning Eq. 10–11) under a stated noise model.  The defaults
plan the seed's experiment on a 3-lane mock-up girder.  See docs/sbg.md.
"""

from __future__ import annotations

import math
from dataclasses import fields
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import Field, create_model

from planners.sbg import (
    ControllerConfig,
    Girder,
    Limits,
    NoiseModel,
    plan_path,
    sample_girders,
)
from planners.sbg.inspection_report import plan_inspection_result
from planners.sbg.robot import ClimberParams
from server.kinds.base import JobContext, KindOutput, PlanKind, PlanView, Seed, StrictParams

DEG = math.pi / 180.0
_DEFAULT_GIRDER = sample_girders()["seed_lab"]


class GirderParams(StrictParams):
    """Girder bay geometry (metres); defaults: the 3-lane ``seed_lab`` mock-up.

    Upper bounds are generous for real orthotropic decks: crossbeams a few
    metres apart, U-ribs about 0.3 m wide at 0.6 m, plates tens of mm."""

    length_m: float = Field(
        _DEFAULT_GIRDER.length_m,
        gt=0,
        le=100.0,
        description="clear length between the crossbeam faces",
    )
    n_ribs: int = Field(
        _DEFAULT_GIRDER.n_ribs, ge=2, le=40, description="U-ribs; lanes = n_ribs − 1"
    )
    rib_spacing_m: float = Field(
        _DEFAULT_GIRDER.rib_spacing_m, gt=0, le=5.0, description="rib centre-to-centre spacing"
    )
    rib_top_width_m: float = Field(
        _DEFAULT_GIRDER.rib_top_width_m, gt=0, le=2.0, description="rib width at the deck"
    )
    rib_bottom_width_m: float = Field(
        _DEFAULT_GIRDER.rib_bottom_width_m, gt=0, le=2.0, description="rib width at its bottom"
    )
    rib_depth_m: float = Field(
        _DEFAULT_GIRDER.rib_depth_m, gt=0, le=2.0, description="rib depth below the deck"
    )
    deck_thickness_m: float = Field(
        _DEFAULT_GIRDER.deck_thickness_m, gt=0, le=0.2, description="roof deck plate"
    )
    crossbeam_depth_m: float = Field(
        _DEFAULT_GIRDER.crossbeam_depth_m,
        gt=0,
        le=5.0,
        description="crossbeam height drawn below the deck",
    )
    crossbeam_thickness_m: float = Field(
        _DEFAULT_GIRDER.crossbeam_thickness_m, gt=0, le=0.2, description="crossbeam plate"
    )
    cutout_clearance_m: float = Field(
        _DEFAULT_GIRDER.cutout_clearance_m,
        ge=0,
        le=0.5,
        description="gap around a rib in the crossbeam cut-out",
    )
    edge_width_m: float = Field(
        _DEFAULT_GIRDER.edge_width_m,
        ge=0,
        le=5.0,
        description="deck drawn beyond the outer rib centres",
    )

    def build(self) -> Girder:
        return Girder(**self.model_dump())


class RobotOverrides(StrictParams):
    """Changes to the climber's parameters (robots/sbg_climber/params.toml);
    ``null`` keeps the file's value.  Upper bounds: a climber that fits a
    U-rib lane (the file's is 230 mm long, 20 mm/s)."""

    wheel_radius_mm: float | None = Field(None, gt=0, le=500.0, description="R (Eq. 1–2)")
    track_mm: float | None = Field(
        None, gt=0, le=2000.0, description="B, wheel centre to wheel centre (Eq. 9, 11)"
    )
    max_speed_mm_s: float | None = Field(
        None, gt=0, le=1000.0, description="wheel speed cap (Eq. 4: 20 mm/s)"
    )
    turn_speed_mm_s: float | None = Field(
        None, gt=0, le=1000.0, description="wheel speed of in-place turns (Eq. 9)"
    )
    arm_length_mm: float | None = Field(None, gt=0, le=2000.0, description="larm (Eq. 1)")
    arm_l0_mm: float | None = Field(None, gt=0, le=2000.0, description="l0 (Eq. 1–2)")
    arm_dg_mm: float | None = Field(None, gt=0, le=2000.0, description="dg (Eq. 1–2)")
    lift_time_s: float | None = Field(None, gt=0, le=60.0, description="minimum-jerk lift stroke")
    camera_hfov_deg: float | None = Field(
        None, gt=0, lt=180, description="camera horizontal field of view"
    )
    camera_tilt_deg: float | None = Field(
        None, gt=0, lt=90, description="camera tilt toward the wall"
    )

    def build(self) -> ClimberParams:
        from robots import load_robot

        base = ClimberParams.coerce(load_robot("sbg_climber"))
        mm = 1e-3
        ch: dict[str, Any] = {}
        pairs = {
            "wheel_radius_mm": ("wheel_radius_m", mm),
            "track_mm": ("track_m", mm),
            "max_speed_mm_s": ("max_speed_m_s", mm),
            "turn_speed_mm_s": ("turn_speed_m_s", mm),
            "arm_length_mm": ("arm_length_m", mm),
            "arm_l0_mm": ("arm_l0_m", mm),
            "arm_dg_mm": ("arm_dg_m", mm),
            "lift_time_s": ("lift_time_s", 1.0),
        }
        for key, (name, scale) in pairs.items():
            v = getattr(self, key)
            if v is not None:
                ch[name] = v * scale
        cam = base.camera
        if self.camera_hfov_deg is not None or self.camera_tilt_deg is not None:
            from dataclasses import replace

            cam = replace(
                cam,
                hfov_rad=cam.hfov_rad
                if self.camera_hfov_deg is None
                else self.camera_hfov_deg * DEG,
                tilt_rad=cam.tilt_rad
                if self.camera_tilt_deg is None
                else self.camera_tilt_deg * DEG,
            )
        return base.with_(camera=cam, **ch)


_NOISE_HELP = {
    "range_sigma_mm": "white noise of each laser range reading",
    "wall_waviness_mm": "amplitude of a sinusoidal waviness of the rib webs",
    "wall_wavelength_m": "wavelength of that waviness",
    "wheel_gain_sigma": "per-wheel constant speed error (fraction)",
    "wheel_speed_sigma": "per-sample wheel speed noise (fraction)",
    "encoder_scale_sigma": "common wheel-radius (distance) error (fraction)",
    "encoder_differential_sigma": "left/right encoder scale mismatch after calibration (fraction)",
    "encoder_resolution_mm": "encoder count resolution",
    "turn_slip_mean": "fraction of an in-place turn lost to skid",
    "turn_slip_sigma": "per-run spread of that fraction",
    "turn_slip_jitter": "per-sample jitter of that fraction",
    "turn_centre_sigma_mm": "offset of the skid-steer turn centre from Oc",
    "gyro_bias_dps": "residual gyro bias (deg/s)",
    "gyro_bias_walk_dps_rts": "gyro bias random walk (deg/s/√s)",
    "gyro_arw_deg_rts": "gyro angle random walk (deg/√s)",
    "gyro_scale_sigma": "gyro scale-factor error (fraction)",
    "corner_lateral_sigma_mm": "lateral shift across a corner crossing",
    "corner_yaw_sigma_deg": "yaw kick across a corner crossing",
    "init_d_sigma_mm": "initial offset from the first lane's centreline",
    "init_delta_sigma_deg": "initial yaw deviation",
}
#: Upper bound of each noise term: far beyond any sensor or plant the model
#: stands for (fractions at most 1, mm errors at most 100 mm in a 300 mm
#: lane, angles at most 90°, gyro terms at most 10 °/s); a field of
#: NoiseModel missing here fails the kind's import, so none goes unbounded.
_NOISE_MAX = {
    "range_sigma_mm": 100.0,
    "wall_waviness_mm": 100.0,
    "wall_wavelength_m": 100.0,
    "wheel_gain_sigma": 1.0,
    "wheel_speed_sigma": 1.0,
    "encoder_scale_sigma": 1.0,
    "encoder_differential_sigma": 1.0,
    "encoder_resolution_mm": 100.0,
    "turn_slip_mean": 1.0,
    "turn_slip_sigma": 1.0,
    "turn_slip_jitter": 1.0,
    "turn_centre_sigma_mm": 100.0,
    "gyro_bias_dps": 10.0,
    "gyro_bias_walk_dps_rts": 10.0,
    "gyro_arw_deg_rts": 10.0,
    "gyro_scale_sigma": 1.0,
    "corner_lateral_sigma_mm": 100.0,
    "corner_yaw_sigma_deg": 90.0,
    "init_d_sigma_mm": 100.0,
    "init_delta_sigma_deg": 90.0,
}
_NOISE_DEFAULT = NoiseModel()
# (type, FieldInfo) per field; typed Any as create_model's **field_definitions are
_NOISE_FIELDS: dict[str, Any] = {
    f.name: (
        float,
        Field(
            getattr(_NOISE_DEFAULT, f.name),
            ge=0,
            le=_NOISE_MAX[f.name],
            description=_NOISE_HELP.get(f.name, f.name),
        ),
    )
    for f in fields(NoiseModel)
}
NoiseParams = create_model(
    "NoiseParams",
    __base__=StrictParams,
    __doc__="Noise model of the simulation (planners.sbg.NoiseModel; all chosen, see docs/sbg.md).",
    **_NOISE_FIELDS,
)


class SbgInspectParams(StrictParams):
    """Girder, robot, operator choices, controller and noise of one inspection plan."""

    girder: GirderParams = Field(default_factory=GirderParams, description="girder bay geometry")
    robot: RobotOverrides = Field(
        default_factory=RobotOverrides, description="changes to the climber's parameters"
    )
    # at most 40 ribs (GirderParams.n_ribs): lanes 0–38
    start_lane: int = Field(
        0, ge=0, le=38, description="lane the inspection starts in (0 = lowest Y)"
    )
    direction: Literal[1, -1] = Field(
        1, description="+1 sweeps toward higher lane numbers first, −1 lower"
    )
    start_end: Literal[0, 1] = Field(
        0, description="crossbeam the first lane starts from (0: X = 0, 1: X = length)"
    )
    preview_mm: float = Field(20.0, ge=0, le=2000, description="preview distance Lx (seed: 20 mm)")
    camera_yaw_cap: bool = Field(
        True,
        description="cap a correction's yaw so the welds stay in view (false + null max_yaw_deg: the seed's law as printed)",
    )
    camera_safety_mm: float = Field(
        5.0, ge=0, le=1000.0, description="weld margin the camera yaw cap keeps"
    )
    max_yaw_deg: float | None = Field(
        None, gt=0, lt=90, description="fixed yaw cap of a correction (null: none)"
    )
    dr_yaw: Literal["imu_turns", "encoder", "imu"] = Field(
        "imu_turns",
        description="U-turn heading: IMU in turns (seed), encoders only (baseline), IMU throughout",
    )
    corner_profile: Literal["smooth", "printed"] = Field(
        "smooth", description="corner wheel/arm profile"
    )
    noise: NoiseParams = Field(default_factory=NoiseParams, description="noise model")
    seed: Seed = Field(0, description="random seed of the simulation")
    sweep_lx_mm: list[Annotated[float, Field(ge=0, le=2000)]] = Field(
        default_factory=lambda: [0.0, 10.0, 20.0, 40.0, 80.0],
        max_length=12,
        description="preview distances (mm) of the Lx sweep shown in the console (empty: no sweep)",
    )
    sweep_seeds: int = Field(2, ge=1, le=8, description="seeds per Lx in the sweep")
    final_d_limit_mm: float = Field(
        0.33, gt=0, le=1000.0, description="check: final |d| at a lane end (seed §4.2)"
    )
    final_delta_limit_deg: float = Field(
        0.06, gt=0, le=90.0, description="check: final |δ| at a lane end (seed §4.2)"
    )
    uturn_yaw_limit_deg: float = Field(
        1.5, gt=0, le=180.0, description="check: |yaw| on reaching the roof after a U-turn"
    )
    camera_margin_limit_mm: float = Field(
        0.0, ge=-1000.0, le=1000.0, description="check: weld margin inside the camera view"
    )
    pitch_accel_limit_deg_s2: float = Field(
        20.0, gt=0, le=10_000.0, description="check: pitch acceleration while crossing"
    )


def _noise(p: SbgInspectParams) -> NoiseModel:
    return NoiseModel(**p.noise.model_dump())


def _config(p: SbgInspectParams) -> ControllerConfig:
    return ControllerConfig(
        preview_m=p.preview_mm * 1e-3,
        camera_yaw_cap=p.camera_yaw_cap,
        camera_safety_m=p.camera_safety_mm * 1e-3,
        max_yaw_rad=None if p.max_yaw_deg is None else p.max_yaw_deg * DEG,
        dr_yaw=p.dr_yaw,
        corner_profile=p.corner_profile,
    )


def validate(p: SbgInspectParams) -> None:
    """Cheap: the geometry must fit and the path must plan (HTTP 422 if not)."""
    plan_path(
        p.girder.build(),
        p.robot.build(),
        start_lane=p.start_lane,
        direction=p.direction,
        start_end=p.start_end,
    )
    _noise(p).validate()
    _config(p).validate()


def run(p: SbgInspectParams, ctx: JobContext) -> KindOutput:
    limits = Limits(
        final_d_m=p.final_d_limit_mm * 1e-3,
        final_delta_rad=p.final_delta_limit_deg * DEG,
        uturn_yaw_rad=p.uturn_yaw_limit_deg * DEG,
        camera_margin_m=p.camera_margin_limit_mm * 1e-3,
        pitch_accel_deg_s2=p.pitch_accel_limit_deg_s2,
    )
    r = plan_inspection_result(
        p.girder.build(), p.robot.build(), start_lane=p.start_lane, direction=p.direction,
        start_end=p.start_end, noise=_noise(p), config=_config(p), seed=p.seed, limits=limits,
        sweep_lx_m=[v * 1e-3 for v in p.sweep_lx_mm], sweep_seeds=p.sweep_seeds,
        progress=ctx.progress,
    )  # fmt: skip
    return KindOutput.from_result(r)


def compile_program(plan: PlanView) -> list[dict[str, Any]]:
    """Wheel-speed and lift-arm commands reproducing the simulated run.

    The four physical wheels, in order front-left, front-right, rear-left,
    rear-right (m/s): on a wall they follow the differential-drive speeds
    (v_left, v_right; Eq. 9), in a corner the front/rear speeds of Eq. 4;
    the lift arm in rad.  The robot's own controllers (trilateration,
    preview-follow) close the loop on board; this program carries the
    planned speed profile.
    """
    from server.kinds.programs import as_dicts, sampled_wheels_and_lift

    w = plan.array("traj_wheels")  # columns: v_left, v_right, v_front, v_rear (NaN when unused)
    on_wall = np.isfinite(w[:, 0]) & np.isfinite(w[:, 1])
    fl = np.where(on_wall, w[:, 0], w[:, 2])
    fr = np.where(on_wall, w[:, 1], w[:, 2])
    rl = np.where(on_wall, w[:, 0], w[:, 3])
    rr = np.where(on_wall, w[:, 1], w[:, 3])
    wheels = np.nan_to_num(np.stack([fl, fr, rl, rr], axis=1), nan=0.0)
    arm = np.nan_to_num(plan.array("traj_arm"), nan=0.0)
    return as_dicts(sampled_wheels_and_lift(plan.array("traj_t"), wheels, arm, dt_s=0.5))


KIND = PlanKind(
    name="sbg.inspect",
    title="Box girder: full-lane inspection by the wall climber",
    description=__doc__ or "",
    params_model=SbgInspectParams,
    run=run,
    robot="sbg_climber",
    validate=validate,
    compile=compile_program,
)
