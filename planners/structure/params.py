"""Parameters of :func:`planners.structure.model_structure`.

Every length left ``None`` is derived from the measured point spacing ``s``
(:func:`planners.pointcloud.spacing.measure_spacing`) by
:meth:`StructureParams.resolve`, so the same defaults serve a 5 mm
terrestrial scan and a 15 cm photogrammetry cloud.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace

from planners.errors import InvalidInputError


@dataclass(frozen=True)
class StructureParams:
    #: point spacing (m); None: measured
    spacing_m: float | None = None
    #: neighbourhood radii of the multi-scale line analysis (m); None: from
    #: max(0.1 m, 5 s) doubling up to ``max_section_m`` × 1.5
    scales_m: tuple[float, ...] | None = None
    #: a voxel is "on a member" when (λ1 − λ2)/λ1 of its neighbourhood is at least this
    linearity_min: float = 0.6
    #: neighbouring linear voxels are linked when their directions differ by less
    link_angle_deg: float = 12.0
    #: fragments / parallel faces are joined into one member within this angle
    merge_angle_deg: float = 5.0
    #: the largest section depth expected (m): parallel lines closer than this
    #: and overlapping along their length are faces of one member
    max_section_m: float = 1.2
    #: collinear fragments separated by an occlusion gap up to this are joined (m)
    max_gap_m: float = 2.0
    #: shortest member kept (m); None: max(0.4 m, 8 s)
    min_member_length_m: float | None = None
    #: a member is at least this many section depths long (a stubby blob is not one)
    min_slenderness: float = 2.5
    #: a member meeting no other one and shorter than this is clutter (m);
    #: None: max(2 m, 60 s).  A coarse scan's lone rows are ground rings and
    #: vegetation edges 2.3–7.7 m long, its lone steel members main girders
    #: of 14 m or more (20 seeds a type at 10 cm: precision +0.014…+0.036,
    #: recall unchanged; 40 s kept half of it, 80 s no more than 60 s)
    min_free_length_m: float | None = None
    #: working voxels at the finest scale at most (bounds time and memory)
    max_voxels: int = 300_000
    #: neighbours per voxel in the local analysis
    k_neighbours: int = 40
    seed: int = 0
    #: clouds of more points than this are modelled in overlapping tiles
    #: (:mod:`planners.structure.tiles`); smaller ones whole, as before
    tile_above_points: int = 3_000_000
    #: a tile's core length along the cloud's longest horizontal axis (m)
    tile_m: float = 30.0
    #: each tile reaches this far past its core on every inner side (m): at
    #: least the longest secondary member, so one tile sees it whole, and
    #: more than ``min_free_length_m``, so a cut piece is not dropped as clutter
    overlap_m: float = 5.0
    #: a tile holding more points than this is split further (bounds memory)
    max_points_per_tile: int = 1_500_000

    def resolve(self, spacing: float) -> StructureParams:
        """These parameters with every derived length filled in from ``spacing``."""
        for name in (
            "linearity_min",
            "link_angle_deg",
            "merge_angle_deg",
            "max_section_m",
            "max_gap_m",
            "min_slenderness",
        ):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise InvalidInputError(
                    f"StructureParams.{name} must be a positive number, got {v!r}"
                )
        free = self.min_free_length_m
        if free is not None and not (math.isfinite(free) and free >= 0):
            raise InvalidInputError(
                f"StructureParams.min_free_length_m must be a length ≥ 0 in metres or None, got {free!r}"
            )
        if not 0 < self.linearity_min < 1:
            raise InvalidInputError(f"linearity_min must lie in (0, 1), got {self.linearity_min}")
        if self.max_voxels < 1000 or self.k_neighbours < 8:
            raise InvalidInputError("max_voxels must be ≥ 1000 and k_neighbours ≥ 8")
        if not (math.isfinite(self.tile_m) and self.tile_m > 0) or not (
            math.isfinite(self.overlap_m) and self.overlap_m >= 0
        ):
            raise InvalidInputError(
                f"tile_m must be > 0 and overlap_m ≥ 0 (m), got {self.tile_m!r}, {self.overlap_m!r}"
            )
        if self.tile_above_points < 10 or self.max_points_per_tile < 1000:
            raise InvalidInputError("tile_above_points must be ≥ 10 and max_points_per_tile ≥ 1000")
        s = float(spacing)
        scales = self.scales_m
        if scales is None:
            r = max(0.1, 3.0 * s)
            out = [r]
            while out[-1] * 2 <= 1.5 * self.max_section_m:
                out.append(out[-1] * 2)
            scales = tuple(out)
        elif not scales or any(not (math.isfinite(r) and r > 0) for r in scales):
            raise InvalidInputError(f"scales_m must be positive radii in metres, got {scales!r}")
        min_len = self.min_member_length_m
        if min_len is None:
            min_len = max(0.4, 5.0 * s)
        free_len = self.min_free_length_m
        if free_len is None:
            free_len = max(2.0, 60.0 * s)
        return replace(
            self,
            spacing_m=s,
            scales_m=tuple(sorted(scales)),
            min_member_length_m=min_len,
            min_free_length_m=free_len,
        )

    def as_dict(self) -> dict[str, float]:
        d = asdict(self)
        d["scales_m"] = list(d["scales_m"] or [])
        return d
