"""What hardware an emulated robot has: joints and their limits, wheels, magnets…

Joint limits come, in order of preference, from explicit arguments, from the
robot's description (``robots.load_robot(name).joint_limits``), or from the
fallback table below (used while a description is missing or broken, with a
warning).  A description may also describe its non-joint hardware in its
``params.toml``::

    [protocol]
    n_wheels = 2
    n_magnets = 2
    n_plates = 0
    lift_limits_rad = [0.0, 1.5708]   # omit when there is no lifting arm
    nozzle = false

Two-footed robots (the ARA) get their feet rules (:mod:`robots.emulator.feet`)
from ``[magnets] mobile`` and the description's kinematics; a robot whose
params have a ``[camera]`` table and whose description has ``camera_to_base``
gets a depth camera (:mod:`robots.emulator.camera`); the wheel track (for the
base pose the wheels drive) is ``[foot] wheel_track_m``.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from robots.emulator.camera import CameraSpec
from robots.emulator.feet import FeetSpec

log = logging.getLogger(__name__)


#: Wheel track when a description gives none, m.
DEFAULT_TRACK_M = 0.2


@dataclass(frozen=True)
class RobotProfile:
    """Hardware of one emulated robot."""

    name: str
    joint_limits: np.ndarray  # (n, 2) rad
    n_wheels: int = 0
    n_magnets: int = 0
    n_plates: int = 0
    lift_limits: tuple[float, float] | None = None  # rad; None: no lifting arm
    nozzle: bool = False
    source: str = "fallback"  # where the joint limits came from
    feet: FeetSpec | None = None  # two feet with magnets: the feet rules apply
    camera: CameraSpec | None = None  # executes capture commands
    wheel_track_m: float = DEFAULT_TRACK_M  # left/right wheel distance (differential drive)

    @property
    def n_joints(self) -> int:
        return int(self.joint_limits.shape[0])


def _deg(rows: Sequence[tuple[float, float]]) -> np.ndarray:
    return np.radians(np.asarray(rows, dtype=float))


# Fallbacks, used only when the description cannot be loaded.
#   denso_vm6083: limits from DESIGN §7 (seed 004); nozzle: the blasting tool.
#   cmbot: chosen — 5-DoF climber + 7-DoF arm (seed 002), ±170° placeholders;
#          2 electromagnet feet and 2 limiting plates (seed 002), spray nozzle.
#   ara: chosen — 6-DoF worming arm (seed 000), ±180° placeholders; 2 differential
#        wheels and 2 magnet arrays driven by the Arduino low level (seed 000).
#   sbg_climber: 4 permanent-magnet wheels, differential drive, a lifting arm
#        (seed 003); lift range 0…90° chosen (arm perpendicular to the wall at 90°).
FALLBACK_PROFILES: dict[str, RobotProfile] = {
    "denso_vm6083": RobotProfile(
        "denso_vm6083",
        _deg([(-170, 170), (-90, 135), (-80, 165), (-185, 185), (-120, 120), (-360, 360)]),
        nozzle=True,
    ),
    "cmbot": RobotProfile("cmbot", _deg([(-170, 170)] * 12), n_magnets=2, n_plates=2, nozzle=True),
    "ara": RobotProfile(
        "ara",
        _deg([(-180, 180)] * 6),
        n_wheels=2,
        n_magnets=2,
        feet=FeetSpec(q_mobile=np.zeros(6)),  # joint tolerance: no kinematics to decide
        wheel_track_m=0.14,
    ),
    "sbg_climber": RobotProfile(
        "sbg_climber", np.zeros((0, 2)), n_wheels=4, lift_limits=(0.0, math.pi / 2)
    ),
    # Everything at once, for protocol tests and unknown names.
    "generic": RobotProfile(
        "generic",
        _deg([(-180, 180)] * 6),
        n_wheels=2,
        n_magnets=2,
        n_plates=2,
        lift_limits=(0.0, math.pi / 2),
        nozzle=True,
    ),
}


def _hardware_from_params(profile: RobotProfile, params: Mapping[str, Any]) -> RobotProfile:
    hw = params.get("protocol") if isinstance(params, Mapping) else None
    if not isinstance(hw, Mapping):
        return profile
    lift = hw.get("lift_limits_rad", profile.lift_limits)
    return replace(
        profile,
        n_wheels=int(hw.get("n_wheels", profile.n_wheels)),
        n_magnets=int(hw.get("n_magnets", profile.n_magnets)),
        n_plates=int(hw.get("n_plates", profile.n_plates)),
        lift_limits=(float(lift[0]), float(lift[1])) if lift is not None else None,
        nozzle=bool(hw.get("nozzle", profile.nozzle)),
    )


def _feet_and_camera(profile: RobotProfile, model: Any) -> RobotProfile:
    """Feet rules, camera and wheel track from a loaded description (see the module doc)."""
    params = getattr(model, "params", {}) or {}
    changes: dict[str, Any] = {}
    foot = params.get("foot")
    if isinstance(foot, Mapping) and "wheel_track_m" in foot:
        changes["wheel_track_m"] = float(foot["wheel_track_m"])
    magnets = params.get("magnets")
    q_mobile = getattr(model, "q_mobile", None)
    fk_all = getattr(model, "fk_all", None)
    if (
        isinstance(magnets, Mapping)
        and "mobile" in magnets
        and profile.n_magnets >= 2
        and q_mobile is not None
        and len(q_mobile) == profile.n_joints
    ):
        changes["feet"] = FeetSpec(
            q_mobile=np.asarray(q_mobile, dtype=float),
            foot_pose=None if fk_all is None else (lambda Q: fk_all(Q)[..., -1, :, :]),
            plane_tol_m=float(magnets.get("mobile_plane_tol_m", 0.003)),
            tilt_tol_rad=math.radians(float(magnets.get("mobile_tilt_tol_deg", 2.0))),
        )
    camera = params.get("camera")
    camera_to_base = getattr(model, "camera_to_base", None)
    if isinstance(camera, Mapping) and camera_to_base is not None:
        changes["camera"] = CameraSpec.from_params(dict(camera), camera_to_base)
    return replace(profile, **changes) if changes else profile


def resolve_profile(name: str, joint_limits: np.ndarray | Sequence | None = None) -> RobotProfile:
    """Profile of robot ``name``: explicit limits > the robot's description > fallback."""
    base = FALLBACK_PROFILES.get(name)
    if base is None:
        base = replace(FALLBACK_PROFILES["generic"], name=name)
    if joint_limits is not None:
        lim = np.asarray(joint_limits, dtype=float).reshape(-1, 2)
        if np.any(lim[:, 0] > lim[:, 1]):
            raise ValueError(f"joint_limits for {name!r}: a lower limit exceeds its upper limit")
        return replace(base, joint_limits=lim, source="arguments")
    from robots import ROBOT_NAMES, load_robot

    if name not in ROBOT_NAMES:
        return base  # "generic" or a name without a description: the table is all there is
    try:
        model = load_robot(name)
        lim = np.asarray(model.dispatch_joint_limits, dtype=float).reshape(-1, 2)
        profile = replace(base, joint_limits=lim, source=f"robots.load_robot({name!r})")
        profile = _hardware_from_params(profile, getattr(model, "params", {}) or {})
        return _feet_and_camera(profile, model)
    except Exception as exc:  # descriptions are optional here; never fail the emulator
        log.warning("robot %r: no usable description (%s); using fallback limits", name, exc)
        return base
