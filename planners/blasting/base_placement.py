"""Where to stand the DENSO arm so that it reaches a whole surface.

The seed places the base by hand (§4.2.4: (500, 375, 370) mm for its three
surfaces).  A surface taken from a finding on a scanned structure has no such
pose, so this searches one, in three steps over a grid of base positions in a
region (world frame, upright base — the seed's mounting):

1. *Stand*: the base lies on the surface's outward side (``normal``) and at
   least ``clearance_m`` from every obstacle point and box (the platform
   needs room).
2. *Reach bound*: for every target (the outline and an interior grid of the
   surface, at most :data:`MAX_TARGETS`) the flange stands ``stream +
   nozzle`` off it along the normal with the blast axis into the surface
   (seed §3.4.1, Eq. 3.5's pose); a base is dropped as soon as one target's
   wrist centre is farther from the shoulder circle than
   :func:`planners.blasting.arm.wrist_reach_m` (no closed-form solution on
   any branch — proved there).
3. *Closed-form IK* (:meth:`robots.denso_vm6083.DensoVM6083.ik_axis`, joint
   limits included) for every target from each remaining base.

Of the bases that reach every target the one with the largest least *reach
margin* (distance of the worst target's wrist centre inside the reach
sphere) is chosen, then refined on a grid of half the step around it.  The
clearance of the arm's links and the coverage are the blast plan's own
checks, computed after this with the chosen base.  No base reaching every
target raises :class:`~planners.errors.UnreachableError` naming the best
found (how many targets it reaches).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import shapely
from scipy.spatial import cKDTree
from shapely.geometry.base import BaseGeometry

from planners.blasting.arm import shoulder_distance, wrist_reach_m
from planners.blasting.collision import Box
from planners.blasting.surface import Surface
from planners.errors import InvalidInputError, UnreachableError

if TYPE_CHECKING:
    from robots.denso_vm6083 import DensoVM6083

__all__ = ["BaseLimits", "BasePlacement", "place_base", "surface_targets"]

#: targets per surface (outline + interior grid)
MAX_TARGETS = 160
#: rows of (base × target) evaluated at once
CHUNK_ROWS = 40_000
#: base positions searched at most (the grid step grows to stay under it)
MAX_CANDIDATES = 30_000


@dataclass(frozen=True)
class BaseLimits:
    """The region searched for the base (world, m; ``None``: a cube around the
    surface as large as the arm's reach), the grid step and the free room
    the base needs around it."""

    lo_m: Sequence[float] | None = None
    hi_m: Sequence[float] | None = None
    step_m: float = 0.1
    clearance_m: float = 0.3

    def __post_init__(self) -> None:
        if (self.lo_m is None) != (self.hi_m is None):
            raise InvalidInputError("give both corners of the base region (lo_m and hi_m) or none")
        if self.lo_m is not None and self.hi_m is not None:
            lo, hi = np.asarray(self.lo_m, float), np.asarray(self.hi_m, float)
            if lo.shape != (3,) or hi.shape != (3,) or not np.all(np.isfinite(lo + hi)):
                raise InvalidInputError("the base region's corners must be 3 finite numbers each")
            if np.any(hi < lo):
                raise InvalidInputError(
                    f"base region hi_m {hi.tolist()} is below lo_m {lo.tolist()}"
                )
        if not (np.isfinite(self.step_m) and self.step_m > 0):
            raise InvalidInputError(f"base search step must be > 0, got {self.step_m}")
        if not (np.isfinite(self.clearance_m) and self.clearance_m >= 0):
            raise InvalidInputError(f"base clearance must be ≥ 0, got {self.clearance_m}")


@dataclass(frozen=True)
class BasePlacement:
    """The chosen base and what the search measured."""

    base_m: np.ndarray
    margin_m: float
    targets: int
    candidates: int
    standing: int
    reaching: int
    region_lo_m: np.ndarray
    region_hi_m: np.ndarray
    step_m: float

    def summary(self) -> dict[str, object]:
        return {
            "base_m": [round(float(v), 6) for v in self.base_m],
            "reach_margin_m": round(self.margin_m, 6),
            "targets": self.targets,
            "candidates": self.candidates,
            "standing": self.standing,
            "reaching": self.reaching,
            "region_lo_m": [round(float(v), 6) for v in self.region_lo_m],
            "region_hi_m": [round(float(v), 6) for v in self.region_hi_m],
            "step_m": self.step_m,
        }


def surface_targets(surface: Surface, limit: int = MAX_TARGETS) -> np.ndarray:
    """(T, 3) points the arm must reach: the outline's vertices (thinned) and
    an interior grid, at most ``limit`` in all (world frame)."""
    poly: BaseGeometry = surface.polygon
    ring = np.asarray(surface.boundary, dtype=float)
    outline = ring[:: max(1, len(ring) // (limit // 2))][: limit // 2]
    x0, y0, x1, y1 = poly.bounds
    room = limit - len(outline)
    h = max(np.sqrt(poly.area / max(room, 1)), 1e-3)
    while True:
        gx, gy = np.meshgrid(np.arange(x0 + h / 2, x1, h), np.arange(y0 + h / 2, y1, h))
        grid = np.column_stack([gx.ravel(), gy.ravel()])
        grid = grid[shapely.intersects_xy(poly, grid[:, 0], grid[:, 1])] if len(grid) else grid
        if len(grid) <= room:
            break
        h *= 1.25
    uv = np.vstack([outline, grid.reshape(-1, 2)])
    return surface.to_world(uv)


def _flange(
    surface: Surface, targets: np.ndarray, standoff_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """Flange positions and blast axes (into the surface) from the outward side."""
    n = surface.normal / np.linalg.norm(surface.normal)
    return targets + standoff_m * n, np.broadcast_to(-n, targets.shape).copy()


def _grid(lo: np.ndarray, hi: np.ndarray, step: float) -> tuple[np.ndarray, float]:
    while True:
        axes = [np.arange(lo[i], hi[i] + step * 0.5, step) for i in range(3)]
        if np.prod([len(a) for a in axes]) <= MAX_CANDIDATES:
            break
        step *= 1.25
    mesh = np.meshgrid(*axes, indexing="ij")
    return np.column_stack([m.ravel() for m in mesh]), step


def _standing(
    cands: np.ndarray,
    surface: Surface,
    points: np.ndarray | None,
    boxes: Sequence[Box],
    clearance: float,
) -> np.ndarray:
    n = surface.normal / np.linalg.norm(surface.normal)
    ok = (cands - surface.origin) @ n > 0.0
    if points is not None and len(points):
        d, _ = cKDTree(points).query(cands, k=1, distance_upper_bound=clearance)
        ok &= ~np.isfinite(d)
    for b in boxes:
        gap = np.maximum(np.abs(cands - b.center) - b.half, 0.0)
        ok &= np.linalg.norm(gap, axis=1) >= clearance
    return ok


def _evaluate(
    arm: DensoVM6083, cands: np.ndarray, p: np.ndarray, z: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Per candidate: targets reached (closed-form IK within the limits) and
    the least reach margin (m) over the targets."""
    T = len(p)
    reach = wrist_reach_m(arm)
    wrist = p - arm.d[5] * z  # wrist centres (T,3), world
    hits = np.zeros(len(cands), dtype=int)
    margin = np.full(len(cands), -np.inf)
    per = max(1, CHUNK_ROWS // T)
    for s in range(0, len(cands), per):
        c = cands[s : s + per]
        # translation-only base: the targets in its frame are p − b
        rel = (wrist[None, :, :] - c[:, None, :]).reshape(-1, 3)
        m = reach - shoulder_distance(arm, rel).reshape(len(c), T)
        margin[s : s + per] = m.min(axis=1)
        live = np.flatnonzero(m.min(axis=1) >= 0.0)
        for i in live:
            _, valid = arm.ik_axis(p - c[i], z)
            hits[s + i] = int(np.count_nonzero(valid.any(axis=1)))
        # out-of-reach bases: count the targets inside the bound (an upper
        # bound on what IK could reach) so the error can name the best
        dead = np.setdiff1d(np.arange(len(c)), live)
        hits[s + dead] = -np.count_nonzero(m[dead] >= 0.0, axis=1)
    return hits, margin


def place_base(
    surface: Surface,
    arm: DensoVM6083,
    *,
    standoff_m: float,
    limits: BaseLimits | None = None,
    obstacle_points: np.ndarray | None = None,
    boxes: Sequence[Box] = (),
) -> BasePlacement:
    """Search a base position from which ``arm`` reaches every target of
    ``surface`` with the flange ``standoff_m`` (stream + nozzle) off it; see
    the module docstring.  ``arm`` is used in its own base frame (only its
    geometry matters here)."""
    lim = limits or BaseLimits()
    if not (np.isfinite(standoff_m) and standoff_m > 0):
        raise InvalidInputError(f"standoff must be > 0 m, got {standoff_m}")
    arm0 = arm.with_base(np.eye(4))
    targets = surface_targets(surface)
    p, z = _flange(surface, targets, standoff_m)
    if lim.lo_m is not None and lim.hi_m is not None:
        lo, hi = np.asarray(lim.lo_m, float), np.asarray(lim.hi_m, float)
    else:
        half = wrist_reach_m(arm0) + float(arm0.a[0]) + float(arm0.d[0]) + float(arm0.d[5])
        lo, hi = p.min(axis=0) - half, p.max(axis=0) + half
    pts = None if obstacle_points is None else np.asarray(obstacle_points, float).reshape(-1, 3)

    cands, step = _grid(lo, hi, lim.step_m)
    stand = _standing(cands, surface, pts, boxes, lim.clearance_m)
    c_ok = cands[stand]
    hits, margin = _evaluate(arm0, c_ok, p, z)
    full = hits == len(targets)
    if not np.any(full):
        best = int(np.abs(hits).max()) if len(hits) else 0
        raise UnreachableError(
            f"no base position reaches the whole surface: searched {len(cands)} positions "
            f"in [{_fmt(lo)}, {_fmt(hi)}] at {step:.3f} m, {int(stand.sum())} with "
            f"{lim.clearance_m:.2f} m of free room on the surface's side; the best reaches "
            f"{best} of {len(targets)} surface points. Widen the base region or pick a "
            "smaller region on the face"
        )
    i = int(np.flatnonzero(full)[np.argmax(margin[full])])
    best_c, best_m = c_ok[i], float(margin[i])
    # refine on half the step around the best
    fine = step / 2.0
    offs = np.arange(-1, 2) * fine
    local = best_c + np.stack(np.meshgrid(offs, offs, offs, indexing="ij"), -1).reshape(-1, 3)
    local = local[np.all((local >= lo - 1e-9) & (local <= hi + 1e-9), axis=1)]
    local = local[_standing(local, surface, pts, boxes, lim.clearance_m)]
    if len(local):
        lh, lm = _evaluate(arm0, local, p, z)
        ok = lh == len(targets)
        if np.any(ok) and lm[ok].max() > best_m:
            j = int(np.flatnonzero(ok)[np.argmax(lm[ok])])
            best_c, best_m = local[j], float(lm[j])
    return BasePlacement(
        base_m=np.asarray(best_c, float),
        margin_m=best_m,
        targets=len(targets),
        candidates=len(cands),
        standing=int(stand.sum()),
        reaching=int(full.sum()),
        region_lo_m=lo,
        region_hi_m=hi,
        step_m=step,
    )


def _fmt(v: np.ndarray) -> str:
    return "(" + ", ".join(f"{x:.2f}" for x in v) + ")"
