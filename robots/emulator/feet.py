"""Feet and magnets of a two-footed climbing robot (the ARA), and the rules that keep it up.

The ARA (``robots/ara``) stands on two feet: foot 2 is the base frame
(``base_link``), foot 1 the end of the 6-DoF arm (``foot1_sole``).  Each foot
has a magnet array (wire channel 0 = foot 1, 1 = foot 2, as
``server/kinds/ara_switch.py`` compiles them) and magnetic wheels.

**Mobile configuration** (seed §3.2): both feet on one surface, both
magnets untouched — the wheels' magnets hold the robot.  "The arm is in its
mobile pose" is decided geometrically, because a jump ends in whatever arm
configuration put foot 2 down beside foot 1, not in the zero pose: foot 1's
sole lies in foot 2's sole plane — in the base frame its origin is within
``plane_tol_m`` of z = 0 and its normal within ``tilt_tol_rad`` of +z
(FK of ``ara.urdf``).  The zero pose (``[poses] mobile_deg``) is one such
configuration.  Without a kinematic description (fallback profile) it is
``|q − q_mobile| ≤ joint_tol_rad`` for every joint.

**Held / in the air.** A foot is *held* when its magnet is touched, or, in the
mobile configuration (no magnet touched, arm in a mobile pose), by its
wheels.  A foot is *in the air* while the arm is off the mobile pose and its
magnet is untouched: from the moment a joint move takes the arm off the
mobile pose until the foot is back (its magnet touched after landing, or the
arm back in a mobile pose).

**Rules** (:meth:`FeetSpec.refusal`; a refusal latches ``FALL_RISK``):

1. a joint move that leaves a mobile pose anywhere along its (linear)
   path, or starts off one, with no magnet touched
   (:attr:`~robots.protocol.messages.FallRule.JOINTS_WITHOUT_MAGNET`);
2. a magnet release after which no foot would be held
   (:attr:`~robots.protocol.messages.FallRule.RELEASE_LAST_HOLD`) — the
   release of the only held foot; releasing the last magnet with the arm in
   a mobile pose is fine (the wheels then hold both feet);
3. a wheels command while a foot is in the air
   (:attr:`~robots.protocol.messages.FallRule.WHEELS_FOOT_IN_AIR`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from robots.protocol.messages import (
    CommandMessage,
    FallRule,
    JointsCmd,
    MagnetCmd,
    WheelsCmd,
)

FEET_MASK = 0b11  # magnet channels of the two feet


@dataclass(frozen=True)
class FeetSpec:
    """What decides the feet rules of one robot; see the module docstring.

    ``foot_pose`` maps joint vectors (B, n) to foot 1's sole frames in the
    base frame (B, 4, 4); ``None`` uses the joint tolerance around
    ``q_mobile`` instead.
    """

    q_mobile: np.ndarray
    foot_pose: Callable[[np.ndarray], np.ndarray] | None = field(default=None, repr=False)
    plane_tol_m: float = 0.003
    tilt_tol_rad: float = math.radians(2.0)
    joint_tol_rad: float = 0.01
    path_samples: int = 16  # points checked along a joint move (ends included)

    def mobile(self, q: np.ndarray) -> np.ndarray:
        """(B,) bool: the arm is in a mobile pose at each row of ``q`` (B, n)."""
        Q = np.atleast_2d(np.asarray(q, dtype=float))
        if self.foot_pose is None:
            return np.all(np.abs(Q - self.q_mobile) <= self.joint_tol_rad, axis=1)
        T = self.foot_pose(Q)
        return (np.abs(T[:, 2, 3]) <= self.plane_tol_m) & (
            T[:, 2, 2] >= math.cos(self.tilt_tol_rad)
        )

    def is_mobile(self, q: np.ndarray) -> bool:
        return bool(self.mobile(q)[0])

    def path_stays_mobile(self, q_from: np.ndarray, q_to: np.ndarray) -> bool:
        """The linear joint path q_from → q_to is in a mobile pose all along (sampled)."""
        a = np.asarray(q_from, dtype=float)
        b = np.asarray(q_to, dtype=float)
        if np.array_equal(a, b):
            return self.is_mobile(a)
        s = np.linspace(0.0, 1.0, max(2, self.path_samples))[:, None]
        return bool(self.mobile(a + (b - a) * s).all())

    def in_air(self, magnets: int, q: np.ndarray) -> int:
        """Bits of the feet in the air (bit 0 = foot 1, bit 1 = foot 2)."""
        if self.is_mobile(q):
            return 0
        return ~magnets & FEET_MASK

    def held(self, magnets: int, q: np.ndarray) -> int:
        """Bits of the feet held (by a touched magnet, or by the wheels in mobile mode)."""
        touched = magnets & FEET_MASK
        if touched == 0 and self.is_mobile(q):
            return FEET_MASK
        return touched

    def refusal(self, msg: CommandMessage, magnets: int, q: np.ndarray) -> FallRule | None:
        """The rule ``msg`` breaks if it starts with ``magnets`` and joints ``q``, else None."""
        if isinstance(msg, JointsCmd):
            if magnets & FEET_MASK:
                return None
            target = np.asarray(msg.q_urad, dtype=float) / 1e6
            if target.shape != np.shape(q) or not self.path_stays_mobile(q, target):
                return FallRule.JOINTS_WITHOUT_MAGNET
        elif isinstance(msg, MagnetCmd):
            bit = 1 << msg.magnet
            releases = not msg.touched and bool(bit & FEET_MASK & magnets)
            if releases and not self.held(magnets & ~bit, q):
                return FallRule.RELEASE_LAST_HOLD
        elif isinstance(msg, WheelsCmd) and self.in_air(magnets, q):
            return FallRule.WHEELS_FOOT_IN_AIR
        return None


__all__ = ["FEET_MASK", "FeetSpec"]
