"""Low-contact-impact compound-cycloid foot trajectory (seed §3.1, Eq. 11).

For 0 ≤ t ≤ Tb the swing foot moves relative to its lift-off point by

    Δpx = S·(t/Tb − sin(2πt/Tb)/(2π))
    Δpy = D·(t/Tb − sin(2πt/Tb)/(2π))
    Δpz = 2H·(t/Tb − sin(4πt/Tb)/(4π))            0 ≤ t < Tb/2
    Δpz = 2H·(1 − t/Tb + sin(4πt/Tb)/(4π))        Tb/2 ≤ t ≤ Tb

(the printed Eq. 11 gives the second Δpz branch the range 0 ≤ t < Tb/2 as
well; it must be the second half).  Velocity and acceleration vanish at
lift-off and touch-down, and Δpz is C¹ at Tb/2 with peak H.
"""

from __future__ import annotations

import numpy as np

from planners.errors import InvalidInputError


def compound_cycloid(
    t: np.ndarray, S: float, H: float, D: float, Tb: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Eq. 11: displacement, velocity and acceleration (…,3) at times ``t`` (clipped to [0, Tb])."""
    if not (np.isfinite(Tb) and Tb > 0):
        raise InvalidInputError(f"phase time Tb must be > 0 s, got {Tb}")
    if not all(np.isfinite(v) for v in (S, H, D)) or H < 0:
        raise InvalidInputError(f"need finite S, D and H ≥ 0, got S={S}, H={H}, D={D}")
    tau = np.clip(np.asarray(t, dtype=float), 0.0, Tb) / Tb
    w2, w4 = 2 * np.pi * tau, 4 * np.pi * tau
    base = tau - np.sin(w2) / (2 * np.pi)
    dbase = (1.0 - np.cos(w2)) / Tb
    ddbase = 2 * np.pi * np.sin(w2) / Tb**2
    first = tau < 0.5
    z = np.where(
        first,
        2 * H * (tau - np.sin(w4) / (4 * np.pi)),
        2 * H * (1.0 - tau + np.sin(w4) / (4 * np.pi)),
    )
    dz = np.where(first, 2 * H * (1.0 - np.cos(w4)) / Tb, 2 * H * (np.cos(w4) - 1.0) / Tb)
    ddz = np.where(first, 1.0, -1.0) * 2 * H * 4 * np.pi * np.sin(w4) / Tb**2
    pos = np.stack([S * base, D * base, z], axis=-1)
    vel = np.stack([S * dbase, D * dbase, dz], axis=-1)
    acc = np.stack([S * ddbase, D * ddbase, ddz], axis=-1)
    return pos, vel, acc


def smooth_blend(t: np.ndarray, T: float) -> np.ndarray:
    """0 → 1 over [0, T] with the cycloid profile (zero rate at both ends)."""
    tau = np.clip(np.asarray(t, dtype=float) / max(T, 1e-12), 0.0, 1.0)
    return tau - np.sin(2 * np.pi * tau) / (2 * np.pi)
