"""Point spacing of a cloud: the median distance to the nearest distinct
neighbour over a random sample (the quantity every structure-model default
is derived from, and what an upload reports)."""

from __future__ import annotations

import numpy as np


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
