"""Point spacing of a cloud: the median distance to the nearest distinct
neighbour over a random sample (the quantity every structure-model default
is derived from, and what an upload reports), and the unit decision made
from it (:func:`decide_units`: metres or millimetres)."""

from __future__ import annotations

import numpy as np

from planners.errors import InvalidInputError

#: A median point spacing at or above this (in the file's unit) cannot be metres
#: of a steel scan (crews scan at 5 mm – 15 cm): the file is in millimetres.
MM_SPACING_FROM = 0.5
#: ... and the cloud spans at least this much (a scan in millimetres of even one
#: short member spans hundreds of units) ...
MM_EXTENT_FROM = 100.0
#: ... with at least this many points (fewer cannot tell a scan's spacing).
MIN_POINTS_TO_DETECT = 100


def decide_units(
    spacing: float | None, extent: float, n_points: int, override: str = "auto"
) -> tuple[str, str]:
    """``("m" | "mm", reason)`` for a cloud of ``n_points`` with median spacing
    ``spacing`` and largest bounding-box side ``extent``, both in its own
    unit; ``override`` ``"m"``/``"mm"`` wins over the detection.  Raises
    :class:`InvalidInputError` (a ``ValueError``) for any other override."""
    if override in ("m", "mm"):
        return override, f"set by the uploader ({override})"
    if override != "auto":
        raise InvalidInputError(f"units must be 'auto', 'm' or 'mm', got {override!r}")
    if spacing is None or n_points < MIN_POINTS_TO_DETECT:
        return "m", f"{n_points} points are too few to tell the units: metres assumed"
    if spacing >= MM_SPACING_FROM and extent >= MM_EXTENT_FROM:
        return "mm", (
            f"median point spacing {spacing:.3g} and extent {extent:.4g} in the file's unit: "
            f"as metres that is a scan sparser than {MM_SPACING_FROM} m over "
            f"≥ {MM_EXTENT_FROM:.0f} m, not steel, so millimetres"
        )
    return "m", f"median point spacing {spacing:.3g}, extent {extent:.4g}: metres"


def measure_spacing(
    points: np.ndarray, *, n_queries: int = 2000, seed: int = 0, chunk: int = 2_000_000
) -> float | None:
    """Median distance from ``n_queries`` random points to their nearest other
    (distinct) point of the cloud, in the cloud's unit; ``None`` below 2 points.

    The cloud (an array or a read-only memmap) is scanned ``chunk`` rows at a
    time, a KD-tree per chunk, so memory stays bounded whatever its size."""
    from scipy.spatial import cKDTree

    n = len(points)
    if n < 2:
        return None
    rng = np.random.default_rng(seed)
    pick = np.sort(rng.choice(n, size=min(n_queries, n), replace=False))
    q = np.asarray(points[pick], dtype=np.float64)
    best = np.full(len(q), np.inf)
    for a in range(0, n, chunk):
        block = np.asarray(points[a : a + chunk], dtype=np.float64)
        d, _ = cKDTree(block).query(q, k=min(4, len(block)))
        d = np.asarray(d, dtype=float).reshape(len(q), -1)
        # the query point itself and up to two exact duplicates sit at 0: the
        # nearest distinct point is the smallest distance above 0
        np.minimum(best, np.where(d > 0, d, np.inf).min(axis=1), out=best)
    finite = best[np.isfinite(best)]
    return float(np.median(finite)) if len(finite) else None
