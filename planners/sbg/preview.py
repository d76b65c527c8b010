""" "Preview-follow" centreline tracking (seed §3.2, Fig. 8, Eq. 6–9).

From the error ``(d, δ)`` (Table 1 signs, see :mod:`planners.sbg.trilateration`)
the robot drives an arc S0 tangent to its heading through the preview point
P, which lies on the centreline ``Lx`` ahead of Oc's foot point; at P it
turns in place until its yaw deviation is zero.  Robot frame: x heading,
y to the left; a positive turning radius turns left.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from planners.errors import InvalidInputError


def preview_point(d: float, delta: float, Lx: float) -> tuple[float, float]:
    """P in the robot frame (Eq. 6): ``xe = d sin δ + Lx cos δ``,
    ``ye = d cos δ − Lx sin δ``."""
    return d * math.sin(delta) + Lx * math.cos(delta), d * math.cos(delta) - Lx * math.sin(delta)


def turning_radius(d: float, delta: float, Lx: float) -> float:
    """Signed radius of arc S0 (Eq. 7): ``Rc = (Lx² + d²) / (2 (d cos δ − Lx sin δ))``.

    ``+inf``/``-inf`` when P lies straight ahead (denominator 0)."""
    den = 2.0 * (d * math.cos(delta) - Lx * math.sin(delta))
    num = Lx * Lx + d * d
    if den == 0.0:
        return math.inf
    return num / den


def arrival_angle(d: float, delta: float, Rc: float) -> float:
    """Unsigned angle δ2 between heading and centreline on reaching P
    (Eq. 8): ``δ2 = arccos((Rc cos δ − d) / Rc)``."""
    if math.isinf(Rc):
        return abs(delta)
    return math.acos(max(-1.0, min(1.0, (Rc * math.cos(delta) - d) / Rc)))


def arrival_heading(d: float, delta: float, Lx: float, Rc: float) -> float:
    """Signed heading ψ (left +) relative to the centreline on reaching P;
    ``|ψ|`` equals Eq. 8's δ2.  The radius from the arc centre to P is
    ``Rc (sin ψ, −cos ψ)`` in the lane frame."""
    if math.isinf(Rc):
        return delta
    return math.atan2((Lx + Rc * math.sin(delta)) / Rc, -(d - Rc * math.cos(delta)) / Rc)


@dataclass(frozen=True)
class ArcPlan:
    """One preview-follow episode: signed radius (m), signed sweep (rad,
    left +), arc length (m), heading at P (rad) and the in-place rotation
    that follows (rad, = −ψ)."""

    radius_m: float
    sweep_rad: float
    length_m: float
    arrival_rad: float

    @property
    def rotation_rad(self) -> float:
        return -self.arrival_rad


def plan_arc(d: float, delta: float, Lx: float) -> ArcPlan:
    """Arc S0 from Oc to P (Eq. 6–8).  ``Lx = 0`` with ``d = 0`` is a pure
    in-place rotation."""
    if Lx < 0 or not math.isfinite(Lx):
        raise InvalidInputError(f"preview distance Lx must be a finite value ≥ 0, got {Lx}")
    xe, ye = preview_point(d, delta, Lx)
    if math.hypot(xe, ye) < 1e-12:
        return ArcPlan(math.inf, 0.0, 0.0, delta)
    Rc = turning_radius(d, delta, Lx)
    if math.isinf(Rc) or abs(ye) < 1e-12 * max(1.0, abs(xe)):
        # P straight ahead: drive straight to it (xe > 0) — or, when P is
        # behind (only for δ beyond ±90°), no forward arc exists.
        if xe < 0:
            raise InvalidInputError("preview point lies behind the robot; |δ| must be < 90°")
        return ArcPlan(math.inf, 0.0, xe, delta)
    psi = arrival_heading(d, delta, Lx, Rc)
    two_pi = 2.0 * math.pi
    sweep = (psi - delta) % two_pi if Rc > 0 else -((delta - psi) % two_pi)
    if abs(sweep) > two_pi - 1e-12:
        sweep = 0.0
    return ArcPlan(Rc, sweep, abs(Rc * sweep), psi)


def arc_wheel_speeds(Rc: float, v_max: float, B: float) -> tuple[float, float]:
    """``(v_l, v_r)`` driving a circle of signed radius ``Rc`` with the outer
    wheel at ``v_max``: ``v_{l,r} = ω (Rc ∓ B/2)``."""
    if math.isinf(Rc):
        return v_max, v_max
    omega = v_max / (abs(Rc) + B / 2.0)
    return omega * (Rc - B / 2.0) * math.copysign(1.0, Rc), omega * (Rc + B / 2.0) * math.copysign(
        1.0, Rc
    )


def rotation_wheel_speeds(delta: float, omega: float, B: float) -> tuple[float, float]:
    """In-place rotation that reduces δ (Eq. 9): ``v_r = −sign(δ) ω B/2``,
    ``v_l = sign(δ) ω B/2``; returns ``(v_l, v_r)``."""
    s = float(np.sign(delta))
    return s * omega * B / 2.0, -s * omega * B / 2.0


def preview_for_arrival(d: float, delta: float, Lx: float, max_arrival_rad: float) -> float:
    """Smallest preview distance ≥ ``Lx`` whose arc arrives at P with
    ``|ψ| ≤ max_arrival_rad`` (a chosen extension that keeps the camera on
    the welds when the error is large; for δ = 0, tan(ψ/2) = d/Lx).  Needs
    ``|δ| ≤ max_arrival_rad``; bisection on the monotone ``|ψ(Lx)|``."""
    if abs(delta) > max_arrival_rad:
        raise InvalidInputError(
            "preview_for_arrival needs |δ| ≤ max_arrival_rad; rotate in place first"
        )

    def ok(lx: float) -> bool:
        return abs(plan_arc(d, delta, lx).arrival_rad) <= max_arrival_rad

    if ok(Lx):
        return Lx
    lo, hi = Lx, max(Lx, 1e-6) * 2.0
    while not ok(hi):
        lo, hi = hi, hi * 2.0
        if hi > 1e6:
            return hi
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if ok(mid) else (mid, hi)
    return hi
