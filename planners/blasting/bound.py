"""What discs can reach at all: certified limits on coverage (ours).

Footprints are discs of radius ≥ ``r_min`` (the shortest stream length's
disc, Eq. 3.1; in the plan's footprint frame every footprint of the surface
tilt is such a disc).  A disc of radius ρ ≥ r_min is the union of the discs
of radius r_min inside it, so whatever larger discs cover, discs of radius
r_min cover too with no more overspray: only r_min matters below.

* :func:`zero_overspray_reach` — the share of the surface that discs can
  cover without any overspray: the morphological opening of the surface by
  the r_min disc (exact up to shapely's polygonal arcs).
* :func:`pointwise_bound` — a certified upper bound on coverage when the
  overspray may not exceed ``budget`` (a share of the surface area): a
  surface point that no single disc can cover within the budget can never be
  covered.  On a raster of pixel h: pixels certainly outside the surface
  (centre outside the surface grown by h/√2) give a lower bound of every
  disc's overspray (an FFT convolution with the pixels lying wholly inside
  the disc shrunk by the distance to the nearest grid centre); a pixel
  certainly inside (centre inside the surface shrunk by h/√2) is
  uncoverable when no grid centre within r_min + √2·h has a lower bound
  within the budget (Euclidean distance transform).  The uncoverable area
  is a lower bound of what every plan misses.

The pointwise bound ignores that discs covering different points overspray
different places; it proves shortfalls in parts much narrower than the disc
(spikes, slits) but not in parts about as wide as it (there the optimiser's
result is only the best found).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely
from scipy.ndimage import distance_transform_edt
from scipy.signal import fftconvolve
from shapely.geometry.base import BaseGeometry

from planners.blasting.coverage import grid_inside

_QUAD = 8  # quad_segs of the buffers below (inscribed polygons; inflated to stay conservative)
MAX_PIXELS = 4_000_000


def zero_overspray_reach(polygon: BaseGeometry, r_min: float) -> float:
    """Share of the surface inside the union of discs of radius r_min that
    lie inside it (its opening by the disc)."""
    op = shapely.buffer(shapely.buffer(polygon, -r_min, quad_segs=32), r_min, quad_segs=32)
    return float(min(op.area / polygon.area, 1.0))


@dataclass
class PointwiseBound:
    """``coverage_max``: certified upper bound on coverage; ``uncoverable_m2``:
    surface area no disc covers within the budget; ``pixel_m``."""

    coverage_max: float
    uncoverable_m2: float
    pixel_m: float


def pointwise_bound(
    polygon: BaseGeometry,
    r_min: float,
    budget: float,
    *,
    pixel: float | None = None,
    shortcut: bool = True,
) -> PointwiseBound:
    """Certified upper bound on coverage by discs of radius ≥ ``r_min`` whose
    overspray stays within ``budget`` × surface area (see module docstring).

    With ``shortcut`` (default) two steps are skipped where they cannot
    change the answer: the convolution when even a disc lying wholly
    outside (the kernel's pixel count) is within the budget — then every
    lower bound is, and no pixel is uncoverable — and the distance
    transform when every pixel certainly inside is within the budget
    itself (its distance is 0).  ``shortcut=False`` always computes both."""
    area = polygon.area
    h = pixel if pixel is not None else r_min / 30.0
    minx, miny, maxx, maxy = polygon.bounds
    pad = 2.0 * r_min + 4.0 * h
    w, hh = maxx - minx + 2 * pad, maxy - miny + 2 * pad
    if w * hh / (h * h) > MAX_PIXELS:
        h = float(np.sqrt(w * hh / MAX_PIXELS))
        pad = 2.0 * r_min + 4.0 * h
        w, hh = maxx - minx + 2 * pad, maxy - miny + 2 * pad
    # a disc centred within h/√2 of a grid centre g contains every pixel
    # square whose centre is within r_min − √2·h of g
    R = r_min - np.sqrt(2.0) * h
    if R <= 0:
        return PointwiseBound(1.0, 0.0, h)
    m = int(np.floor(R / h))
    o = np.arange(-m, m + 1) * h
    K = (o[None, :] ** 2 + o[:, None] ** 2 <= R * R).astype(float)
    if shortcut and float(K.sum()) * h * h <= budget * area:
        return PointwiseBound(1.0, 0.0, h)  # the convolution counts ≤ K's pixels
    x0, y0 = minx - pad, miny - pad
    nx, ny = int(np.ceil(w / h)), int(np.ceil(hh / h))
    # inscribed polygonal arcs come closer than the true offset: inflate
    d = h / np.sqrt(2.0) / np.cos(np.pi / (4 * _QUAD)) * (1 + 1e-6)
    grown = shapely.buffer(polygon, d, quad_segs=_QUAD)
    shrunk = shapely.buffer(polygon, -d, quad_segs=_QUAD)
    outside = ~grid_inside(grown, x0, y0, h, nx, ny)  # pixel squares wholly outside
    inside = (
        grid_inside(shrunk, x0, y0, h, nx, ny)
        if not shrunk.is_empty
        else np.zeros((ny, nx), dtype=bool)
    )
    over_lb = np.rint(fftconvolve(outside.astype(float), K, mode="same")) * h * h
    ok = over_lb <= budget * area
    if shortcut and not (inside & ~ok).any():
        return PointwiseBound(1.0, 0.0, h)  # every such pixel has distance 0 below
    # a disc containing a point of pixel q has its centre within r_min +
    # h/√2 of q's centre, hence a grid centre within r_min + √2·h
    dist = distance_transform_edt(~ok) * h
    uncoverable = inside & (dist > r_min + np.sqrt(2.0) * h)
    u = float(np.count_nonzero(uncoverable) * h * h)
    return PointwiseBound(1.0 - u / area, u, h)
