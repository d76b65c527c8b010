"""Dead reckoning on the crossbeam during the U-turn (seed §3.3, Eq. 10–11).

Frame of Eq. 10: X horizontal and Z vertical (up) on the crossbeam face as
seen from inside the girder, θ the heading measured from +Z toward +X
(clockwise as seen, i.e. a right turn of the robot increases θ).  With
left/right wheel travel speeds ``v_l``, ``v_r`` and track ``B``::

    ΔX = (v_r + v_l)/2 · sin θ_i · ΔT
    ΔZ = (v_r + v_l)/2 · cos θ_i · ΔT
    Δθ = (v_l − v_r)/B · ΔT

Wheel slip during in-place turns corrupts the encoder Δθ, so the seed takes
the yaw change from the IMU while turning (``yaw_increments``).
"""

from __future__ import annotations

import math

import numpy as np


def dr_step(
    X: float, Z: float, theta: float, v_l: float, v_r: float, B: float, dT: float
) -> tuple[float, float, float]:
    """One step of Eq. 10–11 (position uses the heading at step i)."""
    v = 0.5 * (v_r + v_l)
    return X + v * math.sin(theta) * dT, Z + v * math.cos(theta) * dT, theta + (v_l - v_r) / B * dT


def dr_integrate(
    X0: float,
    Z0: float,
    theta0: float,
    v_l: np.ndarray,
    v_r: np.ndarray,
    B: float,
    dT: float | np.ndarray,
    yaw_increments: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vectorised Eq. 10–11 over K steps; returns poses (K+1,) including the
    start.  Where ``yaw_increments`` (K,) is finite it replaces the encoder
    Δθ (IMU yaw during in-place turns)."""
    v_l = np.asarray(v_l, dtype=float)
    v_r = np.asarray(v_r, dtype=float)
    dT = np.broadcast_to(np.asarray(dT, dtype=float), v_l.shape)
    dth = (v_l - v_r) / B * dT
    if yaw_increments is not None:
        yi = np.asarray(yaw_increments, dtype=float)
        dth = np.where(np.isfinite(yi), yi, dth)
    theta = theta0 + np.concatenate([[0.0], np.cumsum(dth)])
    v = 0.5 * (v_r + v_l) * dT
    X = X0 + np.concatenate([[0.0], np.cumsum(v * np.sin(theta[:-1]))])
    Z = Z0 + np.concatenate([[0.0], np.cumsum(v * np.cos(theta[:-1]))])
    return X, Z, theta
