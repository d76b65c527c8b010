"""Colours of a stored cloud drawn in the scene: by its RGB, its intensity or
its height ("Scans as crews bring them" §3).

``auto`` (the default) is RGB when the cloud has it, else height.  Each
function takes the drawn (thinned) rows and returns (k,3) uint8.
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np

ColourBy = Literal["auto", "rgb", "intensity", "height"]
COLOUR_BY: tuple[str, ...] = ("auto", "rgb", "intensity", "height")


def resolve(colour_by: str, attributes: list[str] | dict[str, Any]) -> str:
    """What ``colour_by`` means for a cloud with ``attributes``: ``auto`` is
    ``rgb`` when it has RGB, else ``height``."""
    if colour_by == "auto":
        return "rgb" if "rgb" in attributes else "height"
    return colour_by


def by_height(points: np.ndarray) -> np.ndarray:
    """Blue (low) to amber (high) along z."""
    z = np.asarray(points[:, 2], dtype=np.float64)
    if not len(z):
        return np.zeros((0, 3), dtype=np.uint8)
    t = (z - z.min()) / max(float(np.ptp(z)), 1e-9)
    return np.stack([60 + 180 * t, 120 + 60 * t, 220 - 160 * t], axis=1).astype(np.uint8)


def by_rgb(rgb: np.ndarray, bits: int | None = None) -> np.ndarray:
    """The stored colour as 8 bits a channel: a 16-bit colour (``bits`` 16, or
    any value above 255 when ``bits`` is not known) keeps its high byte."""
    c = np.asarray(rgb)
    if bits is None:
        bits = 16 if len(c) and int(c.max()) > 255 else 8
    if bits > 8:
        return (c >> 8).astype(np.uint8)
    return np.clip(c, 0, 255).astype(np.uint8)


def by_intensity(intensity: np.ndarray) -> np.ndarray:
    """A grey ramp over the 1st–99th percentile of the intensity (a few
    specular returns do not wash the rest out)."""
    v = np.asarray(intensity, dtype=np.float64)
    if not len(v):
        return np.zeros((0, 3), dtype=np.uint8)
    finite = v[np.isfinite(v)]
    lo, hi = np.percentile(finite, [1, 99]) if len(finite) else (0.0, 1.0)
    t = np.clip((np.nan_to_num(v, nan=lo) - lo) / max(float(hi - lo), 1e-12), 0.0, 1.0)
    g = (30 + 225 * t).astype(np.uint8)
    return np.stack([g, g, g], axis=1)
