"""CMBOT 7-DoF redundant arm: FK, Jacobians, covering spheres, statics (seed §3.2).

Forward kinematics follows Eq. 12 with Table 2 in the modified D-H form of
Eq. 2: the frames are the robot model's own (:meth:`robots.cmbot.CmbotChain.link_frames`,
read from the URDF), not a copy here; the tool point Q sits at
e_q = (0, 0, −l7) in frame {12}.  :meth:`ArmKinematics.jacobian`
is the 6×7 geometric Jacobian of Eq. 13 (v = [q̇x q̇y q̇z ωx ωy ωz] in (K)),
:func:`gradient_projection` the general solution Eq. 14
β = J⁺v + (I − J⁺J)Z.  The arm is covered by spheres (Fig. 12) whose centre
Jacobians J_Ci enter Eq. 16–20.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from planners.errors import InvalidInputError


@dataclass(frozen=True)
class SphereSet:
    """Covering spheres: ``frame`` index into :meth:`ArmKinematics.frames`
    (0 = base (K), 1…7 = joint frames of J6…J12, 8 = tool), ``local`` centre in
    that frame, ``radius``, ``body`` (0 = J6/J7 modules and the l3 bracket,
    1 = l4, 2 = l5, 3 = forearm + wrist, 4 = tool) for self-collision pairing."""

    frame: np.ndarray
    local: np.ndarray
    radius: np.ndarray
    body: np.ndarray

    def __len__(self) -> int:
        return len(self.frame)


#: frame index (0 base, 1…7 joints, 8 tool) → body used for self-collision pairs
FRAME_BODY = np.array([0, 0, 1, 2, 3, 3, 3, 3, 4])


def covering_spheres(
    joint_origins: np.ndarray,
    end_offset: np.ndarray,
    link_radius: float,
    module_radius: float,
    *,
    sphere_radius: float | None = None,
    module_half_length: float = 0.05,
) -> SphereSet:
    """Spheres covering every link tube (cylinder of ``link_radius`` along the
    polyline joint → joint) and every joint module (cylinder of
    ``module_radius`` × 2·``module_half_length`` on its axis).

    A sphere of radius R covers a cylinder of radius ρ over a length of
    2·√(R² − ρ²), so tube spheres are spaced by that length.
    """
    R = sphere_radius if sphere_radius is not None else link_radius * 1.4
    if link_radius >= R:
        raise InvalidInputError("sphere_radius must exceed link_radius to cover the tube")
    spacing = 2.0 * np.sqrt(R**2 - link_radius**2)
    Rm = float(np.hypot(module_radius, module_half_length))
    frames, locals_, radii = [], [], []
    n = len(joint_origins)
    # Module spheres: the module of joint k sits at the origin of its joint frame k+1.
    frames.append(0)
    locals_.append(np.zeros(3))
    radii.append(Rm)
    for k in range(1, n):
        frames.append(k)  # on the parent link, at the child joint's origin
        locals_.append(joint_origins[k][:3, 3])
        radii.append(Rm)
    # Tube spheres along (0,0,0) → (0,0,t_z) → t in each joint frame k (t: next joint origin).
    for k in range(1, n + 1):
        t = joint_origins[k][:3, 3] if k < n else end_offset[:3, 3]
        poly = [np.zeros(3), np.array([0.0, 0.0, t[2]]), t]
        for a, b in itertools.pairwise(poly):
            L = float(np.linalg.norm(b - a))
            if L < 1e-9:
                continue
            m = int(np.ceil(L / spacing))
            for s in (np.arange(m) + 0.5) / m:
                frames.append(k)
                locals_.append(a + s * (b - a))
                radii.append(R)
    # The tool point itself (nozzle / laser head).
    frames.append(n + 1)
    locals_.append(np.zeros(3))
    radii.append(R)
    fr = np.array(frames)
    return SphereSet(fr, np.array(locals_), np.array(radii), FRAME_BODY[fr])


@dataclass(frozen=True)
class ArmKinematics:
    """Batched kinematics of the arm chain J6…J12 in its base frame (6)/(K)."""

    joint_origins: np.ndarray  # (7,4,4) fixed part of each joint transform
    end_offset: np.ndarray  # (4,4) frame 12 → tool point Q
    limits: np.ndarray  # (7,2) rad
    max_speed: np.ndarray  # (7,) rad/s
    masses: np.ndarray  # (8,) base + links
    coms: np.ndarray  # (8,3) in frames 0…7
    spheres: SphereSet
    params: dict[str, Any]
    chain: Any  # the robot's arm chain (robots.cmbot.CmbotChain): its FK is the one used

    @classmethod
    def from_model(cls, model: Any) -> ArmKinematics:
        """Build from the CMBOT :class:`robots.model.RobotModel` (arm chain)."""
        a = model.params["arm"]
        spheres = covering_spheres(
            model.joint_origins, model.end_offset, a["link_radius_m"], a["module_radius_m"]
        )
        masses = np.concatenate([[model.base_mass[0]], model.link_masses])
        coms = np.vstack([model.base_mass[1], model.link_coms])
        return cls(
            np.asarray(model.joint_origins, float),
            np.asarray(model.end_offset, float),
            np.asarray(model.joint_limits, float),
            np.asarray(model.max_speed, float),
            masses,
            coms,
            spheres,
            model.params,
            model,
        )

    @property
    def dof(self) -> int:
        return len(self.joint_origins)

    def frames(self, q: np.ndarray) -> np.ndarray:
        """Eq. 12: frames (…,9,4,4): base (K), joint frames J6…J12, tool Q."""
        q = np.asarray(q, dtype=float)
        if q.shape[-1] != self.dof:
            raise InvalidInputError(f"arm: expected {self.dof} joint values, got shape {q.shape}")
        return np.asarray(self.chain.link_frames(q))

    def tool_pose(self, q: np.ndarray) -> np.ndarray:
        """Tool pose Q in (K): one configuration by pinocchio (robot model), a batch by frames."""
        q = np.asarray(q, dtype=float)
        if q.shape == (self.dof,):
            return np.asarray(self.chain.fk(q))
        return self.frames(q)[..., -1, :, :]

    @staticmethod
    def jacobian_from_frames(
        F: np.ndarray, point: np.ndarray | None = None, upto: int = 7
    ) -> np.ndarray:
        """Geometric Jacobian (…,6,7) of ``point`` (default: the tool) moved by joints < ``upto``."""
        z = F[..., 1:8, :3, 2]
        o = F[..., 1:8, :3, 3]
        p = F[..., -1, :3, 3] if point is None else point
        J = np.concatenate([np.cross(z, p[..., None, :] - o), z], axis=-1)
        J[..., upto:, :] = 0.0
        return np.swapaxes(J, -1, -2)

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        """Eq. 13: the 6×7 Jacobian of the tool point in (K) (one configuration
        by pinocchio on the URDF, a batch from the frames)."""
        q = np.asarray(q, dtype=float)
        if q.shape == (self.dof,):
            return np.asarray(self.chain.jacobian(q))
        return self.jacobian_from_frames(self.frames(q))

    def sphere_centers(self, F: np.ndarray) -> np.ndarray:
        """Sphere centres (…,S,3) from frames (…,9,4,4)."""
        s = self.spheres
        Fs = F[..., s.frame, :, :]  # (…,S,4,4); index first so the batch axes stay in front
        R = Fs[..., :3, :3]
        t = Fs[..., :3, 3]
        return np.einsum("...sij,sj->...si", R, s.local) + t

    def sphere_jacobians(self, F: np.ndarray, centers: np.ndarray, idx: np.ndarray) -> np.ndarray:
        """Eq. 16: position Jacobians J_Ci (k,3,7) of the sphere centres ``idx`` (one pose)."""
        z = F[1:8, :3, 2]
        o = F[1:8, :3, 3]
        c = centers[idx]
        J = np.cross(z[None], c[:, None, :] - o[None])  # (k,7,3)
        moved = np.arange(7)[None, :] < np.minimum(self.spheres.frame[idx], 7)[:, None]
        J = np.where(moved[..., None], J, 0.0)
        return np.swapaxes(J, 1, 2)

    def gravity_torques(
        self, q: np.ndarray, gravity: np.ndarray, payload_kg: float = 0.0
    ) -> np.ndarray:
        """Static joint torques (…,7) [N·m] holding the links and a payload at Q
        against ``gravity`` (3,) [m/s²] expressed in (K): τ = −Σ J_mᵀ m g."""
        F = self.frames(q)
        g = np.asarray(gravity, dtype=float)
        tau = np.zeros((*np.shape(q)[:-1], self.dof))
        z = F[..., 1:8, :3, 2]
        o = F[..., 1:8, :3, 3]
        pts = [
            (F[..., k, :3, :3] @ self.coms[k] + F[..., k, :3, 3], self.masses[k], k)
            for k in range(8)
        ]
        pts.append((F[..., -1, :3, 3], payload_kg, 8))
        for p, m, k in pts:
            if m <= 0.0:
                continue
            # joints below frame k move the mass: torque_j = z_j · ((p − o_j) × m g)
            lever = np.cross(p[..., None, :] - o, m * g)
            t = np.einsum("...ji,...ji->...j", z, lever)
            t[..., min(k, 7) :] = 0.0
            tau -= t
        return tau


def pinv(J: np.ndarray, damping: float = 0.0) -> np.ndarray:
    """Eq. 14's J⁺ = Jᵀ(JJᵀ)⁻¹ (via SVD); ``damping`` > 0 gives the damped form
    Jᵀ(JJᵀ + λ²I)⁻¹ used only for the rank-deficient avoidance term."""
    U, s, Vt = np.linalg.svd(J, full_matrices=False)
    if damping > 0.0:
        inv = s / (s**2 + damping**2)
    else:
        inv = np.where(
            s > 1e-10 * max(s.max(initial=0.0), 1e-300), 1.0 / np.where(s > 0, s, 1.0), 0.0
        )
    return (Vt.T * inv) @ U.T


def gradient_projection(J: np.ndarray, v: np.ndarray, Z: np.ndarray | None = None) -> np.ndarray:
    """Eq. 14: β = J⁺v + (I − J⁺J)Z."""
    Jp = pinv(J)
    beta = Jp @ v
    if Z is not None:
        beta = beta + (np.eye(J.shape[1]) - Jp @ J) @ Z
    return beta


def rotation_error(R_target: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Axis·angle (3,) of R_target·Rᵀ: the rotation still to do, in the base frame."""
    E = R_target @ R.T
    c = np.clip((np.trace(E) - 1.0) / 2.0, -1.0, 1.0)
    ang = float(np.arccos(c))
    w = np.array([E[2, 1] - E[1, 2], E[0, 2] - E[2, 0], E[1, 0] - E[0, 1]])
    if ang < 1e-9:
        return 0.5 * w
    if np.pi - ang < 1e-6:
        M = (E + np.eye(3)) / 2.0
        axis = M[:, int(np.argmax(np.diag(M)))]
        return ang * axis / np.linalg.norm(axis)
    return ang / (2.0 * np.sin(ang)) * w


def rpy_to_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """Fixed-axis roll-pitch-yaw (R = Rz·Ry·Rx), the seed's pose angles (α, β, γ):
    extrinsic x-y-z Euler angles in scipy's convention."""
    return np.asarray(Rotation.from_euler("xyz", [roll, pitch, yaw]).as_matrix())
