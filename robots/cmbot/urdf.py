"""Generate ``cmbot.urdf`` from ``params.toml`` (primitive geometry only).

The URDF is the description every consumer reads (viser, the model loader);
this module writes it from the parameters so the two never drift apart
(``tests/robots/test_cmbot.py`` regenerates it and compares).  Run
``python -m robots.cmbot.urdf`` after changing ``params.toml``.

Joint frames follow the seed's modified D-H convention (Eq. 2): joint i's
origin is ``Tz(d_{i-1})·Rx(α_i)·Tx(a_i)`` in the previous link frame and it
turns about its own z axis, so each URDF link frame is Craig's frame i
without its ``Tz(d_i)``.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from robots.cmbot.kinematics import climber_mdh

HERE = Path(__file__).resolve().parent


def climber_table(p: dict[str, Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Corrected Table 1 (see :mod:`robots.cmbot.kinematics`): α, a, d."""
    # One table: the URDF is generated from the same rows the closed forms use.
    return climber_mdh(p["climber"]["l1"], p["climber"]["l2"])


def arm_table(p: dict[str, Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Table 2 with d_10 = −l6 (sign reading, docs/cmbot.md): α, a, d for J6…J12."""
    a_ = p["arm"]
    alpha = np.radians([0.0, -90.0, 0.0, 0.0, 90.0, -90.0, 90.0])
    a = np.array([0.0, a_["l3"], a_["l4"], a_["l5"], 0.0, 0.0, 0.0])
    d = np.array([0.0, 0.0, 0.0, 0.0, -a_["l6"], 0.0, 0.0])
    return alpha, a, d


def work_knee_angle(p: dict[str, Any]) -> float:
    """θ2 of the symmetric work stance (feet ``work_foot_distance_m`` apart, φy = 0)."""
    c = p["climber"]
    return math.acos(c["work_foot_distance_m"] / (2.0 * c["l2"]))


def arm_mount(p: dict[str, Any]) -> np.ndarray:
    """Fixed transform link2 → arm base frame (6) = (K).

    Origin on the J3 axis (J6 coaxial with J3, seed §2.2) shifted
    ``mount_offset_m`` along it; z_K = −z_J3 (seed §3.1: "the Z-axis of J6 is
    opposite to the Z-axis of J3"); x_K points straight up and y_K forward
    along the bar when the robot stands in its work stance.
    """
    l2 = p["climber"]["l2"]
    e = p["arm"]["mount_offset_m"]
    beta = math.pi / 2 - work_knee_angle(p)
    cb, sb = math.cos(beta), math.sin(beta)
    R = np.array([[cb, sb, 0.0], [sb, -cb, 0.0], [0.0, 0.0, -1.0]])  # Rz(β)·Rx(π)
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = np.array([l2, 0.0, 0.0]) + e * R[:, 2]
    return T


def _fmt(v: np.ndarray | list[float]) -> str:
    return " ".join(f"{float(x):.9g}" for x in v)


def _rpy(R: np.ndarray) -> np.ndarray:
    """URDF roll-pitch-yaw of a rotation matrix (R = Rz(y)·Ry(p)·Rx(r)): scipy's
    extrinsic x-y-z Euler angles."""
    with warnings.catch_warnings():
        # Gimbal lock (pitch ±90°) is expected for axis-aligned cylinders;
        # scipy then sets yaw to 0, which still reproduces R.
        warnings.simplefilter("ignore", UserWarning)
        # + 0.0 writes a signed zero as "0" in the file
        return np.asarray(Rotation.from_matrix(R).as_euler("xyz")) + 0.0


def _cylinder(
    a: np.ndarray | Sequence[float], b: np.ndarray | Sequence[float], radius: float, material: str
) -> str:
    """Visual + collision cylinder from point a to b in the link frame."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    v = b - a
    length = float(np.linalg.norm(v))
    if length < 1e-9:
        return ""
    z = v / length
    x = np.cross([0.0, 0.0, 1.0], z) if abs(z[2]) < 0.99 else np.array([1.0, 0.0, 0.0])
    x = x / np.linalg.norm(x)
    y = np.cross(z, x)
    x = np.cross(y, z)
    rpy = _rpy(np.column_stack([x, y, z]))
    geom = f'<cylinder radius="{radius:.6g}" length="{length:.6g}"/>'
    org = f'<origin xyz="{_fmt((a + b) / 2)}" rpy="{_fmt(rpy)}"/>'
    return (
        f'    <visual>{org}<geometry>{geom}</geometry><material name="{material}"/></visual>\n'
        f"    <collision>{org}<geometry>{geom}</geometry></collision>\n"
    )


def _box(
    center: list[float], size: list[float], material: str, rpy: list[float] | None = None
) -> str:
    org = f'<origin xyz="{_fmt(center)}" rpy="{_fmt(rpy or [0, 0, 0])}"/>'
    geom = f'<box size="{_fmt(size)}"/>'
    return (
        f'    <visual>{org}<geometry>{geom}</geometry><material name="{material}"/></visual>\n'
        f"    <collision>{org}<geometry>{geom}</geometry></collision>\n"
    )


def _inertial(m: list[float]) -> str:
    mass, x, y, z = m
    i = max(1e-4, 0.01 * mass)
    return (
        f'    <inertial><origin xyz="{_fmt([x, y, z])}"/><mass value="{mass:.6g}"/>'
        f'<inertia ixx="{i:.4g}" iyy="{i:.4g}" izz="{i:.4g}" ixy="0" ixz="0" iyz="0"/></inertial>\n'
    )


def _foot(p: dict[str, Any]) -> str:
    """Electromagnet module with limiting plate and two laser range finders (seed Fig. 3)."""
    c = p["climber"]
    L, W, H = c["foot_length_m"], c["foot_width_m"], c["foot_height_m"]
    return (
        _box([0, 0, H / 2], [L, W, H], "magnet")
        # limiting plate: hangs beside the bar's top flange, seizes it sideways
        + _box([0, W / 2 + 0.006, -0.015], [0.7 * L, 0.01, 0.07], "plate")
        # laser range finders front and back: sole-to-bar distance for J2/J4 levelling
        + _box([L / 2 + 0.015, 0, 0.02], [0.03, 0.03, 0.03], "sensor")
        + _box([-L / 2 - 0.015, 0, 0.02], [0.03, 0.03, 0.03], "sensor")
    )


def build_urdf(p: dict[str, Any]) -> str:
    """The CMBOT URDF text: rear foot (root) → J1…J5 → front foot; link2 → J6…J12 → tool."""
    c, a_ = p["climber"], p["arm"]
    cm, am = c["mass"], a_["mass"]
    lr, mr = a_["link_radius_m"], a_["module_radius_m"]
    climb_lim = np.radians(c["joint_limits_deg"])
    climb_vel = np.radians(c["joint_speed_deg_s"])
    arm_lim = np.radians(a_["joint_limits_deg"])
    arm_vel = np.radians(a_["joint_speed_deg_s"])
    calpha, ca, cd = climber_table(p)
    aalpha, aa, ad = arm_table(p)
    effort = p["indicators"]["joint_torque_Nm"]
    out = ['<?xml version="1.0"?>', "<!-- Generated by robots/cmbot/urdf.py from params.toml. -->"]
    out.append('<robot name="cmbot">')
    for name, rgba in [
        ("magnet", "0.25 0.25 0.3 1"),
        ("plate", "0.8 0.6 0.1 1"),
        ("sensor", "0.9 0.1 0.1 1"),
        ("link", "0.85 0.85 0.85 1"),
        ("module", "0.2 0.4 0.8 1"),
        ("carbon", "0.1 0.1 0.1 1"),
        ("cabinet", "0.3 0.6 0.3 1"),
    ]:
        out.append(f'  <material name="{name}"><color rgba="{rgba}"/></material>')

    def link(name: str, body: str, mass: list[float] | None) -> None:
        out.append(f'  <link name="{name}">\n{body}{_inertial(mass) if mass else ""}  </link>')

    def joint(
        name: str, kind: str, parent: str, child: str, T: np.ndarray, lim=None, vel=None
    ) -> None:
        s = f'  <joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
        s += f'<origin xyz="{_fmt(T[:3, 3])}" rpy="{_fmt(_rpy(T[:3, :3]))}"/>'
        if kind == "revolute":
            s += '<axis xyz="0 0 1"/>'
            s += f'<limit lower="{lim[0]:.9g}" upper="{lim[1]:.9g}" effort="{effort:g}" velocity="{vel:.9g}"/>'
        out.append(s + "</joint>")

    def origin(alpha: float, a: float, d_prev: float) -> np.ndarray:
        ca_, sa_ = math.cos(alpha), math.sin(alpha)
        T = np.eye(4)
        T[:3, :3] = np.array([[1.0, 0.0, 0.0], [0.0, ca_, -sa_], [0.0, sa_, ca_]])
        T[:3, 3] = [a, 0.0, d_prev]
        return T

    # --- climbing mechanism ---------------------------------------------------
    l1, l2, fh = c["l1"], c["l2"], c["foot_height_m"]
    link("foot_rear", _foot(p), cm["foot_rear"])
    bodies = {
        "link1": _cylinder([0, 0, fh], [0, 0, l1], 0.035, "link")
        + _cylinder([0, 0.05, l1], [0, -0.05, l1], 0.05, "module"),
        "link2": _cylinder([0, 0, 0], [l2, 0, 0], 0.03, "link")
        + _cylinder([l2, 0, -0.05], [l2, 0, 0.05], 0.05, "module")
        + _box([0.15, 0.0, -0.12], [0.20, 0.12, 0.14], "cabinet"),
        "link3": _cylinder([0, 0, 0], [l2, 0, 0], 0.03, "link")
        + _cylinder([l2, 0, -0.05], [l2, 0, 0.05], 0.05, "module")
        + _box([0.10, 0.05, 0.0], [0.08, 0.06, 0.06], "sensor"),
        "link4": "",
        "link5": _cylinder([0, 0, 0], [0, 0, -(l1 - fh)], 0.035, "link"),
    }
    masses = {
        "link1": cm["link1"],
        "link2": [
            cm["link2"][0] + cm["cabinet"][0],
            *(
                (
                    np.array(cm["link2"][1:]) * cm["link2"][0]
                    + np.array(cm["cabinet"][1:]) * cm["cabinet"][0]
                )
                / (cm["link2"][0] + cm["cabinet"][0])
            ),
        ],
        "link3": [
            cm["link3"][0] + cm["lidar"][0],
            *(
                (
                    np.array(cm["link3"][1:]) * cm["link3"][0]
                    + np.array(cm["lidar"][1:]) * cm["lidar"][0]
                )
                / (cm["link3"][0] + cm["lidar"][0])
            ),
        ],
        "link4": cm["link4"],
        "link5": cm["link5"],
    }
    parent = "foot_rear"
    for i in range(5):
        child = f"link{i + 1}"
        T = origin(calpha[i], ca[i], cd[i - 1] if i else 0.0)
        joint(f"J{i + 1}", "revolute", parent, child, T, climb_lim[i], climb_vel[i])
        link(child, bodies[child], masses[child])
        parent = child
    T = np.eye(4)
    T[2, 3] = cd[4]
    joint("foot_front_fixed", "fixed", "link5", "foot_front", T)
    link("foot_front", _foot(p), cm["foot_front"])

    # --- manipulator ------------------------------------------------------------
    joint("arm_mount", "fixed", "link2", "arm_base", arm_mount(p))
    link("arm_base", _cylinder([0, 0, -0.05], [0, 0, 0.05], mr, "module"), am["arm_base"])
    n = 7
    parent = "arm_base"
    for k in range(n):
        child = f"link{k + 6}"
        T = origin(aalpha[k], aa[k], ad[k - 1] if k else 0.0)
        joint(f"J{k + 6}", "revolute", parent, child, T, arm_lim[k], arm_vel[k])
        nxt = aa[k + 1] if k + 1 < n else 0.0
        body = _cylinder([0, 0, 0], [0, 0, ad[k]], lr, "carbon") + _cylinder(
            [0, 0, ad[k]], [nxt, 0, ad[k]], lr, "carbon"
        )
        if k + 1 < n:  # the next joint's module sits at the end of this link
            z_next = origin(aalpha[k + 1], aa[k + 1], ad[k])
            ax = z_next[:3, 2]
            ctr = z_next[:3, 3]
            body += _cylinder(ctr - 0.05 * ax, ctr + 0.05 * ax, mr, "module")
        link(child, body, am[child])
        parent = child
    T = np.eye(4)
    T[2, 3] = ad[-1] - a_["l7"]
    joint("tool_fixed", "fixed", "link12", "tool", T)
    link("tool", _cylinder([0, 0, 0], [0, 0, a_["l7"]], 0.03, "sensor"), None)
    out.append("</robot>")
    return "\n".join(out) + "\n"


def main() -> None:
    """Rewrite ``cmbot.urdf`` next to this file from ``params.toml``."""
    from robots.model import read_params

    (HERE / "cmbot.urdf").write_text(build_urdf(read_params(HERE / "params.toml")))


if __name__ == "__main__":
    main()
