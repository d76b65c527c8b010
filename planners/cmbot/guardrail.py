"""Guardrail model for CMBOT (seed §2.1, Fig. 1): top angle-steel bar, vertical
posts every 1000–1500 mm, irregular gaps up to 10 cm between guardrail
segments, inclined round-steel brackets, the walkway and the wall beside it.

World frame: x along the top bar (the walking direction), z up with z = 0 on
the bar's top surface, y across with −y towards the walkway (the side the arm
works on).  Every element is a :class:`~planners.cmbot.distance.Cuboid` so
the arm's sphere–cuboid distances apply to all of them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from planners.cmbot.distance import Cuboid
from planners.errors import InvalidInputError


@dataclass(frozen=True)
class GuardrailParams:
    """Dimensions of one railway-bridge guardrail (chosen, typical L63×6 angle steel)."""

    bar_width_m: float = 0.063
    bar_depth_m: float = 0.063
    post_width_m: float = 0.063
    post_keepout_m: float = 0.02  # a foot keeps this far from a post's top joint
    rail_height_m: float = 1.35  # bar top above the walkway
    mid_rail_drop_m: float | None = 0.55  # round-steel middle rail below the bar top (None: none)
    rod_half_m: float = 0.0125  # Ø25 mm round steel
    bracket_drop_m: float = 0.60  # bracket leaves the post this far below the bar top
    bracket_reach_m: float = 0.45  # … and meets the walkway bracket this far outboard
    walkway_width_m: float = 2.55  # guardrail to the ballast-retaining wall face
    walkway_thickness_m: float = 0.15
    wall_height_m: float = 0.0  # wall above the walkway's far edge (0: none)
    wall_thickness_m: float = 0.30


@dataclass(frozen=True)
class Guardrail:
    """Segments (K,2) of continuous top bar [x_start, x_end] and post centres (P,)."""

    segments: np.ndarray
    posts: np.ndarray
    params: GuardrailParams = field(default_factory=GuardrailParams)

    def __post_init__(self) -> None:
        seg = np.asarray(self.segments, dtype=float).reshape(-1, 2)
        posts = np.sort(np.asarray(self.posts, dtype=float).ravel())
        if len(seg) == 0:
            raise InvalidInputError("guardrail needs at least one bar segment")
        if np.any(seg[:, 1] <= seg[:, 0]) or np.any(seg[1:, 0] < seg[:-1, 1]):
            raise InvalidInputError(
                "guardrail segments must be increasing, non-overlapping [start, end] pairs"
            )
        object.__setattr__(self, "segments", seg)
        object.__setattr__(self, "posts", posts)

    @property
    def x_min(self) -> float:
        return float(self.segments[0, 0])

    @property
    def x_max(self) -> float:
        return float(self.segments[-1, 1])

    @property
    def gaps(self) -> np.ndarray:
        """Gaps (G,2) between neighbouring segments."""
        return np.column_stack([self.segments[:-1, 1], self.segments[1:, 0]])

    def keepouts(self) -> np.ndarray:
        """Intervals (P,2) of the bar top occupied by post joints."""
        h = self.params.post_width_m / 2 + self.params.post_keepout_m
        return np.column_stack([self.posts - h, self.posts + h])

    def valid_foothold(self, x: np.ndarray | float, foot_length: float) -> np.ndarray:
        """Whether a foot centred at ``x`` lies wholly on one segment and off every post."""
        x = np.asarray(x, dtype=float)
        lo, hi = x - foot_length / 2, x + foot_length / 2
        on = np.any(
            (lo[..., None] >= self.segments[:, 0] - 1e-12)
            & (hi[..., None] <= self.segments[:, 1] + 1e-12),
            axis=-1,
        )
        k = self.keepouts()
        off = ~np.any((hi[..., None] > k[:, 0]) & (lo[..., None] < k[:, 1]), axis=-1)
        return on & off

    def why_invalid(self, x: float, foot_length: float) -> str:
        """A sentence saying why a foothold is not valid ('' when it is)."""
        lo, hi = x - foot_length / 2, x + foot_length / 2
        if lo < self.x_min or hi > self.x_max:
            return f"x = {x:.3f} m puts the foot off the guardrail [{self.x_min:.3f}, {self.x_max:.3f}] m"
        for g0, g1 in self.gaps:
            if hi > g0 and lo < g1:
                return f"x = {x:.3f} m puts the foot over the gap [{g0:.3f}, {g1:.3f}] m"
        for k0, k1 in self.keepouts():
            if hi > k0 and lo < k1:
                return f"x = {x:.3f} m puts the foot on the post at {(k0 + k1) / 2:.3f} m"
        return ""

    def boxes(self, x_lo: float = -np.inf, x_hi: float = np.inf) -> list[Cuboid]:
        """Obstacle cuboids in the world frame overlapping [x_lo, x_hi] along the bar."""
        p = self.params
        out: list[Cuboid] = []
        bw, bd, r = p.bar_width_m / 2, p.bar_depth_m, p.rod_half_m
        H = p.rail_height_m
        for i, (s0, s1) in enumerate(self.segments):
            a, b = max(s0, x_lo), min(s1, x_hi)
            if b <= a:
                continue
            out.append(Cuboid.from_bounds([a, -bw, -bd], [b, bw, 0.0], f"bar{i}", "guardrail"))
            if p.mid_rail_drop_m is not None:
                z = -p.mid_rail_drop_m
                out.append(
                    Cuboid.from_bounds([a, -r, z - r], [b, r, z + r], f"mid_rail{i}", "guardrail")
                )
        for i, xp in enumerate(self.posts):
            if not (x_lo - 0.5 <= xp <= x_hi + 0.5):
                continue
            pw = p.post_width_m / 2
            out.append(
                Cuboid.from_bounds([xp - pw, -pw, -H], [xp + pw, pw, -bd], f"post{i}", "guardrail")
            )
            # Bracket: round-steel stay from the post down and outwards (+y) to the
            # walkway bracket's end, on the side away from the arm's work area.
            a = np.array([xp, pw, -p.bracket_drop_m])
            b = np.array([xp, p.bracket_reach_m, -H])
            ax = (b - a) / np.linalg.norm(b - a)
            R = np.column_stack([ax, [1.0, 0.0, 0.0], np.cross(ax, [1.0, 0.0, 0.0])])
            out.append(
                Cuboid(
                    (a + b) / 2,
                    np.array([np.linalg.norm(b - a) / 2, r, r]),
                    R,
                    f"bracket{i}",
                    "guardrail",
                )
            )
        lo = self.x_min if np.isinf(x_lo) else x_lo
        hi = self.x_max if np.isinf(x_hi) else x_hi
        W = p.walkway_width_m
        out.append(
            Cuboid.from_bounds(
                [lo, -W, -H - p.walkway_thickness_m], [hi, 0.3, -H], "walkway", "structure"
            )
        )
        if p.wall_height_m > 0:
            out.append(
                Cuboid.from_bounds(
                    [lo, -W - p.wall_thickness_m, -H - p.walkway_thickness_m],
                    [hi, -W, -H + p.wall_height_m],
                    "wall",
                    "structure",
                )
            )
        return out


def make_guardrail(
    length_m: float,
    *,
    seed: int = 0,
    post_spacing_m: tuple[float, float] = (1.0, 1.5),
    max_gap_m: float = 0.10,
    bays_per_segment: tuple[int, int] = (2, 4),
    end_overhang_m: float = 0.25,
    start_x_m: float = 0.0,
    params: GuardrailParams | None = None,
) -> Guardrail:
    """A guardrail of about ``length_m``: segments of 2–4 bays with posts
    every 1.0–1.5 m (seed §2.1), separated by gaps drawn up to ``max_gap_m``."""
    if not (np.isfinite(length_m) and length_m > 0):
        raise InvalidInputError(f"length_m must be positive, got {length_m}")
    lo, hi = post_spacing_m
    if not 0 < lo <= hi:
        raise InvalidInputError(f"post_spacing_m must be 0 < min ≤ max, got {post_spacing_m}")
    if max_gap_m < 0:
        raise InvalidInputError(f"max_gap_m must be ≥ 0, got {max_gap_m}")
    rng = np.random.default_rng(seed)
    segments, posts = [], []
    x = start_x_m
    while x < start_x_m + length_m:
        n = int(rng.integers(bays_per_segment[0], bays_per_segment[1] + 1))
        p0 = x + end_overhang_m
        ps = p0 + np.concatenate([[0.0], np.cumsum(rng.uniform(lo, hi, n))])
        end = ps[-1] + end_overhang_m
        segments.append([x, end])
        posts.extend(ps.tolist())
        x = end + float(rng.uniform(0.3 * max_gap_m, max_gap_m)) if max_gap_m > 0 else end
    return Guardrail(np.array(segments), np.array(posts), params or GuardrailParams())


def guardrail_from_lists(segments: Sequence[Sequence[float]], posts: Sequence[float]) -> Guardrail:
    """Convenience constructor from plain lists (metres)."""
    return Guardrail(np.asarray(segments, float), np.asarray(posts, float))


#: The sample scene of the ``cmbot.*`` plan kinds: three guardrail segments with
#: the widest gap the seed names (10 cm) and an 8 cm gap, posts 1.0–1.5 m apart.
SEED_SEGMENTS = ((0.0, 5.55), (5.65, 11.20), (11.28, 16.0))
SEED_POSTS = (
    0.25,
    1.55,
    2.95,
    4.20,
    5.30,
    5.90,
    7.35,
    8.60,
    9.85,
    10.95,
    11.53,
    12.90,
    14.30,
    15.75,
)


def seed_guardrail() -> Guardrail:
    """The deterministic sample guardrail (chosen; the seed gives only its rules)."""
    return Guardrail(np.array(SEED_SEGMENTS), np.array(SEED_POSTS))
