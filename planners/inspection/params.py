"""Parameters of :func:`planners.inspection.plan_inspection`.

Planners read no files: every robot number is a plain default equal to the
ARA's value in ``robots/ara/params.toml``, repeated here with its derivation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from planners.errors import InvalidInputError

__all__ = [
    "ARA_ARM_LENGTH_M",
    "ARA_JUMP_REACH_M",
    "ARA_WRIST_LANDING_M",
    "ARA_WRIST_STANDING_M",
    "InspectionParams",
]

#: The ARA's largest sole-to-sole distance (metres).  ``robots/ara/params.toml``
#: [arm]: joint 2 sits j1_above_sole + j2_above_j1 = 0.05 + 0.05 = 0.10 m above
#: the standing sole, joints 2 → 5 are link2 + link3 + link4 = 0.15 + 0.20 +
#: 0.15 = 0.50 m apart at most (straight arm), and the moving sole is
#: j6_below_j5 + sole_below_j6 = 0.05 + 0.05 = 0.10 m beyond joint 5.  By the
#: triangle inequality no pose puts the soles further apart than
#: 0.10 + 0.50 + 0.10 = 0.70 m, and the straight arm pitched in line with both
#: offsets attains it.  It is an upper bound on the reach, not a guarantee
#: that every landing closer than it is kinematically reachable (that is the
#: inch-worm motion planner's job, :mod:`planners.switching.jump`).
ARA_JUMP_REACH_M = 0.10 + 0.50 + 0.10

#: The ARA's wrist offsets and arm length (metres, ``robots/ara/params.toml``
#: [arm]): joint 2 sits ``j1_above_sole_m + j2_above_j1_m`` = 0.10 m along the
#: standing foot's normal above its sole, joint 5 ``j6_below_j5_m +
#: sole_below_j6_m`` = 0.10 m along the landing foot's normal off its sole,
#: and between them the arm is three straight links, ``link2_m + link3_m +
#: link4_m`` = 0.50 m.  A landing whose two wrist points are further apart
#: than the arm length is out of reach for every joint value (the exact
#: bound of :func:`planners.switching.jump.wrist_distance` / ``arm_length``).
ARA_WRIST_STANDING_M = 0.05 + 0.05
ARA_WRIST_LANDING_M = 0.05 + 0.05
ARA_ARM_LENGTH_M = 0.15 + 0.20 + 0.15


@dataclass(frozen=True)
class InspectionParams:
    """Tunables of the inspection route, units in the names.

    Robot (ARA defaults, ``robots/ara/params.toml`` [foot]):

    - ``foot_length_m`` × ``foot_width_m``: the sole rectangle the area check
      (S_am) must fit on a face (0.18 × 0.12 m);
    - ``jump_reach_m``: the largest sole-to-sole distance of an inch-worm jump
      (:data:`ARA_JUMP_REACH_M`, 0.70 m): the radius about a vertex within
      which foot placements are looked for, and the widest gap joined;
    - ``arm_length_m``, ``wrist_standing_m``, ``wrist_landing_m``: the exact
      reach bound of the inch-worm height check S_hc
      (:mod:`planners.inspection.transitions`): the wrist points, the
      standing sole's centre ``wrist_standing_m`` along its face's normal and
      the landing sole's ``wrist_landing_m`` along its own, must be at most
      ``arm_length_m`` apart (ARA: 0.10, 0.10 and 0.50 m,
      :data:`ARA_ARM_LENGTH_M`);
    - ``reach_candidates``: at most this many foot placements per face (the
      ones nearest the vertex) enter that check, so its cost is bounded
      whatever the placement grid holds.

    Transition decision:

    - ``coplanar_angle_deg``: two driving faces continue (mobile transition)
      when their outward normals are within this angle, ...
    - ``contact_tolerance_m``: ... their planes are within this step of each
      other at the vertex and their outlines (projected into the first face's
      plane, clipped to the disc of radius ``jump_reach_m`` about the vertex)
      come within this distance of each other;
    - ``placement_spacing_m``, ``placement_headings``: the grid of foot centres
      and the number of headings (evenly over 180°, the first along the member
      axis) at which foot rectangles are tried on a face; the grid covers a
      disc of radius ``jump_reach_m`` about the vertex, so at most
      ``(2·jump_reach_m / placement_spacing_m + 1)²`` centres are tested per
      (face, vertex) and heading: a bound independent of the structure's size.

    Route:

    - ``jump_cost_m``: what one inch-worm jump is worth in metres of driving
      when the route is chosen (see :mod:`planners.inspection.transitions`
      for how it enters the edge weights); lengths are still reported in
      metres of steel and jumps counted separately.
    - ``close_member``: a close inspection — the route drives
      from ``start`` to this member and along it
      (:mod:`planners.inspection.close`); no other member is required.
    """

    foot_length_m: float = 0.18
    foot_width_m: float = 0.12
    jump_reach_m: float = ARA_JUMP_REACH_M
    arm_length_m: float = ARA_ARM_LENGTH_M
    wrist_standing_m: float = ARA_WRIST_STANDING_M
    wrist_landing_m: float = ARA_WRIST_LANDING_M
    reach_candidates: int = 2048
    coplanar_angle_deg: float = 10.0
    contact_tolerance_m: float = 0.02
    jump_cost_m: float = 0.5
    placement_spacing_m: float = 0.02
    placement_headings: int = 4
    close_member: int | None = None

    def __post_init__(self) -> None:
        cm = self.close_member
        if cm is not None and not (isinstance(cm, int) and not isinstance(cm, bool) and cm >= 0):
            raise InvalidInputError(f"close_member must be a member id ≥ 0 or None, got {cm!r}")
        positive = {
            "foot_length_m": self.foot_length_m,
            "foot_width_m": self.foot_width_m,
            "jump_reach_m": self.jump_reach_m,
            "arm_length_m": self.arm_length_m,
            "placement_spacing_m": self.placement_spacing_m,
        }
        for name, value in positive.items():
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise InvalidInputError(f"{name} must be a finite number > 0, got {value!r}")
        non_negative = {
            "contact_tolerance_m": self.contact_tolerance_m,
            "jump_cost_m": self.jump_cost_m,
            "wrist_standing_m": self.wrist_standing_m,
            "wrist_landing_m": self.wrist_landing_m,
        }
        for name, value in non_negative.items():
            if not (isinstance(value, int | float) and math.isfinite(value) and value >= 0):
                raise InvalidInputError(f"{name} must be a finite number ≥ 0, got {value!r}")
        a = self.coplanar_angle_deg
        if not (isinstance(a, int | float) and math.isfinite(a) and 0 <= a < 90):
            raise InvalidInputError(f"coplanar_angle_deg must be in [0, 90), got {a!r}")
        rc = self.reach_candidates
        if not (isinstance(rc, int) and not isinstance(rc, bool) and 1 <= rc <= 100_000):
            raise InvalidInputError(f"reach_candidates must be an int in [1, 100000], got {rc!r}")
        h = self.placement_headings
        if not (isinstance(h, int) and not isinstance(h, bool) and 1 <= h <= 36):
            raise InvalidInputError(f"placement_headings must be an int in [1, 36], got {h!r}")
        # The placement grid is sized by reach / spacing: keep it bounded.
        if self.jump_reach_m / self.placement_spacing_m > 500:
            raise InvalidInputError(
                "jump_reach_m / placement_spacing_m must be ≤ 500 (the foot placement grid "
                f"would have more than 1e6 cells), got {self.jump_reach_m / self.placement_spacing_m:.0f}"
            )
