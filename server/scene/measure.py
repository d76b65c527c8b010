"""The scene's measuring tool ("two picks in the scene → distance
in mm shown in the console").

A shift-click in the viser scene arrives as a ray (camera origin and
direction, world frame).  :func:`pick_on_ray` turns it into the drawn point
the operator clicked: among the points within a narrow cone around the ray
(half-angle ``tol_rad``, and never narrower than ``min_tol_m``), the one
nearest the ray on the front surface, as seen.  :class:`Measurer` pairs a
client's picks: the first is remembered, the second closes a measurement
(the Euclidean distance between the two picked points, in millimetres).

The points are what the scene drew (clouds at their drawn resolution, plan
geometry, vertices); they are kept at most :data:`MAX_PICKABLE` (evenly
thinned), and a pick scans them in chunks of :data:`_CHUNK` so the
temporaries stay bounded.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

#: Points a pick searches at most (a thinned cloud is still picked where seen).
MAX_PICKABLE = 400_000
#: Rows per chunk of the ray scan.
_CHUNK = 65_536


def pick_on_ray(
    points: np.ndarray,
    origin: np.ndarray,
    direction: np.ndarray,
    *,
    tol_rad: float = 0.01,
    min_tol_m: float = 0.01,
) -> int | None:
    """Index of the point of ``points`` (N, 3) a click along the ray hit, or
    ``None`` when no point lies within the cone in front of the camera.

    A point at depth ``t`` (along the unit ray, ``t > 0``) is under the
    cursor when its distance from the ray is at most
    ``tol(t) = max(min_tol_m, t·tan(tol_rad))``.  The surface seen is the
    front one: with ``t0`` the smallest such depth, the candidates no deeper
    than ``t0 + 3·tol(t0)`` (a surface seen at a slant spans that much of the
    cone).  Of those, the one nearest the ray is picked (ties: the shallower,
    then the lower index), so a slanted surface is not picked at the cone's
    near edge."""
    P = np.asarray(points, dtype=float).reshape(-1, 3)
    o = np.asarray(origin, dtype=float).reshape(3)
    d = np.asarray(direction, dtype=float).reshape(3)
    n = float(np.linalg.norm(d))
    if not (np.all(np.isfinite(o)) and np.all(np.isfinite(d)) and n > 0):
        raise ValueError("the click ray needs a finite origin and a non-zero direction")
    if not (tol_rad > 0 and min_tol_m >= 0):
        raise ValueError("tol_rad must be positive and min_tol_m non-negative")
    d = d / n
    slope = float(np.tan(tol_rad))

    def chunks() -> Iterator[tuple[int, np.ndarray, np.ndarray, np.ndarray]]:
        for start in range(0, len(P), _CHUNK):
            V = P[start : start + _CHUNK] - o
            t = V @ d
            perp2 = np.maximum(np.einsum("ij,ij->i", V, V) - t * t, 0.0)
            tol = np.maximum(min_tol_m, t * slope)
            yield start, t, perp2, (t > 0) & (perp2 <= tol * tol)

    t0 = np.inf
    for _, t, _, hit in chunks():
        if hit.any():
            t0 = min(t0, float(t[hit].min()))
    if not np.isfinite(t0):
        return None
    depth = t0 + 3.0 * max(min_tol_m, t0 * slope)
    best: tuple[float, float, int] | None = None
    for start, t, perp2, hit in chunks():
        idx = np.nonzero(hit & (t <= depth))[0]
        if len(idx) == 0:
            continue
        k = int(idx[np.lexsort((idx, t[idx], perp2[idx]))[0]])
        cand = (float(perp2[k]), float(t[k]), start + k)
        if best is None or cand < best:
            best = cand
    assert best is not None  # t0's own point passes the second scan
    return best[2]


def thin(points: list[np.ndarray], limit: int = MAX_PICKABLE) -> np.ndarray:
    """The finite rows of ``points`` stacked, evenly thinned to at most ``limit``."""
    parts = [np.asarray(p, dtype=float).reshape(-1, 3) for p in points]
    P = np.vstack(parts) if parts else np.zeros((0, 3))
    P = P[np.isfinite(P).all(axis=1)]
    if len(P) > limit:
        P = P[:: int(np.ceil(len(P) / limit))]
    return P


@dataclass(frozen=True)
class Measurement:
    """Two picked points (world frame, m) and their distance (mm)."""

    a: tuple[float, float, float]
    b: tuple[float, float, float]
    distance_mm: float
    client: int | None
    at: float

    def public(self) -> dict[str, Any]:
        return {
            "a_m": list(self.a),
            "b_m": list(self.b),
            "distance_mm": self.distance_mm,
            "client": self.client,
            "at": self.at,
        }


def _triple(p: np.ndarray) -> tuple[float, float, float]:
    return (round(float(p[0]), 4), round(float(p[1]), 4), round(float(p[2]), 4))


class Measurer:
    """Pairs each scene client's picks into measurements; thread-safe (picks
    arrive on viser's callback threads, reads on FastAPI's)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._points = np.zeros((0, 3))
        self._first: dict[int | None, np.ndarray] = {}
        self.last: Measurement | None = None

    def set_points(self, points: list[np.ndarray]) -> None:
        """What the scene now shows; pending first picks refer to the old
        picture, so they are dropped (a finished measurement is kept)."""
        P = thin(points)
        with self._lock:
            self._points = P
            self._first.clear()

    @property
    def pickable(self) -> int:
        return len(self._points)

    def click(
        self, client: int | None, origin: np.ndarray, direction: np.ndarray
    ) -> dict[str, Any]:
        """One pick.  ``state`` is ``missed`` (nothing drawn under the
        cursor), ``first`` (the first point, ``point_m``) or ``measured``
        (with the measurement's fields)."""
        with self._lock:
            P = self._points
        k = pick_on_ray(P, origin, direction)
        if k is None:
            return {"state": "missed", "client": client}
        p = P[k]
        with self._lock:
            first = self._first.pop(client, None)
            if first is None:
                self._first[client] = p
                return {"state": "first", "point_m": list(_triple(p)), "client": client}
            m = Measurement(
                _triple(first),
                _triple(p),
                round(float(np.linalg.norm(p - first)) * 1000.0, 1),
                client,
                time.time(),
            )
            self.last = m
        return {"state": "measured", **m.public()}

    def clear(self) -> None:
        with self._lock:
            self._first.clear()
            self.last = None

    def public(self) -> dict[str, Any] | None:
        m = self.last
        return None if m is None else m.public()
