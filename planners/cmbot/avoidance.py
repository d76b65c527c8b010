"""Obstacle-avoidance escape velocities for the redundant arm (seed §3.2, Eq. 15–20).

For every sphere C_i / cuboid D_j pair closer than the safety threshold d_s
the sphere should move away along u_ij with the escape speed of Eq. 15

    s_ij = v_max/2 · (cos(π·d_ij/d_s) + 1) · u_ij      (d_ij ≤ d_s, else 0)

(zero at d_s, v_max at contact).  The k active pairs are stacked (Eq. 17)
into v* and J*, and the joint rates that track the tool velocity v while
doing their best on the escapes are (Eq. 19–20)

    β = J⁺v + (I − J⁺J)·[J*(I − J⁺J)]⁺·(v* − J*J⁺v).

With 7 joints and a 6-D task, I − J⁺J has rank one, so J*(I − J⁺J) is rank
one too and its pseudoinverse blows up as the null motion stops moving the
spheres; that pseudoinverse is damped (λ below) so the null-space rate stays
bounded.  The task term J⁺v is never damped, so tracking is unaffected.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planners.cmbot.arm import pinv


@dataclass(frozen=True)
class AvoidanceParams:
    """Safety threshold d_s [m], maximum escape speed v_max [m/s] (Eq. 15) and
    the damping λ [m/s per rad/s] of the rank-one pseudoinverse in Eq. 19."""

    d_s: float = 0.10
    v_max: float = 0.30
    damping: float = 0.02


def escape_speed(d: np.ndarray, d_s: float, v_max: float) -> np.ndarray:
    """Eq. 15 magnitude: v_max/2·(cos(π d/d_s) + 1) for d ≤ d_s (clamped to v_max below 0), else 0."""
    d = np.asarray(d, dtype=float)
    x = np.clip(d / d_s, 0.0, 1.0)
    return np.where(d <= d_s, 0.5 * v_max * (np.cos(np.pi * x) + 1.0), 0.0)


def escape_velocities(d: np.ndarray, u: np.ndarray, params: AvoidanceParams) -> np.ndarray:
    """Eq. 15: s_ij (k,3) from distances (k,) and unit directions (k,3)."""
    return escape_speed(d, params.d_s, params.v_max)[:, None] * np.asarray(u, dtype=float)


def combine(
    J: np.ndarray,
    v: np.ndarray,
    J_star: np.ndarray | None = None,
    v_star: np.ndarray | None = None,
    damping: float = 0.02,
) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 17–20: joint rates ``(β_task, β_null)`` with β = β_task + β_null.

    ``J`` (6,7) tool Jacobian, ``v`` (6,) tool velocity, ``J_star`` (3k,7) and
    ``v_star`` (3k,) the stacked sphere Jacobians and escape velocities.
    """
    Jp = pinv(J)
    beta_task = Jp @ v
    if J_star is None or v_star is None or len(v_star) == 0:
        return beta_task, np.zeros_like(beta_task)
    N = np.eye(J.shape[1]) - Jp @ J  # projector onto the self-motion (Eq. 14)
    A = J_star @ N
    Z = pinv(A, damping) @ (v_star - J_star @ beta_task)  # Eq. 19
    return beta_task, N @ Z  # Eq. 20
