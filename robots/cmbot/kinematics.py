"""CMBOT climbing-mechanism kinematics (seed §3.1, Eq. 1–8, Table 1).

The robot's own analytic kinematics, so that :mod:`robots.cmbot` needs nothing
from ``planners/`` (the layers import one way: planners → robots).  Bad input
raises ``ValueError``; :mod:`planners.cmbot.climbing_kinematics` re-raises it
as :class:`planners.errors.InvalidInputError`.

The 5-DoF biped is a serial chain from the stance foot (frame B, origin at the
centre of the foot's lower surface, z up, x towards the other foot) to point P
at the centre of the swing foot's lower surface.  Transforms follow Eq. 2,
which is Craig's *modified* D-H convention::

    T_{i-1}^{i} = Rx(α_i) · Tx(a_i) · Rz(θ_i) · Tz(d_i)

Table 1 as printed (l1 as d_2, α_5 = +90°, d_5 = +l1) does not reproduce the
printed Eq. 3–5: with d_2 = l1 the offset l1 lies along J2's horizontal axis
and pz has no constant l1 term.  The table that reproduces Eq. 3–5 (and
Eq. 7, φz = θ1 + θ5) is :data:`CLIMBER_MDH`: l1 is the vertical offset along
J1 (d_1), and the last row flips the foot frame back to z-up (α_5 = −90°,
d_5 = −l1).  With it the corrected closed forms are

* Eq. 3–5  p = (c1·r, s1·r, l1 + l2·s2 + l2·s23 − l1·c234),
  r = l2·c2 + l2·c23 + l1·s234   (printed Eq. 5 drops the l1 on c234)
* Eq. 6    φy = −(θ2 + θ3 + θ4)  (printed without the parentheses)
* Eq. 7    φz = θ1 + θ5
* Eq. 8 (φy = 0, so θ2 + θ3 + θ4 = 0 and l1 cancels in pz): with
  r = √(px² + py²) and ρ = √(r² + pz²) the two l2 links form an isosceles
  triangle, ρ = 2·l2·cos(θ3/2), hence

      θ1 = atan2(py, px)
      θ3 = −arccos((px² + py² + pz² − 2·l2²) / (2·l2²))        (knee up, θ3 ≤ 0)
      θ2 = arcsin(pz / ρ) − θ3/2
      θ4 = −θ2 − θ3
      θ5 = φz − θ1

  The printed Eq. 8 has py where px belongs in θ3 (after multiplying through
  by cos²θ1), the wrong sign and a missing pz² under the root in θ2, θ4 =
  θ2 − θ3 instead of −θ2 − θ3, and θ5 = φy instead of φz − θ1.  We evaluate θ3
  as −2·atan2(√(4·l2² − ρ²), ρ), the same angle without arccos' loss of
  precision near full stretch, and θ2 with atan2.
"""

from __future__ import annotations

import numpy as np

#: Corrected Table 1 rows (α_i [rad], a_i, d_i) as multiples of (l1, l2): see module doc.
CLIMBER_ALPHA = np.array([0.0, np.pi / 2, 0.0, 0.0, -np.pi / 2])


