"""Flip torque about the stance foot and the arm counterweight (seed §3.1, Eq. 9–10).

Eq. 9 sums, over the point masses m_i at L_i (every climbing link, both feet,
the folded arm's links), the moment about the stance-foot sole centre B of
gravity and of the inertial (d'Alembert) forces:

    M = Σ BL_i × m_i·(g − a_Li),      g = (0, 0, −9.81) m/s²

(the seed writes "+ m_i·a_Li"; the inertial force opposes the acceleration).
M_y, the moment about the axis across the bar, tips the stance magnet over
its toe or heel; the magnet holds it up to F·L/2 (holding force × half the
sole length).

Eq. 10 sets the swing of the folded arm about J6 so that M_y vanishes:
moving the arm's centre of mass E (mass m_E, distance l_e from the J6 axis)
by l_e·sin δ along the bar changes M_y by −m_E·g·l_e·sin δ, so

    δ = arcsin(M_y,rest / (m_E·g·l_e))  ≈  M_y,rest / (m_E·g·l_e),

which is the printed θ6 = M_y / l_e with the moment expressed per unit arm
weight (the printed form has units of force, not of angle).  δ is clipped to
the allowed swing.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

G = 9.81


@dataclass(frozen=True)
class MassPoints:
    """Point masses over time: ``positions`` (T,K,3) in the world, ``masses`` (K,),
    ``labels`` (K,), ``arm`` (K,) bool marks the arm's points."""

    positions: np.ndarray
    masses: np.ndarray
    labels: list[str]
    arm: np.ndarray


def climber_mass_points(model: Any, q_climb: np.ndarray, T_world_rear: np.ndarray) -> MassPoints:
    """Climbing-chain masses (rear foot, links 1–5, front foot) in the world (T,7,3)."""
    F = np.asarray(T_world_rear)[..., None, :, :] @ model.climber.link_frames(q_climb)
    return climber_mass_points_at(model, F)


def climber_mass_points_at(model: Any, F: np.ndarray) -> MassPoints:
    """:func:`climber_mass_points` from the world frames (T,7,4,4) of the chain
    (base, J1…J5, end), for callers that already have them."""
    c = model.climber
    coms = np.vstack([c.base_mass[1], c.link_coms, c.end_mass[1]])
    masses = np.concatenate([[c.base_mass[0]], c.link_masses, [c.end_mass[0]]])
    pos = np.einsum("tkij,kj->tki", F[..., :3, :3], coms) + F[..., :3, 3]
    labels = ["foot_rear", *[f"link{i}" for i in range(1, 6)], "foot_front"]
    return MassPoints(pos, masses, labels, np.zeros(len(masses), dtype=bool))


def arm_mass_points(
    arm: Any, q_arm: np.ndarray, T_world_base: np.ndarray, payload_kg: float = 0.0
) -> MassPoints:
    """Arm masses (base + J6…J12 links, optional payload at Q) in the world (T,K,3)."""
    F = np.asarray(T_world_base)[..., None, :, :] @ arm.frames(q_arm)  # (T,9,4,4)
    return arm_mass_points_at(arm, F, payload_kg)


def arm_mass_points_at(arm: Any, F: np.ndarray, payload_kg: float = 0.0) -> MassPoints:
    """:func:`arm_mass_points` from the arm's world frames (T,9,4,4)."""
    pos = np.einsum("tkij,kj->tki", F[..., :8, :3, :3], arm.coms) + F[..., :8, :3, 3]
    masses = arm.masses.copy()
    labels = ["arm_base", *[f"link{i}" for i in range(6, 13)]]
    if payload_kg > 0:
        pos = np.concatenate([pos, F[..., -1:, :3, 3]], axis=-2)
        masses = np.concatenate([masses, [payload_kg]])
        labels.append("payload")
    return MassPoints(pos, masses, labels, np.ones(len(masses), dtype=bool))


def merge(*parts: MassPoints) -> MassPoints:
    return MassPoints(
        np.concatenate([p.positions for p in parts], axis=-2),
        np.concatenate([p.masses for p in parts]),
        [lab for p in parts for lab in p.labels],
        np.concatenate([p.arm for p in parts]),
    )


