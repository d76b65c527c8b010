"""CMBOT climbing-mechanism kinematics (seed §3.1, Eq. 1–8, Table 1) for the planners.

The equations (corrected Table 1 in Craig's modified D-H convention, Eq. 3–5
written out, Eq. 6–7 foot angles, Eq. 8 closed-form knee-up IK for φy = 0)
live with the robot in :mod:`robots.cmbot.kinematics`, so that ``robots/``
never imports ``planners/``.  This module re-exports them under the names the
planners and tests use and turns their ``ValueError`` into the planners' own
error types (DESIGN §5): bad input → :class:`InvalidInputError`, an
unreachable single target → :class:`UnreachableError`.
"""

from __future__ import annotations

import numpy as np

from planners.errors import InvalidInputError, UnreachableError
from robots.cmbot import kinematics as _kin
from robots.cmbot.kinematics import (
    CLIMBER_ALPHA,
    climber_fk_explicit,
    climber_mdh,
    foot_angles,
    mdh_transform,
    wrap_angle,
)

__all__ = [
    "CLIMBER_ALPHA",
    "climber_fk",
    "climber_fk_explicit",
    "climber_frames",
    "climber_ik",
    "climber_ik_batch",
    "climber_mdh",
    "foot_angles",
    "mdh_frames",
    "mdh_transform",
    "wrap_angle",
]


def mdh_frames(
    q: np.ndarray,
    alpha: np.ndarray,
    a: np.ndarray,
    d: np.ndarray,
    base: np.ndarray | None = None,
) -> np.ndarray:
    """Frames of a modified-D-H chain (Eq. 1, 2): ``q`` (…,n) → (…,n+1,4,4); index 0 is the base."""
    try:
        return _kin.mdh_frames(q, alpha, a, d, base)
    except ValueError as exc:
        raise InvalidInputError(str(exc)) from exc


def climber_frames(q: np.ndarray, l1: float, l2: float) -> np.ndarray:
    """Eq. 1: frames B, 1…5 of the climbing chain; the last is the swing-foot frame at P."""
    return mdh_frames(q, *climber_mdh(l1, l2))


def climber_fk(q: np.ndarray, l1: float, l2: float) -> np.ndarray:
    """Eq. 1: 4×4 pose(s) of the swing foot (point P, z up) in the stance-foot frame B."""
    return climber_frames(q, l1, l2)[..., -1, :, :]


def climber_ik_batch(
    p: np.ndarray,
    phi_z: np.ndarray | float,
    l1: float,
    l2: float,
    limits: np.ndarray | None = None,
    *,
    tol: float = 1e-12,
) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 8 (corrected) for φy = 0, vectorised: ``p`` (…,3) → ``(q (…,5), ok (…,))``.

    See :func:`robots.cmbot.kinematics.climber_ik_batch`; rows that are not ok
    hold NaN.  Non-finite or misshapen ``p`` raises :class:`InvalidInputError`.
    """
    try:
        return _kin.climber_ik_batch(p, phi_z, l1, l2, limits, tol=tol)
    except ValueError as exc:
        raise InvalidInputError(str(exc)) from exc


def climber_ik(
    p: np.ndarray,
    phi_z: float,
    l1: float,
    l2: float,
    limits: np.ndarray | None = None,
) -> np.ndarray:
    """Eq. 8 (corrected) for one target: joint angles (5,) or :class:`UnreachableError`."""
    p = np.asarray(p, dtype=float)
    if p.shape != (3,):
        raise InvalidInputError(f"p must be one (3,) position in metres, got shape {p.shape}")
    q, ok = climber_ik_batch(p, phi_z, l1, l2, limits)
    if not ok:
        rho = float(np.linalg.norm(p))
        if rho > 2 * l2:
            why = f"|p| = {rho:.4f} m exceeds the reach 2·l2 = {2 * l2:.4f} m"
        elif np.hypot(p[0], p[1]) <= 1e-9:
            why = "p lies on the J1 axis (θ1 undefined)"
        else:
            why = "the knee-up solution leaves the joint limits"
        raise UnreachableError(f"swing-foot target p = {p.tolist()} unreachable with φy = 0: {why}")
    return q
