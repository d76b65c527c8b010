"""Params shared by the two CMBOT kinds (``cmbot.climb``, ``cmbot.manipulate``):
the guardrail they stand on.  Not a kind itself (it assigns no ``KIND``), so
neither kind module imports the other."""

from __future__ import annotations

import math

import numpy as np
from pydantic import Field, model_validator

from planners.cmbot.guardrail import SEED_POSTS, SEED_SEGMENTS, Guardrail, GuardrailParams
from server.kinds.base import Offset, StrictParams

ROBOT = "cmbot"


class GuardrailSpec(StrictParams):
    """The guardrail along which CMBOT works (defaults: the sample scene)."""

    # positions along the bar, metres: a guardrail is as long as its bridge
    segments_m: list[tuple[Offset, Offset]] = Field(
        default_factory=lambda: list(SEED_SEGMENTS),
        description="continuous top-bar segments [x_start, x_end] in metres, increasing",
    )
    posts_m: list[Offset] = Field(
        default_factory=lambda: list(SEED_POSTS), description="post centres along the bar, metres"
    )
    rail_height_m: float = Field(
        GuardrailParams.rail_height_m, gt=0.3, le=3.0, description="bar top above the walkway"
    )
    mid_rail: bool = Field(True, description="round-steel middle rail between the posts")

    @model_validator(mode="after")
    def _ordered(self) -> GuardrailSpec:
        if not self.segments_m:
            raise ValueError("segments_m needs at least one [x_start, x_end] pair")
        for a, b in self.segments_m:
            if not (math.isfinite(a) and math.isfinite(b) and b > a):
                raise ValueError(f"segment [{a}, {b}] must have x_end > x_start (metres)")
        for (_, b), (a2, _) in zip(self.segments_m, self.segments_m[1:], strict=False):
            if a2 < b:
                raise ValueError("segments_m must be increasing and must not overlap")
        return self

    def build(self) -> Guardrail:
        """The planner's :class:`~planners.cmbot.guardrail.Guardrail`."""
        p = GuardrailParams(
            rail_height_m=self.rail_height_m,
            mid_rail_drop_m=GuardrailParams.mid_rail_drop_m if self.mid_rail else None,
        )
        return Guardrail(np.array(self.segments_m, float), np.array(self.posts_m, float), p)