def accelerations(positions: np.ndarray, dt: float) -> np.ndarray:
    """Second time derivative of sampled positions (T,K,3) by central differences."""
    if len(positions) < 3:
        return np.zeros_like(positions)
    return np.gradient(np.gradient(positions, dt, axis=0), dt, axis=0)


def flip_moment(
    points: MassPoints, pivot: np.ndarray, dt: float | None, include: np.ndarray | None = None
) -> np.ndarray:
    """Eq. 9: moment (T,3) about ``pivot`` (T,3) of gravity and inertia of the points.

    ``dt`` None → quasi-static (gravity only); ``include`` (K,) bool selects points.
    """
    g = np.array([0.0, 0.0, -G])
    a = accelerations(points.positions, dt) if dt else np.zeros_like(points.positions)
    m = points.masses if include is None else np.where(include, points.masses, 0.0)
    r = points.positions - pivot[:, None, :]
    return np.einsum("k,tki->ti", m, np.cross(r, g - a))


@dataclass(frozen=True)
class FoldedArm:
    """The folded arm as one mass E: ``mass`` m_E [kg] and its centre of mass
    ``com`` (3,) in the arm base frame (6) at θ6 = 0 (J7…J12 at the fold)."""

    mass: float
    com: np.ndarray

    def _coeffs(
        self, R_world_base: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        c = self.com
        u, w = R_world_base[..., 0, :], R_world_base[..., 2, :]  # world x and z rows
        A = u[..., 0] * c[0] + u[..., 1] * c[1]
        B = u[..., 1] * c[0] - u[..., 0] * c[1]
        Az = w[..., 0] * c[0] + w[..., 1] * c[1]
        Bz = w[..., 1] * c[0] - w[..., 0] * c[1]
        return A, B, Az, Bz

    def lever(self, R_world_base: np.ndarray) -> np.ndarray:
        """l_e: distance of E from the J6 axis (J6 horizontal, across the bar)."""
        A, B, _, _ = self._coeffs(R_world_base)
        return np.hypot(A, B)

    def vertical_angle(self, R_world_base: np.ndarray) -> np.ndarray:
        """θ6 putting E straight above the J6 axis ("the vertical position")."""
        A, B, Az, Bz = self._coeffs(R_world_base)
        th = np.arctan2(-A, B)  # A·cos θ + B·sin θ = 0
        up = Az * np.cos(th) + Bz * np.sin(th)
        return np.where(up >= 0, th, th + np.pi)

    def along_bar_offset(self, theta6: np.ndarray, R_world_base: np.ndarray) -> np.ndarray:
        """E's world-x offset from the J6 axis for J6 angle(s) ``theta6``."""
        A, B, _, _ = self._coeffs(R_world_base)
        return A * np.cos(theta6) + B * np.sin(theta6)


def folded_arm(arm: Any, q_fold: np.ndarray) -> FoldedArm:
    """m_E and E of the folded arm (Eq. 10), from the arm's link masses."""
    q = np.array(q_fold, dtype=float)
    q[0] = 0.0
    mp = arm_mass_points(arm, q[None], np.eye(4)[None])
    m = float(mp.masses.sum())
    return FoldedArm(m, (mp.masses @ mp.positions[0]) / m)


def counterweight_angle(
    M_rest_y: np.ndarray, fa: FoldedArm, R_world_base: np.ndarray, max_swing: float
) -> np.ndarray:
    """Eq. 10 (exact form): θ6 = θ_v + δ so that m_E·g·(E's along-bar shift) = −M_y,rest.

    With E's along-bar offset A·cos θ6 + B·sin θ6 = −s·l_e·sin δ around the
    vertical θ_v = φ + s·π/2, the condition gives
    δ = arcsin(s·M_y,rest/(m_E·g·l_e)), clipped to ±``max_swing``.
    """
    A, B, _, _ = fa._coeffs(R_world_base)
    th_v = fa.vertical_angle(R_world_base)
    phi = np.arctan2(B, A)
    s = np.sign(np.sin(th_v - phi))
    s = np.where(s == 0, 1.0, s)
    ratio = np.asarray(M_rest_y, dtype=float) / (fa.mass * G * np.maximum(np.hypot(A, B), 1e-9))
    delta = np.arcsin(np.clip(s * ratio, -1.0, 1.0))
    return th_v + np.clip(delta, -max_swing, max_swing)
