"""Trilateration of the centreline error from three side range finders
(seed §3.2, Fig. 7, Eq. 5).

Sign convention (seed Table 1): ``d > 0`` when the robot centre Oc is right
of the lane centreline, ``δ > 0`` when the robot heads to the left of it.
l2 and l3 look to the right, ``b`` apart (l2 ahead); l4 looks to the left.
``a`` and ``c`` are the distances from l4 and l3 to the front of the robot,
``n`` its length, so in the body frame (origin Oc, mid-length) the sensors
sit at ``x3 = n/2 − c``, ``x2 = x3 + b``, ``x4 = n/2 − a``.
"""

from __future__ import annotations

import numpy as np


def trilaterate(
    l2: np.ndarray | float,
    l3: np.ndarray | float,
    l4: np.ndarray | float,
    *,
    a: float,
    b: float,
    c: float,
    n: float,
) -> tuple[np.ndarray, np.ndarray]:
    """``(d, δ)`` from the readings l2, l3, l4 (Eq. 5), vectorised:

    δ = arctan((l2 − l3)/b),  d = ((l4 − l3) cos δ + (n − a − c) sin δ) / 2.
    """
    l2, l3, l4 = (np.asarray(v, dtype=float) for v in (l2, l3, l4))
    delta = np.arctan((l2 - l3) / b)
    d = ((l4 - l3) * np.cos(delta) + (n - a - c) * np.sin(delta)) / 2.0
    return d, delta


def side_ranges(
    d: np.ndarray | float,
    delta: np.ndarray | float,
    *,
    half_width_right: np.ndarray | float,
    half_width_left: np.ndarray | float,
    side: float,
    x2: float,
    x3: float,
    x4: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """True readings ``(l2, l3, l4)`` for a robot at ``(d, δ)`` (the forward
    model Eq. 5 inverts).  Beams leave the sensors (``side`` from the body
    axis) perpendicular to the body and hit walls at ``half_width_*`` from
    the centreline::

        l_right(x) = (W_r − d + x sin δ − side cos δ) / cos δ
        l4         = (W_l + d − x4 sin δ − side cos δ) / cos δ
    """
    d = np.asarray(d, dtype=float)
    delta = np.asarray(delta, dtype=float)
    s, co = np.sin(delta), np.cos(delta)
    wr, wl = np.asarray(half_width_right, dtype=float), np.asarray(half_width_left, dtype=float)
    l2 = (wr - d + x2 * s - side * co) / co
    l3 = (wr - d + x3 * s - side * co) / co
    l4 = (wl + d - x4 * s - side * co) / co
    return l2, l3, l4