def climber_mdh(l1: float, l2: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Modified D-H parameters ``(alpha, a, d)`` of the corrected Table 1."""
    a = np.array([0.0, 0.0, l2, l2, 0.0])
    d = np.array([l1, 0.0, 0.0, 0.0, -l1])
    return CLIMBER_ALPHA.copy(), a, d


def mdh_transform(theta: np.ndarray, alpha: float, a: float, d: float) -> np.ndarray:
    """Eq. 2: ``Rx(α)·Tx(a)·Rz(θ)·Tz(d)`` for a scalar or batch of angles → (…,4,4)."""
    theta = np.asarray(theta, dtype=float)
    ct, st = np.cos(theta), np.sin(theta)
    ca, sa = np.cos(alpha), np.sin(alpha)
    T = np.zeros((*theta.shape, 4, 4))
    T[..., 0, 0] = ct
    T[..., 0, 1] = -st
    T[..., 0, 3] = a
    T[..., 1, 0] = st * ca
    T[..., 1, 1] = ct * ca
    T[..., 1, 2] = -sa
    T[..., 1, 3] = -sa * d
    T[..., 2, 0] = st * sa
    T[..., 2, 1] = ct * sa
    T[..., 2, 2] = ca
    T[..., 2, 3] = ca * d
    T[..., 3, 3] = 1.0
    return T


def mdh_frames(
    q: np.ndarray,
    alpha: np.ndarray,
    a: np.ndarray,
    d: np.ndarray,
    base: np.ndarray | None = None,
) -> np.ndarray:
    """Frames of a modified-D-H chain: ``q`` (…,n) → (…,n+1,4,4); index 0 is the base."""
    q = np.asarray(q, dtype=float)
    n = len(alpha)
    if q.shape[-1] != n:
        raise ValueError(f"expected {n} joint values, got shape {q.shape}")
    out = np.empty((*q.shape[:-1], n + 1, 4, 4))
    out[..., 0, :, :] = np.eye(4) if base is None else base
    for i in range(n):
        out[..., i + 1, :, :] = out[..., i, :, :] @ mdh_transform(q[..., i], alpha[i], a[i], d[i])
    return out


def climber_frames(q: np.ndarray, l1: float, l2: float) -> np.ndarray:
    """Eq. 1: frames B, 1…5 of the climbing chain; the last is the swing-foot frame at P."""
    return mdh_frames(q, *climber_mdh(l1, l2))


def climber_fk(q: np.ndarray, l1: float, l2: float) -> np.ndarray:
    """Eq. 1: 4×4 pose(s) of the swing foot (point P, z up) in the stance-foot frame B."""
    return climber_frames(q, l1, l2)[..., -1, :, :]


def climber_fk_explicit(q: np.ndarray, l1: float, l2: float) -> np.ndarray:
    """Eq. 3–5 (corrected) written out: position(s) p (…,3) of P in B."""
    q = np.asarray(q, dtype=float)
    t1, t2, t3, t4 = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    r = l2 * np.cos(t2) + l2 * np.cos(t2 + t3) + l1 * np.sin(t2 + t3 + t4)
    pz = l1 + l2 * np.sin(t2) + l2 * np.sin(t2 + t3) - l1 * np.cos(t2 + t3 + t4)
    return np.stack([np.cos(t1) * r, np.sin(t1) * r, pz], axis=-1)


def foot_angles(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 6–7 (corrected): ``(φy, φz)`` of the swing foot relative to B."""
    q = np.asarray(q, dtype=float)
    return -(q[..., 1] + q[..., 2] + q[..., 3]), q[..., 0] + q[..., 4]


def wrap_angle(x: np.ndarray) -> np.ndarray:
    """Wrap angles to (−π, π]."""
    return -((-np.asarray(x, dtype=float) + np.pi) % (2 * np.pi) - np.pi)


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

    ``ok`` is False where P is farther than 2·l2 from J2–J4's plane origin,
    on the J1 axis (θ1 undefined), or the solution leaves ``limits`` (5,2).
    Rows that are not ok hold NaN.  l1 does not enter: with φy = 0 the two
    legs are vertical and cancel in pz.
    """
    p = np.asarray(p, dtype=float)
    if p.shape[-1] != 3 or not np.all(np.isfinite(p)):
        raise ValueError(f"p must be finite (…,3) positions in metres, got shape {p.shape}")
    phi_z = np.broadcast_to(np.asarray(phi_z, dtype=float), p.shape[:-1])
    px, py, pz = p[..., 0], p[..., 1], p[..., 2]
    r = np.hypot(px, py)
    rho = np.hypot(r, pz)
    reach = 2.0 * l2
    ok = (rho <= reach * (1.0 + tol)) & (r > 1e-9)
    half = np.arctan2(np.sqrt(np.clip(reach**2 - rho**2, 0.0, None)), rho)  # |θ3|/2
    t1 = np.arctan2(py, px)
    t3 = -2.0 * half
    t2 = np.arctan2(pz, r) + half
    t4 = -t2 - t3
    t5 = wrap_angle(phi_z - t1)
    q = np.stack([t1, t2, t3, t4, t5], axis=-1)
    if limits is not None:
        lim = np.asarray(limits, dtype=float)
        ok &= np.all((q >= lim[:, 0] - 1e-12) & (q <= lim[:, 1] + 1e-12), axis=-1)
    q = np.where(ok[..., None], q, np.nan)
    return q, ok
