"""Generic serial-chain kinematics: D-H forward kinematics, geometric
Jacobian and damped-least-squares inverse kinematics.

References: Denavit & Hartenberg (1955) standard convention; Siciliano et al.,
*Robotics: Modelling, Planning and Control* §3.1 (geometric Jacobian) and
§3.7 (damped least squares).  Robot-specific analytic IK lives with each robot.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from robots.model import RobotModel


def dh_transform(theta: np.ndarray, d: float, a: float, alpha: float) -> np.ndarray:
    """Standard D-H link transform(s); ``theta`` may be a scalar or (B,) batch."""
    theta = np.asarray(theta, dtype=float)
    ct, st = np.cos(theta), np.sin(theta)
    ca, sa = np.cos(alpha), np.sin(alpha)
    T = np.zeros((*theta.shape, 4, 4))
    T[..., 0, 0] = ct
    T[..., 0, 1] = -st * ca
    T[..., 0, 2] = st * sa
    T[..., 0, 3] = a * ct
    T[..., 1, 0] = st
    T[..., 1, 1] = ct * ca
    T[..., 1, 2] = -ct * sa
    T[..., 1, 3] = a * st
    T[..., 2, 1] = sa
    T[..., 2, 2] = ca
    T[..., 2, 3] = d
    T[..., 3, 3] = 1.0
    return T


def dh_chain_transforms(
    q: np.ndarray,
    d: np.ndarray,
    a: np.ndarray,
    alpha: np.ndarray,
    offset: np.ndarray,
    base: np.ndarray | None = None,
) -> np.ndarray:
    """Frames of a D-H chain.  ``q`` (n,) → (n+1,4,4); ``q`` (B,n) → (B,n+1,4,4)."""
    q = np.asarray(q, dtype=float)
    n = len(d)
    if q.shape[-1] != n:
        raise ValueError(f"expected {n} joint values, got shape {q.shape}")
    batch = q.shape[:-1]
    out = np.empty((*batch, n + 1, 4, 4))
    out[..., 0, :, :] = np.eye(4) if base is None else base
    for i in range(n):
        out[..., i + 1, :, :] = out[..., i, :, :] @ dh_transform(
            q[..., i] + offset[i], d[i], a[i], alpha[i]
        )
    return out


def geometric_jacobian(frames: np.ndarray) -> np.ndarray:
    """6×n geometric Jacobian of the last frame for revolute joints about each
    frame's z axis (standard D-H: joint i turns about z of frame i-1)."""
    n = frames.shape[0] - 1
    p_end = frames[-1, :3, 3]
    J = np.zeros((6, n))
    for i in range(n):
        z = frames[i, :3, 2]
        p = frames[i, :3, 3]
        J[:3, i] = np.cross(z, p_end - p)
        J[3:, i] = z
    return J


def pose_error(T_target: np.ndarray, T: np.ndarray) -> np.ndarray:
    """6-vector [position error; orientation error (axis·angle)] from T to T_target."""
    dp = T_target[:3, 3] - T[:3, 3]
    R_err = T_target[:3, :3] @ T[:3, :3].T
    cos_angle = np.clip((np.trace(R_err) - 1.0) / 2.0, -1.0, 1.0)
    angle = np.arccos(cos_angle)
    if angle < 1e-12:
        w = np.zeros(3)
    elif np.pi - angle < 1e-6:
        # Near π the skew part vanishes; take the axis from the symmetric part.
        M = (R_err + np.eye(3)) / 2.0
        axis = M[:, int(np.argmax(np.diag(M)))]
        w = angle * axis / np.linalg.norm(axis)
    else:
        w = (
            angle
            / (2.0 * np.sin(angle))
            * np.array(
                [R_err[2, 1] - R_err[1, 2], R_err[0, 2] - R_err[2, 0], R_err[1, 0] - R_err[0, 1]]
            )
        )
    return np.concatenate([dp, w])


def solve_ik_dls(
    model: RobotModel,
    T_target: np.ndarray,
    q0: np.ndarray | None = None,
    *,
    tol_pos: float = 1e-7,
    tol_rot: float = 1e-7,
    max_iter: int = 200,
    restarts: int = 16,
    damping: float = 1e-3,
    seed: int = 0,
) -> np.ndarray | None:
    """Damped-least-squares IK with random restarts inside the joint limits.

    Returns the solution closest to ``q0`` among those found, or ``None``.
    """
    lo, hi = model.joint_limits[:, 0], model.joint_limits[:, 1]
    rng = np.random.default_rng(seed)
    starts = [np.clip(q0, lo, hi)] if q0 is not None else []
    starts += [rng.uniform(np.maximum(lo, -np.pi), np.minimum(hi, np.pi)) for _ in range(restarts)]
    best: np.ndarray | None = None
    for q in starts:
        q = np.array(q, dtype=float)
        for _ in range(max_iter):
            err = pose_error(T_target, model.fk(q))
            if np.linalg.norm(err[:3]) < tol_pos and np.linalg.norm(err[3:]) < tol_rot:
                break
            J = model.jacobian(q)
            JJt = J @ J.T + damping**2 * np.eye(6)
            q = np.clip(q + J.T @ np.linalg.solve(JJt, err), lo, hi)
        err = pose_error(T_target, model.fk(q))
        if np.linalg.norm(err[:3]) < tol_pos * 10 and np.linalg.norm(err[3:]) < tol_rot * 10:
            if q0 is None:
                return q
            if best is None or np.linalg.norm(q - q0) < np.linalg.norm(best - q0):
                best = q
    return best
